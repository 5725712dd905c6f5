"""``warpcut optimize``: a plan of grasp moves optimised through the simulator, then evaluated
(:func:`agents.pipelines.optimize_contour`)."""

from __future__ import annotations

from pathlib import Path

import click

from agents.cli import options, outputs, settings
from agents.config import EVALUATION_TRIALS
from agents.methods import point_text
from agents.plan_optimizer.config import GRAD_CONFIG, GRAD_CONFIGS, GRAD_ESTIMATORS


@click.command("optimize", cls=settings.Command)
@options.contour_setting()
@click.option(
    "--pinch",
    cls=options.Setting,
    key="pinch",
    default=None,
    callback=options.point_callback,
    help="Pinch point X,Y (mm); default: the plan's (fixed tension's best candidate).",
)
@click.option(
    "--estimator",
    cls=options.Setting,
    key="grad.estimator",
    type=click.Choice(GRAD_ESTIMATORS),
    default=GRAD_CONFIG.estimator,
    show_default=True,
    help="How the optimiser estimates its gradient: 'es', evolution strategies on the path score itself "
    "(perturbed plans cut in one batch; with grad.es_feedback_phases, feedback gains too); 'tape', the path "
    "surrogate's through wp.Tape (weaker on the suite: docs/results.md).",
)
@options.count_option(
    "iterations",
    None,
    f"Optimiser steps; default the estimator's: {GRAD_CONFIGS['es'].iterations} (es: one batch of perturbed "
    f"plans each), {GRAD_CONFIGS['tape'].iterations} (tape: a forward and a backward pass each).",
    key="grad.iterations",
)
@options.count_option(
    "trials", EVALUATION_TRIALS, "Evaluation trials (none, fixed and grad, paired).", key="trials"
)
@options.seed_option
@options.device_option
@options.out_option("logs/optimize-CONTOUR-TIMESTAMP; the plan, the optimiser's state and results.json")
@click.option(
    "--resume",
    is_flag=True,
    help="Continue the run in --out (interrupted, or to finish it): a finished plan is kept, an interrupted "
    "optimisation continues from its state; the settings must be the run's (its config.json).",
)
@options.overwrite_option
@options.json_option
@options.config_options
def command(
    contour: str | None,
    pinch: list[float] | None,
    estimator: str,
    iterations: int | None,
    trials: int,
    seed: int,
    device: str | None,
    out: Path | None,
    resume: bool,
    overwrite: bool,
    json_path: Path | None,
    config_file: str | None,
    overrides: tuple[str, ...],
    print_config: bool,
) -> None:
    """Optimise grasp moves through the simulator (tape or es gradients; with es, also feedback gains), then
    evaluate them against no tension and fixed tension at the same pinch point.

    Everything but the flags is set with --config FILE and --set KEY=VALUE (the optimiser: grad.*, e.g.
    grad.learning_rate, grad.es_population, grad.es_feedback_phases, grad.es_randomize; the physics and
    noise: sim.*; candidates, arm.length_mm); --print-config shows them all.
    """
    from agents.jobs import OptimizeJob
    from agents.pipelines import optimize_contour
    from warpcut.io import safe_name, write_json
    from warpcut.planning import resolve_contour

    base = settings.resumed_job(OptimizeJob, out, resume, "optimize")
    job = settings.resolve(OptimizeJob, config_file, overrides, base).check()
    if base is None:  # a resumed run's config.json holds every setting it was started with
        settings.refuse_unused_settings(job, overrides)
    contour = resolve_contour(job.contour, job.sim)  # a bad name or file: now
    contour_name = contour.name
    if print_config:
        settings.print_config(job)
        return
    if job.pinch is not None:  # an infeasible pinch point: now
        from warpcut.planning import check_pinch

        check_pinch(job.pinch, contour, job.sim.validated(), None, job.arm, allow=job.allow_infeasible_pinch)
    out, claim = outputs.claim(out, f"optimize-{safe_name(contour_name)}", resume, overwrite, "optimize")
    outputs.check_outputs(
        {"--json": json_path}, [job.contour] if isinstance(job.contour, str) else [], own=(out, "optimize")
    )
    with claim:
        report = optimize_contour(job, out, resume=resume, device=device, log=outputs.log)
    optimized = report["optimized"]
    click.echo(
        f"{report['contour']}: pinch {point_text(optimized['pinch'])}, kept iteration "
        f"{optimized['best_iteration']} of {job.grad.iterations}, {optimized['seconds']:.0f} s, "
        f"{optimized['env_steps']} env steps"
    )
    click.echo(f"{'method':<8} {'error (vertices)':>16} {'improvement':>12}")
    for name, row in report["evaluation"].items():
        ci = f" ±{row['ci95_pct']:.1f}" if job.trials > 1 else ""  # no CI of one sample
        improvement = f"{row['improvement_pct']:>+11.1f}%{ci}"
        mark = outputs.infeasible_mark(row["pinch_feasible"])
        click.echo(f"{name:<8} {row['error_vertices']:>16.1f} {improvement}{mark}")
    outputs.echo_infeasible({"fixed, grad": report["pinch_problem"]})
    if json_path:
        write_json(json_path, report)
    click.echo(f"wrote {out}")
