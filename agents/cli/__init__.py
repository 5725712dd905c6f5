"""The ``warpcut`` command line: one module per command, each a thin wrapper that parses its options,
makes one library call and prints or writes what it returns.

Every command has ``--help``; bad input exits with status 2 and a one-line ``error: ...`` naming what
to fix, never a traceback (:class:`agents.cli.common.CleanErrors`). Heavy modules (torch, Warp, rerun)
load inside the commands, so ``warpcut --help`` starts fast.
"""

from __future__ import annotations

import click

from agents.cli import (
    bench,
    contours,
    evaluate,
    export,
    optimize,
    plan,
    replay,
    robustness,
    run,
    simulate,
    train,
)
from agents.cli.common import CleanErrors


@click.group(cls=CleanErrors, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="warpcut")
def main() -> None:
    """Simulate, plan and learn tensioning for surgical pattern cutting."""


for _module in (run, contours, simulate, train, optimize, robustness, export, evaluate, replay, plan, bench):
    main.add_command(_module.command)
