"""``warpcut optimize``: an open-loop tension plan optimised through the differentiable simulator
(:func:`agents.gradient.optimize_contour`)."""

from __future__ import annotations

from pathlib import Path

import click

from agents.cli import common
from agents.config import EVALUATION_CANDIDATES, EVALUATION_TRIALS, GRAD_CONFIG, GRAD_CONFIGS, grad_config
from agents.methods import point_text
from warpcut.sim.config import SimConfig

GRAD_FLAGS = {
    "estimator": "--estimator", "iterations": "--iterations", "trials": "--episodes", "learning_rate": "--lr",
    "es_population": "--population", "es_trials": "--population-episodes", "es_sigma_mm": "--sigma",
    "es_feedback_phases": "--feedback-phases", "es_feedback_only": "--feedback-only",
    "es_feedback_sag": "--feedback-sag", "es_randomize": "--randomize",
    "es_randomize_ranges": "--randomize-range", "optimize_pinch": "--optimize-pinch",
}  # fmt: skip
"""The optimiser's settings (:class:`agents.config.GradConfig` fields) by the flags that set them."""


@click.command("optimize")
@common.contour_option
@click.option(
    "--pinch",
    default=None,
    help="Pinch point X,Y (mm); default: the plan's (fixed tension's best candidate).",
)
@common.estimator_option("estimator", "the optimiser")
@common.count_option(
    "iterations",
    None,
    f"Adam steps; default {GRAD_CONFIGS['tape'].iterations} (tape: a forward and a backward pass each), "
    f"{GRAD_CONFIGS['es'].iterations} (es: one batch of perturbed plans each).",
)
@common.count_option(
    "episodes", GRAD_CONFIG.trials, "Noisy episodes per tape step (their noise is not the evaluation's)."
)
@click.option(
    "--lr",
    "learning_rate",
    default=None,
    type=common.FloatRange(min=0.0, min_open=True),
    help=f"Adam's step (mm per grasp move); default {GRAD_CONFIGS['tape'].learning_rate} (tape), "
    f"{GRAD_CONFIGS['es'].learning_rate} (es).",
)
@common.count_option("population", GRAD_CONFIGS["es"].es_population, "Perturbed plans per es step (even).")
@common.count_option(
    "population-episodes", GRAD_CONFIGS["es"].es_trials, "Noisy episodes per perturbed plan (es)."
)
@click.option(
    "--sigma",
    default=GRAD_CONFIGS["es"].es_sigma_mm,
    show_default=True,
    type=common.FloatRange(min=0.0, min_open=True),
    help="Standard deviation of es's perturbation of each move (mm).",
)
@common.feedback_options("", "the policy")
@click.option(
    "--randomize",
    default=None,
    metavar="PARAMS",
    help="es: physical parameters drawn anew at every step for the episodes, comma-separated from "
    "warpcut.sim.config.RANDOMIZE_RANGES (over those ranges, or --randomize-range's); errors weighed by the "
    "nominal sheet's no-tension error over their own sheet's. Default: the nominal sheet.",
)
@common.randomize_range_option
@click.option(
    "--optimize-pinch",
    is_flag=True,
    help="Also move the pinch point along its gradient (kept feasible).",
)
@common.count_option("trials", EVALUATION_TRIALS, "Evaluation trials (none, fixed and grad, paired).")
@common.count_option("candidates", EVALUATION_CANDIDATES, "Pinch candidates of the plan.")
@common.noise_option
@common.score_option
@common.arm_length_option
@common.device_option
@common.seed_option
@common.out_option("logs/optimize-TIMESTAMP; the plan, the optimiser's state and results.json")
@common.run_dir_options
@common.json_option
def command(
    contour_name: str,
    pinch: str | None,
    estimator: str,
    iterations: int | None,
    episodes: int,
    learning_rate: float | None,
    population: int,
    population_episodes: int,
    sigma: float,
    feedback_phases: int | None,
    feedback_only: bool,
    feedback_sag: bool,
    randomize: str | None,
    randomize_range: tuple[str, ...],
    optimize_pinch: bool,
    trials: int,
    candidates: int,
    noise: float,
    score: str,
    arm_length: float,
    device: str | None,
    seed: int,
    out: Path | None,
    resume: bool,
    overwrite: bool,
    json_path: Path | None,
) -> None:
    """Optimise grasp moves by gradient descent through the simulator (tape or es gradients; with es, also
    feedback gains), then evaluate them."""
    from agents.gradient import optimize_contour
    from warpcut.io import write_json
    from warpcut.planning import ArmModel

    point = common.parse_point(pinch, "--pinch")
    _, ranges = common.parse_randomization(randomize, randomize_range)
    common.check_outputs({"--json": json_path}, [contour_name])
    try:
        settings = grad_config(
            estimator, iterations=iterations, trials=episodes, learning_rate=learning_rate,
            es_population=population, es_trials=population_episodes, es_sigma_mm=sigma,
            es_feedback_phases=feedback_phases, es_feedback_only=feedback_only, es_feedback_sag=feedback_sag,
            es_randomize=randomize, es_randomize_ranges=ranges or None, optimize_pinch=optimize_pinch,
        )  # fmt: skip
    except ValueError as error:
        raise common.flag_error(error, GRAD_FLAGS) from None
    out, claim = common.claim(out, "optimize", resume, overwrite)
    with claim:
        report = optimize_contour(
            contour_name, out, pinch=point, settings=settings, trials=trials,
            config=SimConfig(noise_std=noise, score=score), candidates=candidates,
            arm=ArmModel(length_mm=arm_length), device=device, seed=seed, log=common.log,
        )  # fmt: skip
    optimized = report["optimized"]
    click.echo(
        f"{report['contour']}: pinch {point_text(optimized['pinch'])}, kept iteration "
        f"{optimized['best_iteration']} of {settings.iterations}, {optimized['seconds']:.0f} s, "
        f"{optimized['env_steps']} env steps"
    )
    click.echo(f"{'method':<8} {'error (vertices)':>16} {'improvement':>12}")
    for name, row in report["evaluation"].items():
        improvement = f"{row['improvement_pct']:>+11.1f}% ±{row['ci95_pct']:.1f}"
        click.echo(f"{name:<8} {row['error_vertices']:>16.1f} {improvement}")
    if json_path:
        write_json(json_path, report)
    click.echo(f"wrote {out}")
