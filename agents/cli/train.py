"""``warpcut train``: train a tensioner for one contour into a run directory
(:func:`agents.training.train_contour`)."""

from __future__ import annotations

from pathlib import Path

import click

from agents.algorithms import ALGORITHMS, DEFAULT_ALGORITHM
from agents.cli import errors, options, outputs, settings
from agents.cli.video import videos, with_videos


@click.command("train", cls=settings.Command)
@options.contour_setting()
@click.option(
    "--pinch",
    cls=options.Setting,
    key="pinch",
    default=None,
    callback=options.point_callback,
    help="Pinch point X,Y (mm); default: the centroid, or the feasible point nearest it.",
)
@click.option(
    "--algo",
    cls=options.Setting,
    key="train.algo",
    type=click.Choice(list(ALGORITHMS)),
    default=DEFAULT_ALGORITHM,
    show_default=True,
    help="The learner: " + "; ".join(f"{a.name}: {a.summary}" for a in ALGORITHMS.values()) + ".",
)
@options.count_option(
    "num-envs", None, "Parallel envs (default: the learner's, 256 for es and ppo).", key="train.num_envs"
)
@options.count_option(
    "iterations",
    None,
    "Iterations in total, a resumed run's included (default: the learner's).",
    key="train.iterations",
)
@options.seed_option
@options.device_option
@options.out_option("logs/train-CONTOUR-TIMESTAMP")
@click.option(
    "--resume",
    type=click.Path(exists=True, path_type=Path),
    default=None,
    help="Run directory (or checkpoint) to continue, with the run's own settings (its config.json); only "
    "--iterations, to train longer, may change.",
)
@options.overwrite_option
@options.record_flag("of the final evaluation, in the run directory")
@click.option("--no-progress", is_flag=True, help="Hide the progress bar.")
@options.config_options
def command(
    contour: str | None,
    pinch: list[float] | None,
    algo: str,
    num_envs: int | None,
    iterations: int | None,
    seed: int,
    device: str | None,
    out: Path | None,
    resume: Path | None,
    overwrite: bool,
    record_envs: int | None,
    no_progress: bool,
    config_file: str | None,
    overrides: tuple[str, ...],
    print_config: bool,
) -> None:
    """Train a tensioning policy for one contour (the default learner, gps, or --algo es|ppo|apg).

    Everything but the flags is set with --config FILE and --set KEY=VALUE (the env's observations, actions
    and reward: env.*; the physics and noise: sim.*; the learner: train.*; fine-tuning from a generalist:
    init=generalist, or init=DIR of 'warpcut generalist'; init_gain: the factor on its moves it starts
    from); --print-config shows them all.
    """
    from agents.jobs import CONFIG_FILE, TrainJob
    from warpcut.io import RUN_MARKER, check_run_dir, enclosing_run, read_run_marker, safe_name

    base, run = None, None
    if resume is not None:
        run = resume if resume.is_dir() else resume.parent
        if out is not None and out.resolve() != run.resolve():
            raise click.BadParameter(
                f"a resumed run continues in its own directory ({run}), never in another; drop --out {out}",
                param_hint="--out",
            )
        if resume.is_file() and read_run_marker(run) is None and enclosing_run(run) is None:
            raise click.BadParameter(
                f"{resume}: not a checkpoint of a warpcut run ({run} holds no {RUN_MARKER}); give the "
                "directory of a warpcut train run, or one of its checkpoints",
                param_hint="--resume",
            )
        check_run_dir(run, command="train", resume=True)  # before its settings are read
        base = settings.saved_job(TrainJob, run / CONFIG_FILE)
    job = settings.resolve(TrainJob, config_file, overrides, base)
    if run is not None:
        from agents.training import check_resumed_job

        check_resumed_job(run, job)
    else:  # a resumed run's config.json holds every setting it was started with
        settings.refuse_unused_settings(job, overrides)
    scenario = job.options(device)
    settings.check_learner(job)
    contour_name = scenario.per_env(1)[0][0].name  # a bad contour or an infeasible default pinch: now
    if print_config:
        settings.print_config(job)
        return
    out = out or (run if run is not None else outputs.run_dir(None, f"train-{safe_name(contour_name)}"))
    out, claim = outputs.claim(out, "train", resume is not None, overwrite, "train")
    from agents.checkpoints import resume_checkpoint, saved_nothing  # torch: after every check
    from agents.training import train_contour

    try:
        with claim, outputs.recorder(out, job.record, job.colour_by) as rec, videos(out, job.video) as vid:
            if run is not None and saved_nothing(run):
                click.echo(f"{run} saved no checkpoint before it stopped: training it from the start")
            elif run is not None:
                checkpoint, state, _ = resume_checkpoint(resume)
                done = (state.get("infos") or {}).get("iterations_done", state.get("iter", -1) + 1)
                click.echo(
                    f"resuming {contour_name} with {job.train.algo} in {out} ({device}) after iteration "
                    f"{done} ({checkpoint.name})"
                )
            else:
                click.echo(f"training {contour_name} with {job.train.algo} into {out} ({device})")
                if job.at_generalists_cut:
                    click.echo(
                        "  from the generalist, where it plays: the plan's candidate it validates best at"
                    )
            result = train_contour(
                job,
                out,
                resume=resume,
                device=device,
                progress=not no_progress,
                step_callbacks=with_videos(outputs.step_callbacks(rec, None), vid),
            )
    except KeyboardInterrupt as stop:  # Ctrl-C, SIGTERM, SIGHUP: the checkpoint is saved
        if not (out / "summary.json").is_file():
            raise
        raise errors.RunInterrupted(out) from stop
    s, e = result["summary"], result["evaluation"]
    click.echo(
        f"done: {s['iterations']} iterations, {s['env_steps']:,} env steps in {s['wall_time_s']:.0f} s "
        f"({s['steps_per_s']:,.0f} steps/s)"
    )
    click.echo(
        f"evaluation ({e['trials']} trials): no tension {e['none_error_vertices']:.1f} vertices, "
        f"rl {e['rl_error_vertices']:.1f} vertices, improvement {e['rl_improvement_pct']:+.1f}%"
        + (f" ± {e['rl_ci95']:.1f}" if e["trials"] > 1 else "")  # no CI of one sample
        + outputs.infeasible_mark(e["pinch_feasible"])
    )
    outputs.echo_infeasible({"rl": e["pinch_problem"]})
    if job.plots:
        from agents.plots import plot_learning_curve

        outputs.echo_written(plot_learning_curve(s["history"], s["validation"], out, title=contour_name))
    outputs.echo_recording(rec)
    click.echo(f"wrote {out}")
