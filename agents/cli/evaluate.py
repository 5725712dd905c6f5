"""``warpcut evaluate``: the paper's Table I protocol (:func:`agents.pipelines.evaluate_table`)."""

from __future__ import annotations

from pathlib import Path

import click

from agents import cluster
from agents.algorithms import ALGORITHMS, DEFAULT_ALGORITHM
from agents.cli import options, outputs, settings
from agents.cli.checks import check_planner_memory
from agents.cli.video import videos, with_videos
from agents.config import EVALUATION_TRIALS
from agents.methods import METHODS, TABLE_METHODS


@click.command("evaluate", cls=settings.Command)
@click.option(
    "--contours",
    cls=options.Setting,
    key="contours",
    default="all",
    show_default=True,
    callback=lambda ctx, param, value: [v.strip() for v in value.split(",") if v.strip()],
    help="'all' (the built-in suite), or comma-separated names and contour files.",
)
@click.option(
    "--methods",
    cls=options.Setting,
    key="methods",
    default=",".join(TABLE_METHODS),
    show_default=True,
    callback=lambda ctx, param, value: [v.strip() for v in value.split(",") if v.strip()],
    help=f"Comma-separated, of {','.join(METHODS)} (rl: a policy trained per contour; generalist: one "
    "policy for every contour, zero-shot; grad: an open-loop plan optimised through the differentiable "
    "simulator, per contour).",
)
@click.option(
    "--algo",
    cls=options.Setting,
    key="train.algo",
    type=click.Choice(list(ALGORITHMS)),
    default=DEFAULT_ALGORITHM,
    show_default=True,
    help="The rl column's learner.",
)
@click.option(
    "--checkpoints",
    cls=options.Setting,
    key="checkpoints",
    type=click.Path(exists=True, file_okay=False),
    default=None,
    help="Directory of trained runs, one per contour (CHECKPOINTS/NAME, as 'warpcut train' writes); "
    "without it the rl column trains a policy per contour.",
)
@options.generalist_option
@options.count_option("trials", EVALUATION_TRIALS, "Trials per contour and method.", key="trials")
@options.seed_option
@options.device_option
@options.ray_option("each contour's plan and rl policy")
@options.out_option("logs/evaluate-TIMESTAMP; results.json, results.md, plans and trained policies")
@options.run_dir_options
@options.json_option
@options.config_options
def command(
    contours: list[str],
    methods: list[str],
    algo: str,
    checkpoints: str | None,
    generalist_source: str | None,
    trials: int,
    seed: int,
    device: str | None,
    ray: str | None,
    out: Path | None,
    resume: bool,
    overwrite: bool,
    json_path: Path | None,
    config_file: str | None,
    overrides: tuple[str, ...],
    print_config: bool,
) -> None:
    """The paper's Table I: per contour the no-tension error and each method's improvement (95% CI).

    Everything but the flags is set with --config FILE and --set KEY=VALUE (e.g. sim.noise_std, candidates,
    plan, analytic_pinch, train.iterations, grad.estimator); --print-config shows them all.
    """
    from agents.jobs import EvaluateJob
    from agents.progress import stage_bars
    from warpcut.io import safe_name, write_json
    from warpcut.planning.generate import resolve_specs

    base = settings.resumed_job(EvaluateJob, out, resume, "evaluate")
    job = settings.resolve(EvaluateJob, config_file, overrides, base)
    if base is None:  # a resumed run's config.json holds every setting it was started with
        settings.refuse_unused_settings(job, overrides)
    job = job.check()
    if "rl" in job.methods and job.checkpoints is None:
        settings.check_learner(job)
    resolve_specs(job.contours, job.sim.validated())  # a bad name or file: now
    if ray is not None and not job.plan and ("rl" not in job.methods or job.checkpoints is not None):
        raise click.UsageError(
            "--ray: nothing to fan out: the units are each contour's plan (plan true) and rl policy "
            "(--methods with rl, without --checkpoints); leave out --ray"
        )
    if print_config:
        settings.print_config(job)
        return
    if job.plan:
        check_planner_memory(job.candidates, job.sim)
    record = _first_contour_envs("record", job.record, job.trials, "recording")
    video = _first_contour_envs("video", job.video, job.trials, "filming")
    out, claim = outputs.claim(out, "evaluate", resume, overwrite, "evaluate")
    outputs.check_outputs({"--json": json_path}, list(job.contours), own=(out, "evaluate"))
    cuts = outputs.final_cuts(not job.plots)
    from agents.pipelines import evaluate_table  # torch: after every check, so that a refusal is quick

    with (
        claim,
        cluster.executor(ray, device, outputs.log) as units,
        stage_bars() as stages,
        outputs.recorder(out, record, job.colour_by) as rec,
        videos(out, video) as vid,
    ):
        report = evaluate_table(
            job,
            out,
            resume=resume,
            device=device,
            log=outputs.log,
            stages=stages,
            step_callbacks=with_videos(outputs.step_callbacks(rec, cuts), vid),
            cluster=units,
        )
    click.echo(report.markdown())
    rows = report.table["rows"]
    outputs.echo_infeasible(
        {f"{r['contour']} {m}": r.get(f"{m}_pinch_problem") for r in rows for m in job.methods}
    )
    click.echo(f"({len(report.contours)} contours x {job.trials} trials in {report.seconds:.0f} s)")
    kept = (
        ("grad_initial_plan_contours", "grad kept its initial plan (hold still)"),
        ("rl_initial_policy_contours", "rl kept its initial policy (hold still)"),
        ("rl_plan_contours", "rl kept its teacher's plan (open loop)"),
        (
            "generalist_still_contours",
            "the generalist held still (its choice cut no better on fresh episodes)",
        ),
    )
    for key, what in kept:
        if key in report.table:
            click.echo(f"{what} on {report.table[key]} of {len(report.contours)} contours")
    if json_path:
        write_json(json_path, report.to_json())
        click.echo(f"wrote {json_path}")
    if cuts is not None:
        from agents.plots import plot_improvements
        from warpcut.viz.plots import plot_pinch_candidates

        outputs.echo_written(plot_improvements(report.to_json(), job.methods, out))
        shown = ["none"] + [m for m in job.methods if m != "none"]
        outputs.echo_written(cuts.plot(out / "regions", shown, [c.name for c in report.contours]))
        for p in report.plans or []:
            outputs.echo_written(
                plot_pinch_candidates(p, report.config, out / "plans", name=safe_name(p.contour.name))
            )
        outputs.plot_learning_curves({run: run.name for run in report.policy_runs})
    outputs.echo_recording(rec)
    click.echo(f"wrote {out}")


def _first_contour_envs(key: str, envs: int | None, trials: int, doing: str) -> int | None:
    """``envs`` to record or film of the first contour, at most its ``trials`` (with a warning)."""
    if envs is None or envs <= trials:
        return envs
    click.echo(
        f"warning: {key} {envs}: the first contour has only {trials} env(s) per method (trials); "
        f"{doing} {trials}",
        err=True,
    )
    return trials
