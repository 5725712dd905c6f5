"""``warpcut generalist``: train one tensioning policy for every contour
(:func:`agents.pipelines.generalist.train_generalist`)."""

from __future__ import annotations

from pathlib import Path

import click

from agents.cli import errors, options, outputs, settings
from agents.cli.checks import check_network_memory, check_planner_memory
from agents.config import GENERALIST_CONTOURS, GENERALIST_ITERATIONS, GENERALIST_VALIDATION_CONTOURS


@click.command("generalist", cls=settings.Command)
@options.count_option(
    "generated", None, f"Generated training contours (default {GENERALIST_CONTOURS}).", key="generated"
)
@click.option(
    "--contours",
    cls=options.Setting,
    key="contours",
    default=None,
    callback=lambda ctx, param, value: (
        None if value is None else [v.strip() for v in value.split(",") if v.strip()]
    ),
    help="Built-in contours to train on as well: 'all' (the suite), or comma-separated names and files "
    "(default: none, so the suite measures the generalist zero-shot).",
)
@click.option(
    "--teachers",
    cls=options.Setting,
    key="train.dagger.teachers",
    default=None,
    help="Learn from this teacher dataset (a directory of 'warpcut teachers'), by DAgger on its contours "
    "(default: es on generated contours).",
)
@options.count_option(
    "validation-contours",
    None,
    f"Generated held-out contours that choose the policy kept (default {GENERALIST_VALIDATION_CONTOURS}).",
    key="validation_contours",
)
@options.count_option(
    "iterations",
    None,
    f"es iterations in total, a resumed run's included (default {GENERALIST_ITERATIONS}).",
    key="train.iterations",
)
@options.seed_option
@options.device_option
@options.ray_option("the contours' plans and es's perturbed policies (the envs of whole policies a worker)")
@options.out_option("logs/generalist-TIMESTAMP")
@options.run_dir_options
@click.option("--no-progress", is_flag=True, help="Hide the progress bar.")
@options.config_options
def command(
    generated: int | None,
    contours: list[str] | None,
    teachers: str | None,
    validation_contours: int | None,
    iterations: int | None,
    seed: int,
    device: str | None,
    ray: str | None,
    out: Path | None,
    resume: bool,
    overwrite: bool,
    no_progress: bool,
    config_file: str | None,
    overrides: tuple[str, ...],
    print_config: bool,
) -> None:
    """Train a generalist: one tensioning policy for every contour, over generated contours (and built-in
    ones where asked) at once; it plays contours it never saw with no training (evaluate --methods
    ...,generalist; run --policy generalist; simulate --policy generalist).

    Everything but the flags is set with --config FILE and --set KEY=VALUE (the look-ahead: env.lookahead;
    es: train.es.population, train.es.sigma; the physics: sim.*); --print-config shows them all.
    """
    from agents.cluster import executor
    from agents.jobs import GeneralistJob
    from warpcut.planning.generate import resolve_specs

    base = settings.resumed_job(GeneralistJob, out, resume, "generalist")
    if teachers is not None and not any(o.split("=", 1)[0].strip() == "train.algo" for o in overrides):
        overrides = ("train.algo=dagger", *overrides)  # the learner that learns from teachers
    job = settings.resolve(GeneralistJob, config_file, overrides, base)
    if base is None:
        settings.refuse_unused_settings(job, overrides)
    job.check()
    if print_config:
        settings.print_config(job)
        return
    check_network_memory(job.train)
    check_planner_memory(job.candidates, job.sim)
    if job.contours:  # a bad name or file: now
        resolve_specs(job.contours, job.sim.validated())
    out, claim = outputs.claim(out, "generalist", resume, overwrite, "generalist")
    from agents.pipelines.generalist import train_generalist  # torch: after every check

    try:
        with claim, executor(ray, device, outputs.log) as units:
            click.echo(f"training a generalist into {out} ({device})")
            summary = train_generalist(
                job, out, resume=resume, device=device, progress=not no_progress, log=outputs.log,
                cluster=units,
            )  # fmt: skip
    except KeyboardInterrupt as stop:  # Ctrl-C, SIGTERM, SIGHUP: the checkpoint is saved
        if not (out / "summary.json").is_file():
            raise
        raise errors.RunInterrupted(out) from stop
    best = summary.get("best") or {}
    click.echo(
        f"done: {summary['iterations']} iterations, {summary['env_steps']:,} env steps in "
        f"{summary['wall_time_s']:.0f} s ({summary['steps_per_s']:,.0f} steps/s)"
    )
    if best:
        click.echo(
            f"kept iteration {best['iterations']}: on the {summary['validation_contours']} held-out contours "
            f"its error is {best['validation_error']:.3f} of no tension's "
            f"({100 * (1 - best['validation_error']):+.1f}% improvement)"
        )
    click.echo(f"play it: warpcut evaluate --methods none,fixed,analytic,generalist --generalist {out}")
    click.echo(f"wrote {out}")
