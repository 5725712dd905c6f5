"""The ``warpcut`` command line: one module per command, each a thin wrapper that parses its options,
makes one library call and prints or writes what it returns.

Every command has ``--help``; bad input exits with status 2 and a one-line ``error: ...`` naming what
to fix, never a traceback (:class:`agents.cli.errors.CleanErrors`). Heavy modules (torch, Warp, rerun)
load inside the commands, so ``warpcut --help`` starts fast.
"""

from __future__ import annotations

import os

import click

from agents.cli import (
    bench,
    contours,
    evaluate,
    export,
    generalist,
    optimize,
    plan,
    replay,
    robustness,
    run,
    simulate,
    teachers,
    train,
)
from agents.cli.errors import CleanErrors


class Main(CleanErrors):
    """:class:`CleanErrors` that also names the OS limit behind a write the OS refused where its error does
    not (:func:`warpcut.limits.write_cause`): ``EFBIG`` is the file-size limit (``ulimit -f``), and under a
    limit of 0 Python's ``tempfile`` (which torch calls on import) finds "no usable temporary directory"."""

    def invoke(self, ctx: click.Context):
        from warpcut.limits import write_cause

        try:
            return super().invoke(ctx)
        except OSError as exc:
            cause = write_cause(exc)
            if cause is None or os.environ.get("WARPCUT_VERBOSE"):
                raise
            what = exc.filename if exc.filename is not None else "a temporary file"
            raise ValueError(f"cannot write {what} ({exc.strerror or exc}): {cause}") from exc


@click.group(cls=Main, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="warpcut")
def main() -> None:
    """Simulate, plan and learn tensioning for surgical pattern cutting."""


for _module in (
    run,
    contours,
    simulate,
    train,
    generalist,
    teachers,
    optimize,
    robustness,
    export,
    evaluate,
    replay,
    plan,
    bench,
):
    main.add_command(_module.command)
