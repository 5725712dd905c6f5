"""``docs/cli.md``, the command reference: every command's ``--help``, as the command prints it.

Regenerate it with ``python -m agents.cli.reference > docs/cli.md`` (a test checks that it matches).
"""

from __future__ import annotations

import click

HEAD = """# Command reference

Every `warpcut` command with its options, as `warpcut COMMAND --help` prints them. Settings that are not
flags are set with `--config FILE` and `--set KEY=VALUE`; `warpcut COMMAND --print-config` prints every key
of a command with its value (`docs/usage.md`, "Settings").

Regenerate this page with `python -m agents.cli.reference > docs/cli.md`.
"""


def command_help(name: str) -> str:
    """``warpcut NAME --help``'s text, at a fixed width."""
    from agents.cli import main

    command = main.commands[name]
    settings = {**main.context_settings, "terminal_width": 100, "max_content_width": 100}
    parent = click.Context(main, info_name="warpcut", **settings)
    with click.Context(command, parent=parent, info_name=name, **settings) as ctx:
        return command.get_help(ctx)


def reference() -> str:
    """The whole page."""
    from agents.cli import main

    parts = [HEAD]
    for name in main.commands:
        parts.append(f"## `warpcut {name}`\n\n```text\n{command_help(name)}\n```\n")
    return "\n".join(parts)


if __name__ == "__main__":
    print(reference(), end="")
