"""``warpcut train``: train a PPO tensioner for one contour into a run directory."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from agents.cli import common
from agents.config import EVALUATION_TRIALS, RECIPE, VALIDATION_TRIALS, TrainConfig
from warpcut.sim.config import SimConfig

TRAIN = TrainConfig()
"""The PPO settings the options show and pass on (the library's defaults)."""


@click.command("train")
@common.contour_option
@click.option(
    "--pinch", default=None, help="Pinch point X,Y (mm); default: centroid or nearest feasible point."
)
@common.count_option("num-envs", TRAIN.num_envs, "Parallel envs.")
@common.count_option(
    "iterations", TRAIN.iterations, "PPO iterations in total (a resumed run continues up to this count)."
)
@common.count_option("steps-per-env", TRAIN.num_steps_per_env, "Env steps per env per PPO iteration.")
@common.noise_option
@common.score_option
@click.option(
    "--reward",
    default="dense" if RECIPE["dense_reward"] else "sparse",
    show_default=True,
    type=click.Choice(["sparse", "dense"]),
    help="sparse: -(final error / area) at the last step only (paper); dense: plus per-step shaping by the "
    "cut's deviation from the contour in material coordinates (learns in short runs, docs/learning.md).",
)
@click.option(
    "--observe",
    default="contour" if RECIPE["contour_features"] else "fiducials",
    show_default=True,
    type=click.Choice(["fiducials", "contour"]),
    help="fiducials: time, grasp displacement, 12 fiducials (paper); contour: plus the scissor tip and the "
    "vector to the contour point it is about to cut.",
)
@click.option(
    "--actions",
    "action_type",
    default=RECIPE["action_type"],
    show_default=True,
    type=click.Choice(["discrete", "continuous"]),
    help="discrete: stay, +-x, +-y (and +-z) at 1 mm (paper: x-y); continuous: moves up to 1 mm per axis.",
)
@click.option(
    "--z/--no-z",
    "allow_z",
    default=RECIPE["allow_z"],
    show_default=True,
    help="Let the grasp also move along z (lift or lower the sheet); --no-z: x-y only (paper).",
)
@click.option(
    "--stay-prior",
    default=TRAIN.stay_prior,
    show_default=True,
    type=click.FloatRange(0.0, 1.0, max_open=True),
    help="Discrete: initial probability of 'stay', so training starts from holding still (fixed "
    "tensioning); 0: a uniform start (paper).",
)
@click.option(
    "--validation-trials",
    default=VALIDATION_TRIALS,
    show_default=True,
    type=click.IntRange(min=0),
    help="Held-out episodes scoring the policy every 10 iterations; the best is kept (best.pt). 0: off, "
    "the last policy is the run's.",
)
@common.count_option("eval-trials", EVALUATION_TRIALS, "Trials of the final evaluation against no tension.")
@common.device_option
@common.seed_option
@common.out_option("logs/train-CONTOUR-TIMESTAMP")
@click.option(
    "--resume",
    type=click.Path(exists=True, path_type=Path),
    default=None,
    help="Run directory or checkpoint to continue from (writes into it unless --out is given).",
)
@common.record_option("of the final evaluation, in the run directory")
@common.plots_option("learning_curve.png/svg in the run directory")
@click.option("--no-progress", is_flag=True, help="Hide the progress bar.")
def command(
    contour_name: str,
    pinch: str | None,
    num_envs: int,
    iterations: int,
    steps_per_env: int,
    noise: float,
    score: str,
    reward: str,
    observe: str,
    action_type: str,
    allow_z: bool,
    stay_prior: float,
    validation_trials: int,
    eval_trials: int,
    device: str | None,
    seed: int,
    out: Path | None,
    resume: Path | None,
    record_envs: int | None,
    colour_by: str,
    no_plots: bool,
    no_progress: bool,
) -> None:
    """Train a PPO tensioning policy (rsl-rl, 2x32 MLP, 1 mm moves) for one contour."""
    from agents.rl import load_options, train_contour
    from envs.options import PatternCutOptions
    from warpcut.contours import load_contour

    point = common.parse_point(pinch, "--pinch")
    if resume is not None:
        run = resume if resume.is_dir() else resume.parent
        options, out = load_options(run, device), out or run
    else:
        options = PatternCutOptions(
            contour=contour_name,
            pinch_point=point,
            sim_config=SimConfig(noise_std=noise, score=score).validated(),
            device=device,
            action_type=action_type,
            dense_reward=reward == "dense",
            contour_features=observe == "contour",
            allow_z=allow_z,
        )
        options.per_env(1)  # fail early on a bad contour or an infeasible default pinch
        out = common.run_dir(out, f"train-{load_contour(contour_name).name}")
    name, discrete = options.contours(1)[0].name, options.action_type == "discrete"
    cfg = TrainConfig(
        num_envs=num_envs, iterations=iterations, num_steps_per_env=steps_per_env, seed=seed,
        discrete=discrete, stay_prior=stay_prior if discrete else 0.0,
    )  # fmt: skip
    click.echo(f"training {name} into {out} ({num_envs} envs, {iterations} iterations, {device})")
    try:
        with common.recorder(out, record_envs, colour_by) as rec:
            result = train_contour(
                options, out, cfg, resume=resume, eval_trials=eval_trials, progress=not no_progress,
                validation_trials=validation_trials, step_callbacks=common.step_callbacks(rec, None),
            )  # fmt: skip
    except KeyboardInterrupt:
        click.echo(f"interrupted: checkpoint saved in {out}; continue with --resume {out}", err=True)
        sys.exit(130)
    s, e = result["summary"], result["evaluation"]
    click.echo(
        f"done: {s['iterations']} iterations, {s['env_steps']:,} env steps in {s['wall_time_s']:.0f} s "
        f"({s['steps_per_s']:,.0f} steps/s)"
    )
    click.echo(
        f"evaluation ({e['trials']} trials): no tension {e['none_error_vertices']:.1f} vertices, "
        f"rl {e['rl_error_vertices']:.1f} vertices, improvement {e['rl_improvement_pct']:+.1f}% "
        f"± {e['rl_ci95']:.1f}"
    )
    if not no_plots:
        from warpcut.viz.plots import plot_learning_curve

        common.echo_written(plot_learning_curve(s["history"], s["validation"], out, title=name))
    common.echo_recording(rec)
    click.echo(f"wrote {out}")
