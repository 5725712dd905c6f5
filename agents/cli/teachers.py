"""``warpcut teachers``: optimise a teacher for each of many generated contours, the dataset a generalist
learns from (:func:`agents.pipelines.teachers.make_teachers`)."""

from __future__ import annotations

from pathlib import Path

import click

from agents.cli import errors, options, outputs, settings
from agents.cli.checks import check_planner_memory
from agents.config import TEACHER_CONTOURS


@click.command("teachers", cls=settings.Command)
@options.count_option(
    "count", None, f"Generated contours, a teacher each (default {TEACHER_CONTOURS}).", key="count"
)
@options.seed_option
@options.device_option
@options.ray_option("the contours (a contour's plan and teacher a unit)")
@options.out_option("logs/teachers-TIMESTAMP")
@options.run_dir_options
@options.config_options
def command(
    count: int | None,
    seed: int,
    device: str | None,
    ray: str | None,
    out: Path | None,
    resume: bool,
    overwrite: bool,
    config_file: str | None,
    overrides: tuple[str, ...],
    print_config: bool,
) -> None:
    """Optimise a teacher for each of many generated contours: each contour is planned as evaluate plans it,
    and its teacher is the open-loop plan 'warpcut optimize' finds there. The dataset trains a generalist
    (warpcut generalist --teachers DIR). --resume continues an interrupted dataset, or grows it with a larger
    --count.

    Everything but the flags is set with --config FILE and --set KEY=VALUE (the kinds of contour: kinds; the
    teacher's optimiser: grad.*; the physics: sim.*; a generalist every teacher starts from and is tethered
    to, guided policy search's next round: near=DIR, tether=W); --print-config shows them all.
    """
    from agents.cluster import executor
    from agents.jobs import TeachersJob

    base = settings.resumed_job(TeachersJob, out, resume, "teachers")
    job = settings.resolve(TeachersJob, config_file, overrides, base)
    job.check()
    if print_config:
        settings.print_config(job)
        return
    check_planner_memory(job.candidates, job.sim)
    if job.near is not None:
        from agents.generalist import generalist_dir

        generalist_dir(job.near)
    out, claim = outputs.claim(out, "teachers", resume, overwrite, "teachers")
    from agents.pipelines.teachers import make_teachers  # torch: after every check

    try:
        with claim, executor(ray, device, outputs.log) as units:
            click.echo(f"optimising {job.count} teacher(s) into {out} ({device})")
            index = make_teachers(job, out, resume=resume, device=device, log=outputs.log, cluster=units)
    except KeyboardInterrupt as stop:
        raise errors.RunInterrupted(out) from stop
    click.echo(
        f"done: {index['count']} teachers in {index['seconds']:.0f} s; their mean validation error "
        f"{index['mean_error_vertices']:.1f} vertices, a still grasp's "
        f"{index['mean_still_error_vertices']:.1f}"
    )
    click.echo(f"learn from them: warpcut generalist --teachers {out}")
    click.echo(f"wrote {out}")
