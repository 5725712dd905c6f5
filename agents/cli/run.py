"""``warpcut run``: the main job (:func:`agents.pipeline.run_pipeline`)."""

from __future__ import annotations

from pathlib import Path

import click

from agents.cli import common
from agents.config import (
    APG_BATCH,
    BUDGETS,
    DEFAULT_BUDGET,
    DEFAULT_CONTOUR,
    DEFAULT_SELECTOR,
    RECIPES,
    SHARED_BASE_PLAN,
)
from agents.methods import SELECTORS, point_text
from warpcut.sim.config import SimConfig


@click.command("run")
@click.option(
    "--contour",
    "contour_name",
    default=DEFAULT_CONTOUR,
    show_default=True,
    help="Built-in name or a .json/.svg contour file.",
)
@click.option(
    "--budget",
    default=DEFAULT_BUDGET,
    show_default=True,
    type=click.Choice(list(BUDGETS)),
    help="; ".join(
        f"{name}: {b['candidates']} pinch candidates (plus the centroid when feasible), a PPO policy for "
        + ("every one" if b["rl_candidates"] is None else f"each of the best {b['rl_candidates']}")
        + f", {b['iterations']} PPO iterations each, {b['trials']} trials"
        for name, b in BUDGETS.items()
    )
    + ". fast: about a minute on 2 CPU cores; paper: hours.",
)
@click.option(
    "--policy",
    "run_policy",
    default=DEFAULT_SELECTOR,
    show_default=True,
    type=click.Choice(SELECTORS),
    help="The tensioner that picks the pinch candidate (each candidate with its best order): rl (a PPO "
    "policy per candidate, the one that validates best wins); fixed or analytic for quick plans without "
    "training.",
)
@click.option(
    "--shared-policy",
    is_flag=True,
    help="Train one PPO policy for all the RL candidates (it observes its pinch point) instead of one each: "
    "about K times faster, but it lost to separate policies where they learn (docs/learning.md).",
)
@common.recipe_option
@common.randomize_options
@common.count_option("candidates", None, "Override the budget's pinch candidates.")
@common.count_option(
    "rl-candidates",
    None,
    "Override how many of the best candidates (ranked by fixed tension) get a PPO policy.",
)
@common.count_option(
    "iterations",
    None,
    f"Override the budget's PPO iterations (--recipe apg: APG's own, {APG_BATCH['iterations']}; --recipe es: "
    "as many whole cuts as PPO's env steps).",
)
@click.option(
    "--validation-trials",
    default=None,
    type=click.IntRange(min=1),
    help="Held-out episodes per validation of each policy (default: the recipe's, 16); more make model "
    "selection steadier under --randomize.",
)
@common.count_option("trials", None, "Override the budget's evaluation trials.")
@common.count_option(
    "num-envs",
    None,
    "Envs per policy (default: the recipe's algorithm's, PPO 256, APG 16, es 256; with --shared-policy at "
    "least 8 per candidate).",
)
@common.resolution_option
@common.noise_option
@common.score_option
@common.arm_length_option
@common.analytic_pinch_option
@common.device_option
@common.seed_option
@common.out_option("logs/run-CONTOUR-TIMESTAMP")
@common.run_dir_options
@common.json_option
@common.record_option("in the run directory")
@common.plots_option("in the run directory")
def command(
    contour_name: str,
    budget: str,
    run_policy: str,
    shared_policy: bool,
    recipe: str,
    randomize: str | None,
    randomize_range: tuple[str, ...],
    relative_reward: bool,
    candidates: int | None,
    rl_candidates: int | None,
    iterations: int | None,
    validation_trials: int | None,
    trials: int | None,
    num_envs: int | None,
    resolution: int,
    noise: float,
    score: str,
    arm_length: float,
    analytic_pinch: str,
    device: str | None,
    seed: int,
    out: Path | None,
    resume: bool,
    overwrite: bool,
    json_path: Path | None,
    record_envs: int | None,
    colour_by: str,
    no_plots: bool,
) -> None:
    """The whole pipeline: plan the cut, pick the pinch candidate with a tensioner (RL: a policy per
    candidate), compare none/fixed/analytic/RL."""
    import numpy as np

    from agents.pipeline import run_pipeline
    from warpcut.contours import load_contour
    from warpcut.io import safe_name, write_json
    from warpcut.planning import ArmModel

    if run_policy != "rl":
        training = ["shared_policy", "recipe", "randomize", "randomize_range", "relative_reward"]
        training += ["rl_candidates", "iterations", "validation_trials"]
        common.refuse_unused(training, f"only with --policy rl (--policy {run_policy} trains no policy)")
    common.check_outputs({"--json": json_path}, [contour_name])
    chosen_recipe = common.randomized_recipe(RECIPES[recipe], randomize, randomize_range, relative_reward)
    common.check_es_batch(chosen_recipe, num_envs)
    if shared_policy and chosen_recipe.base_plan:
        raise click.UsageError(f"--{SHARED_BASE_PLAN}")
    if validation_trials is not None:
        import dataclasses

        chosen_recipe = dataclasses.replace(chosen_recipe, validation_trials=validation_trials)
    out, claim = common.claim(out, f"run-{safe_name(load_contour(contour_name).name)}", resume, overwrite)
    cuts = common.final_cuts(no_plots)
    with claim, common.recorder(out, record_envs, colour_by) as rec:
        report = run_pipeline(
            contour_name, out, resume=resume, budget=budget, selector=run_policy, shared_policy=shared_policy,
            recipe=chosen_recipe,
            candidates=candidates, rl_candidates=rl_candidates, iterations=iterations, trials=trials,
            num_envs=num_envs, config=SimConfig(resolution=resolution, noise_std=noise, score=score),
            arm=ArmModel(length_mm=arm_length), analytic_pinch=analytic_pinch, device=device,
            seed=seed, log=common.log, step_callbacks=common.step_callbacks(rec, cuts),
        )  # fmt: skip
    name, pinch, row = report.contour.name, report.plan.chosen["pinch"], report.row
    click.echo(
        f"{name}: planned order {list(report.plan.order)}, pinch {point_text(pinch)}; "
        f"{report.table['trials']} trials, {report.seconds:.0f} s"
    )
    click.echo(f"{'method':<10} {'error (vertices)':>16} {'improvement':>14} {'pinch (mm)':>16}")
    for m in report.methods:
        p = row[f"{m}_pinch"]
        p_txt = "-" if p is None else point_text(p)
        imp = row[f"{m}_improvement_pct"]
        imp_txt = f"{imp:+.1f}% ±{row[f'{m}_ci95']:.1f}" if np.isfinite(imp) else "n/a"
        click.echo(f"{m:<10} {row[f'{m}_error_vertices']:>16.1f} {imp_txt:>14} {p_txt:>16}")
    if json_path:
        write_json(json_path, report.to_json())
    if cuts is not None:
        from warpcut.viz.plots import plot_improvements, plot_pinch_candidates, plot_regions

        common.plot_learning_curves({run: _policy_title(report, run, out) for run in report.policy_runs})
        common.echo_written(plot_regions(cuts.of(name, report.methods), out))
        common.echo_written(plot_improvements(report.to_json(), report.methods[1:], out))
        common.echo_written(plot_pinch_candidates(report.plan, report.config, out))
    common.echo_recording(rec)
    click.echo(f"wrote {out}")


def _policy_title(report, run: Path, out: Path) -> str:
    """The learning curve's title of a policy the pipeline trained: its contour and pinch candidate(s)."""
    served = [c for c in report.candidates if c.get("run") == str(run.relative_to(out))]
    if len(served) == 1:
        pinch = served[0]["pinch"]
        return f"{report.contour.name}, pinch {point_text(pinch)}"
    return f"{report.contour.name}, one policy for {len(served)} pinch candidates"
