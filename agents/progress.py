"""warpcut's progress bars, on stderr: a training run's (:func:`training_progress`: iterations, env steps/s,
the last final error and return, elapsed time and ETA) and a pipeline's stages (:func:`stage_bars`)."""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable, Iterator

from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

FILE_WIDTH = 200
"""Columns of a progress line written to a file or a pipe (a terminal's own width elsewhere): rich's default
of 80 cut a training's line to its first words."""


def _console() -> Console:
    """The bars' console: stderr, as wide as the terminal, or :data:`FILE_WIDTH` where it is no terminal."""
    return Console(stderr=True, width=None if sys.stderr.isatty() else FILE_WIDTH)


@contextlib.contextmanager
def training_progress(
    enabled: bool, total: int, completed: int, steps_per_iteration: int, label: str = "PPO"
) -> Iterator[Callable[[int, dict], None]]:
    """Yield a callback ``(iterations_done, metrics)`` that advances a progress bar labelled ``label``, or
    does nothing. The bar shows env steps/s since it started (not one iteration's rate, which swings with
    validation and evaluation), the last known final error and return, the elapsed time and the ETA."""
    if not enabled:
        yield lambda iterations_done, metrics: None
        return
    columns = (
        TextColumn(escape(label)),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[steps_per_s]} steps/s"),
        TextColumn("final error {task.fields[final_error]}"),
        TextColumn("return {task.fields[mean_return]}"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
    )
    start = time.monotonic()
    # stderr: rsl-rl's report is swallowed by redirecting stdout, which must not catch the bar's redraws.
    with Progress(*columns, console=_console()) as bar:
        task = bar.add_task(
            "train", total=total, completed=completed, steps_per_s="-", final_error="-", mean_return="-"
        )

        def report(iterations_done: int, metrics: dict) -> None:
            # Keep the last known episode metrics through iterations in which no episode ended.
            known = {
                key: f"{metrics[key]:.3f}"
                for key in ("final_error", "mean_return")
                if metrics[key] is not None
            }
            rate = (iterations_done - completed) * steps_per_iteration / max(time.monotonic() - start, 1e-9)
            bar.update(task, completed=iterations_done, steps_per_s=f"{rate:,.0f}", **known)

        yield report


@contextlib.contextmanager
def stage_bars(enabled: bool = True):
    """A pipeline's ``stages(stage, done, total)`` callback (:data:`agents.pipelines.table.Stages`) drawing
    one
    progress bar per stage (planning, training, evaluating) with elapsed time and ETA, on stderr; a no-op
    when not ``enabled``."""
    if not enabled:
        yield lambda stage, done, total: None
        return
    columns = (
        TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
        TextColumn("ETA"), TimeRemainingColumn(),
    )  # fmt: skip
    bars = Progress(*columns, console=_console(), transient=False)
    tasks: dict[str, int] = {}

    def stages(stage: str, done: int, total: int) -> None:
        if not tasks:  # started at the first stage: a pipeline that stops before one draws nothing
            bars.start()
        if stage not in tasks:
            tasks[stage] = bars.add_task(stage, total=total)
        bars.update(tasks[stage], completed=done, total=total)

    try:
        yield stages
    finally:
        if tasks:
            bars.stop()
