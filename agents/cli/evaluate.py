"""``warpcut evaluate``: the paper's Table I protocol (:func:`agents.pipeline.evaluate_table`)."""

from __future__ import annotations

from pathlib import Path

import click

from agents.cli import common
from agents.cli.video import video_option, videos, with_videos
from agents.config import EVALUATION_CANDIDATES, EVALUATION_TRIALS, GRAD_CONFIGS, RECIPES, grad_config
from agents.methods import METHODS, TABLE_METHODS
from warpcut.sim.config import SimConfig

GRAD_FLAGS = {
    "estimator": "--grad-estimator", "iterations": "--grad-iterations",
    "es_feedback_phases": "--grad-feedback-phases", "es_feedback_only": "--grad-feedback-only",
    "es_feedback_sag": "--grad-feedback-sag",
}  # fmt: skip
"""The grad column's settings (:class:`agents.config.GradConfig` fields) by the flags that set them."""


@click.command("evaluate")
@click.option(
    "--contours",
    "contour_args",
    multiple=True,
    default=("all",),
    show_default=True,
    help="'all' (the built-in suite), names or contour files; repeat or comma-separate.",
)
@click.option(
    "--methods",
    default=",".join(TABLE_METHODS),
    show_default=True,
    help=f"Comma-separated methods, of {','.join(METHODS)} (grad: an open-loop plan optimised through the "
    "differentiable simulator, per contour).",
)
@common.count_option("trials", EVALUATION_TRIALS, "Trials per contour.")
@common.noise_option
@common.score_option
@click.option(
    "--checkpoints",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    default=None,
    help="Directory of trained runs, one per contour (CHECKPOINTS/NAME, as 'warpcut train' writes); "
    "without it the rl column trains a policy per contour.",
)
@click.option(
    "--allow-partial",
    is_flag=True,
    help="Accept --checkpoints runs whose training was interrupted (their last saved policy).",
)
@common.recipe_option
@common.count_option(
    "iterations", None, f"Iterations per contour when training. {common.BATCH_DEFAULTS_HELP}"
)
@common.count_option("num-envs", None, f"Envs when training. {common.BATCH_DEFAULTS_HELP}")
@common.estimator_option("grad-estimator", "the grad column's optimiser (and a recipe's on its plans)")
@common.count_option(
    "grad-iterations",
    None,
    "Adam steps per contour of the grad column's optimiser; default "
    f"{GRAD_CONFIGS['tape'].iterations} (tape), {GRAD_CONFIGS['es'].iterations} (es).",
)
@common.feedback_options("grad-", "the grad column")
@common.device_option
@common.seed_option
@common.out_option("logs/evaluate-TIMESTAMP; results and trained policies")
@common.run_dir_options
@common.json_option
@click.option(
    "--markdown",
    "markdown_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the table as Markdown here.",
)
@click.option(
    "--plan/--no-plan",
    default=True,
    show_default=True,
    help="Cut every contour as planned (segments, order) and pinch fixed and rl at the planned point "
    "(analytic at the centroid, as in the paper; see --analytic-pinch); --no-plan: one loop per contour, "
    "fixed by random search, rl at the centroid (or the feasible point nearest to it).",
)
@common.count_option("candidates", EVALUATION_CANDIDATES, "Pinch candidates per plan.")
@common.arm_length_option
@common.analytic_pinch_option
@common.record_option("in the run directory; of the first contour, at most --trials envs")
@video_option
@common.plots_option(
    "improvement.png/svg, regions/CONTOUR.png/svg and plans/CONTOUR.png/svg in the run directory, and "
    "policies/CONTOUR/learning_curve.png/svg when training"
)
def command(
    contour_args: tuple[str, ...],
    methods: str,
    trials: int,
    noise: float,
    score: str,
    checkpoints: Path | None,
    allow_partial: bool,
    recipe: str,
    iterations: int,
    num_envs: int,
    grad_estimator: str,
    grad_iterations: int | None,
    grad_feedback_phases: int | None,
    grad_feedback_only: bool,
    grad_feedback_sag: bool,
    plan: bool,
    candidates: int,
    arm_length: float,
    analytic_pinch: str,
    device: str | None,
    seed: int,
    out: Path | None,
    resume: bool,
    overwrite: bool,
    json_path: Path | None,
    markdown_path: Path | None,
    record_envs: int | None,
    colour_by: str,
    video_envs: int | None,
    no_plots: bool,
) -> None:
    """The paper's Table I: per contour the no-tension error and each method's improvement (95% CI)."""
    from agents.pipeline import evaluate_table
    from warpcut.io import safe_name, write_atomic, write_json
    from warpcut.planning import ArmModel

    names = common.parse_methods(methods, "--methods", tuple(METHODS))
    common.check_es_batch(RECIPES[recipe], num_envs)
    if "rl" not in names:
        training = ["checkpoints", "allow_partial", "recipe", "iterations", "num_envs"]
        common.refuse_unused(training, "only with rl in --methods (they train or load its policies)")
    if "grad" not in names and not (RECIPES[recipe].base_plan and "rl" in names):
        grad = ["grad_estimator", "grad_iterations", "grad_feedback_phases", "grad_feedback_only"]
        common.refuse_unused(
            [*grad, "grad_feedback_sag"],
            "only with grad in --methods, or a --recipe on grad plans",
        )
    record_envs = _first_contour_envs("--record", record_envs, trials, "recording")
    video_envs = _first_contour_envs("--video", video_envs, trials, "filming")
    common.check_outputs({"--json": json_path, "--markdown": markdown_path}, list(contour_args))
    try:
        grad = grad_config(
            grad_estimator,
            iterations=grad_iterations,
            es_feedback_phases=grad_feedback_phases,
            es_feedback_only=grad_feedback_only,
            es_feedback_sag=grad_feedback_sag,
        )
    except ValueError as error:
        raise common.flag_error(error, GRAD_FLAGS) from None
    out, claim = common.claim(out, "evaluate", resume, overwrite)
    cuts = common.final_cuts(no_plots)
    from agents.progress import stage_bars

    bars = stage_bars()
    with (
        claim,
        bars as stages,
        common.recorder(out, record_envs, colour_by) as rec,
        videos(out, video_envs) as vid,
    ):
        report = evaluate_table(
            contour_args, out, resume=resume, methods=names, trials=trials,
            config=SimConfig(noise_std=noise, score=score),
            checkpoints=checkpoints, allow_partial=allow_partial, recipe=RECIPES[recipe],
            iterations=iterations, num_envs=num_envs,
            plan=plan,
            candidates=candidates,
            arm=ArmModel(length_mm=arm_length), analytic_pinch=analytic_pinch,
            grad=grad,
            device=device,
            seed=seed, log=common.log, stages=stages,
            step_callbacks=with_videos(common.step_callbacks(rec, cuts), vid),
        )  # fmt: skip
    table = report.markdown()
    click.echo(table)
    click.echo(f"({len(report.contours)} contours x {trials} trials in {report.seconds:.0f} s)")
    if "grad_initial_plan_contours" in report.table:
        click.echo(
            f"grad kept its initial plan (hold still) on {report.table['grad_initial_plan_contours']} of "
            f"{len(report.contours)} contours"
        )
    if "rl_initial_policy_contours" in report.table:
        click.echo(
            f"rl kept its initial policy on {report.table['rl_initial_policy_contours']} of "
            f"{len(report.contours)} contours"
        )
    if json_path:
        write_json(json_path, report.to_json())
    if markdown_path:
        write_atomic(markdown_path, table + "\n")
    if cuts is not None:
        from warpcut.viz.plots import plot_improvements, plot_pinch_candidates

        common.echo_written(plot_improvements(report.to_json(), names, out))
        shown = ["none"] + [m for m in names if m != "none"]
        common.echo_written(cuts.plot(out / "regions", shown, [c.name for c in report.contours]))
        for p in report.plans or []:
            name = safe_name(p.contour.name)
            common.echo_written(plot_pinch_candidates(p, report.config, out / "plans", name=name))
        common.plot_learning_curves({run: run.name for run in report.policy_runs})
    common.echo_recording(rec)
    click.echo(f"wrote {out}")


def _first_contour_envs(option: str, envs: int | None, trials: int, doing: str) -> int | None:
    """``envs`` to record or film of the first contour, at most its ``trials`` (with a warning)."""
    if envs is None or envs <= trials:
        return envs
    click.echo(
        f"warning: {option} {envs}: the first contour has only {trials} env(s) per method (--trials); "
        f"{doing} {trials}",
        err=True,
    )
    return trials
