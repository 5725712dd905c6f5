"""``warpcut train``: train a tensioner (PPO, APG or es) for one contour into a run directory."""

from __future__ import annotations

from pathlib import Path

import click

from agents.cli import common
from agents.cli.video import video_option, videos, with_videos
from agents.config import (
    ALGORITHMS,
    CONTINUOUS_ALGORITHMS,
    EVALUATION_TRIALS,
    RECIPE,
    VALIDATION_TRIALS,
    TrainConfig,
    algorithm_settings,
    batch_defaults,
    es_population_error,
    iterations_text,
)
from warpcut.sim.config import SimConfig

TRAIN = TrainConfig()
"""The PPO settings the options show and pass on (the library's defaults)."""


RESUMED_FLAGS = {
    "contour_name": "--contour",
    "pinch": "--pinch",
    "noise": "--noise",
    "score": "--score",
    "reward": "--reward",
    "observe": "--observe",
    "action_type": "--actions",
    "allow_z": "--z/--no-z",
    "randomize": "--randomize",
    "relative_reward": "--relative-reward",
}
"""The env options a run fixes (its options.json): with --resume they may only repeat the run's values."""


@click.command("train")
@click.option(
    "--contour",
    "contour_name",
    default=None,
    help="Built-in name or a .json/.svg contour file (required unless --resume: a run keeps its contour).",
)
@click.option(
    "--pinch", default=None, help="Pinch point X,Y (mm); default: centroid or nearest feasible point."
)
@click.option(
    "--algo",
    default=TRAIN.algorithm,
    show_default=True,
    type=click.Choice(ALGORITHMS),
    help="ppo (rsl-rl); apg: analytic policy gradients through the differentiable simulator; es: evolution "
    "strategies on the policy's weights, whole cuts scored by the path score, the MLP plus a linear feedback "
    "path on the tracking error where the policy observes the contour (apg and es: continuous moves, one "
    "whole episode per env and iteration, their recipe's learning rate; docs/learning.md).",
)
@common.count_option("num-envs", None, f"Parallel envs. {common.BATCH_DEFAULTS_HELP}")
@common.count_option(
    "iterations",
    None,
    f"Iterations in total (a resumed run continues up to this count). {common.BATCH_DEFAULTS_HELP}",
)
@common.count_option("steps-per-env", TRAIN.num_steps_per_env, "Env steps per env per PPO iteration.")
@click.option(
    "--es-population",
    default=TRAIN.es_population,
    show_default=True,
    type=click.IntRange(min=2),
    help="es: perturbed policies per iteration (even, dividing --num-envs; each plays num-envs / population "
    "episodes).",
)
@click.option(
    "--es-sigma",
    default=TRAIN.es_sigma,
    show_default=True,
    type=common.FloatRange(min=0.0, min_open=True),
    help="es: standard deviation of the perturbations of the MLP's weights (the feedback gains have their "
    "own, --es-feedback-sigma; docs/learning.md).",
)
@click.option(
    "--es-feedback-sigma",
    default=TRAIN.es_feedback_sigma,
    show_default=True,
    type=common.FloatRange(min=0.0, min_open=True),
    help="es with the feedback path: standard deviation of the perturbations of the feedback gains (on the "
    "normalised tracking error).",
)
@click.option(
    "--es-feedback-lr",
    "es_feedback_learning_rate",
    default=TRAIN.es_feedback_learning_rate,
    show_default=True,
    type=common.FloatRange(min=0.0, min_open=True),
    help="es with the feedback path: Adam's step for the feedback gains (the MLP's is the recipe's).",
)
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
    type=common.FloatRange(0.0, 1.0, max_open=True),
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
@common.randomize_options
@common.count_option("eval-trials", EVALUATION_TRIALS, "Trials of the final evaluation against no tension.")
@common.device_option
@common.seed_option
@common.out_option("logs/train-CONTOUR-TIMESTAMP")
@click.option(
    "--resume",
    type=click.Path(exists=True, path_type=Path),
    default=None,
    help="Run directory or checkpoint to continue from (writes into it unless --out is given), with the "
    "run's options: --contour, the other env options, --seed and --validation-trials may be left out, and "
    "may not differ from the run's.",
)
@click.option(
    "--overwrite", is_flag=True, help="Replace the contents of --out (an earlier run's) instead of refusing."
)
@common.record_option("of the final evaluation, in the run directory")
@video_option
@common.plots_option("learning_curve.png/svg in the run directory")
@click.option("--no-progress", is_flag=True, help="Hide the progress bar.")
def command(
    contour_name: str | None,
    pinch: str | None,
    algo: str,
    num_envs: int | None,
    iterations: int | None,
    steps_per_env: int,
    es_population: int,
    es_sigma: float,
    es_feedback_sigma: float,
    es_feedback_learning_rate: float,
    noise: float,
    score: str,
    reward: str,
    observe: str,
    action_type: str,
    allow_z: bool,
    stay_prior: float,
    validation_trials: int,
    randomize: str | None,
    randomize_range: tuple[str, ...],
    relative_reward: bool,
    eval_trials: int,
    device: str | None,
    seed: int,
    out: Path | None,
    resume: Path | None,
    overwrite: bool,
    record_envs: int | None,
    colour_by: str,
    video_envs: int | None,
    no_plots: bool,
    no_progress: bool,
) -> None:
    """Train a tensioning policy (2x32 MLP, 1 mm moves) for one contour: PPO, APG or es."""
    from agents.rl import train_contour
    from envs.options import PatternCutOptions
    from warpcut.contours import load_contour
    from warpcut.io import safe_name

    point = common.parse_point(pinch, "--pinch")
    action_type = _actions_for(algo, action_type)
    randomized, ranges = common.parse_randomization(randomize, randomize_range)
    common.refuse_apg(bool(randomized) or relative_reward, algo)
    settings = dict(
        seed=seed, validation_trials=validation_trials, num_envs=num_envs, num_steps_per_env=steps_per_env,
        stay_prior=stay_prior, algorithm=algo, es_population=es_population, es_sigma=es_sigma,
        es_feedback_sigma=es_feedback_sigma, es_feedback_learning_rate=es_feedback_learning_rate,
    )  # fmt: skip
    if resume is not None:
        given = dict(
            contour_name=contour_name, pinch=point, noise=noise, score=score, reward=reward, observe=observe,
            action_type=action_type, allow_z=allow_z, randomize=randomized, relative_reward=relative_reward,
        )  # fmt: skip
        options, out, settings = _resumed_run(resume, device, out, given, ranges, settings)
    else:
        if contour_name is None:
            raise click.UsageError("--contour: give the contour to train on (or --resume RUN to continue)")
        options = PatternCutOptions(
            contour=contour_name,
            pinch_point=point,
            sim_config=SimConfig(noise_std=noise, score=score).validated(),
            device=device,
            action_type=action_type,
            dense_reward=reward == "dense",
            contour_features=observe == "contour",
            allow_z=allow_z,
            randomize=randomized,
            randomize_ranges=ranges or None,
            relative_reward=relative_reward,
        )
        options.per_env(1)  # fail early on a bad contour or an infeasible default pinch
        out = out or common.run_dir(None, f"train-{safe_name(load_contour(contour_name).name)}")
    name = options.contours(1)[0].name
    cfg = _train_config(settings, iterations, options)
    algo, num_envs, iterations = cfg.algorithm, cfg.num_envs, cfg.iterations
    out, claim = common.claim(out, "train", resume is not None, overwrite)
    click.echo(
        f"training {name} with {algo} into {out} ({num_envs} envs, {iterations_text(iterations)}, {device})"
    )
    try:
        with claim, common.recorder(out, record_envs, colour_by) as rec, videos(out, video_envs) as vid:
            result = train_contour(
                options, out, cfg, resume=resume, eval_trials=eval_trials, progress=not no_progress,
                validation_trials=settings["validation_trials"],
                step_callbacks=with_videos(common.step_callbacks(rec, None), vid),
            )  # fmt: skip
    except KeyboardInterrupt as stop:  # Ctrl-C, SIGTERM, SIGHUP: the checkpoint is saved
        if not (out / "summary.json").is_file():
            raise
        raise common.RunInterrupted(out) from stop
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


def _resumed_run(resume: Path, device, out: Path | None, given: dict, ranges: dict, settings: dict):
    """``(options, out, settings)`` of a resumed run: its options (the flags ``given`` on the command line
    checked against them), its directory unless ``out``, and the training ``settings`` it keeps."""
    from agents.rl import load_options

    if not resume.is_dir():
        from agents.train import read_checkpoint

        read_checkpoint(resume)  # a file that is not a checkpoint: named before its directory is read
    run = resume if resume.is_dir() else resume.parent
    options, out = load_options(run, device), out or run
    _check_resumed_flags(run, options, given)
    trained = options.randomized()
    if any(trained.get(name) != bounds for name, bounds in ranges.items()):
        raise click.UsageError(
            f"--randomize-range: the resumed run {run} randomises {trained or 'nothing'} (its "
            "options.json); drop --randomize-range, or train a new run without --resume"
        )
    return options, out, _resumed_settings(resume, **settings)


def _train_config(settings: dict, iterations: int | None, options) -> TrainConfig:
    """The run's :class:`TrainConfig`: the algorithm's batch and recipe settings under the command's (the
    recipe's feedback path only where the policy observes the tracking error; a resumed run's own, and its
    step sizes; es without it: :func:`~agents.config.algorithm_settings`'s plain-network σ and step unless
    ``--es-sigma`` is given); a usage error for an es population that does not fit the envs."""
    algo, discrete = settings["algorithm"], options.action_type == "discrete"
    feedback = settings.get("actor_feedback")
    if feedback is None:
        feedback = algorithm_settings(algo).get("actor_feedback", False) and options.contour_features
    recipe = algorithm_settings(algo, feedback)
    batch = batch_defaults(algo)
    num_envs, iterations = settings["num_envs"] or batch["num_envs"], iterations or batch["iterations"]
    misfit = es_population_error(settings["es_population"], num_envs) if algo == "es" else None
    if misfit:
        raise click.BadParameter(misfit.split(": ", 1)[1], param_hint="--es-population")
    source = click.get_current_context().get_parameter_source("es_sigma")
    if source == click.core.ParameterSource.COMMANDLINE or "es_sigma" not in recipe:
        recipe["es_sigma"] = settings["es_sigma"]  # the recipe's own (the plain MLP's) unless given
    recipe.update(settings.get("resumed_steps", {}))  # a resumed run's own step sizes
    return TrainConfig(**{
        **recipe, "num_envs": num_envs, "iterations": iterations, "seed": settings["seed"],
        "num_steps_per_env": settings["num_steps_per_env"], "discrete": discrete,
        "stay_prior": settings["stay_prior"] if discrete else 0.0, "algorithm": algo,
        "es_population": settings["es_population"], "es_feedback_sigma": settings["es_feedback_sigma"],
        "es_feedback_learning_rate": settings["es_feedback_learning_rate"],
    })  # fmt: skip


def _actions_for(algo: str, action_type: str) -> str:
    """The action type ``algo`` trains: APG and es need continuous moves, and take them by default."""
    if algo not in CONTINUOUS_ALGORITHMS or action_type == "continuous":
        return action_type
    if (
        click.get_current_context().get_parameter_source("action_type")
        == click.core.ParameterSource.COMMANDLINE
    ):
        raise click.UsageError(f"--algo {algo}: plays continuous moves; use --actions continuous")
    return "continuous"


def _check_resumed_flags(run: Path, options, given: dict) -> None:
    """A usage error naming the first env option given on the command line whose value differs from the
    resumed run's (``options``, from its options.json)."""
    import numpy as np

    from agents.rl import same_contour
    from warpcut.contours import load_contour

    ctx = click.get_current_context()
    config = options.config()
    for name, flag in RESUMED_FLAGS.items():
        if ctx.get_parameter_source(name) != click.core.ParameterSource.COMMANDLINE:
            continue
        value = given[name]
        if name == "contour_name":
            trained = options.contours(1)[0]
            if same_contour(load_contour(value), trained):
                continue
            has = f"was trained on contour {trained.name!r}"
        elif name == "pinch":
            trained = options.pinch_point
            if trained is not None and np.allclose(np.asarray(trained, dtype=float), value, atol=1e-6):
                continue
            has = "shares its policy across pinch candidates" if trained is None else f"pinches at {trained}"
        else:
            trained = {
                "noise": config.noise_std,
                "score": config.score,
                "reward": "dense" if options.dense_reward else "sparse",
                "observe": "contour" if options.contour_features else "fiducials",
                "action_type": options.action_type,
                "allow_z": options.allow_z,
                "randomize": list(options.randomized()),
                "relative_reward": options.relative_reward,
            }[name]
            if np.array_equal(np.asarray(trained), np.asarray(value)):
                continue
            has = f"was trained with {flag} {trained}"
            if name == "allow_z":
                has = f"was trained with {'--z' if trained else '--no-z'}"
        raise click.UsageError(
            f"{flag}: the resumed run {run} {has} (its options.json); a resumed run keeps its options: drop "
            f"{flag.split('/')[0]}, or train a new run without --resume"
        )


RESUMED_SETTINGS = {
    "algorithm": ("algo", "--algo"),
    "seed": ("seed", "--seed"),
    "validation_trials": ("validation_trials", "--validation-trials"),
    "num_envs": ("num_envs", "--num-envs"),
    "num_steps_per_env": ("steps_per_env", "--steps-per-env"),
    "stay_prior": ("stay_prior", "--stay-prior"),
    "es_population": ("es_population", "--es-population"),
    "es_sigma": ("es_sigma", "--es-sigma"),
    "es_feedback_sigma": ("es_feedback_sigma", "--es-feedback-sigma"),
    "es_feedback_learning_rate": ("es_feedback_learning_rate", "--es-feedback-lr"),
}
"""What a resumed run keeps beyond its options (:func:`agents.rl.resume_settings`): its key, the command's
parameter and flag."""

RESUMED_STEPS = ("learning_rate",)
"""The step sizes a resumed run keeps that have no flag here (:data:`agents.rl.RESUMED_TRAIN_FIELDS`)."""


def _resumed_settings(resume: Path, **values) -> dict:
    """The training settings of a resumed run: the run's own (its seed and validation episodes, its batch,
    its prior, its step sizes: ``resumed_steps``), whatever the defaults say; a usage error naming a flag
    given with another value."""
    from agents.rl import resume_settings

    ctx = click.get_current_context()
    fixed = resume_settings(resume)
    for name, (parameter, flag) in RESUMED_SETTINGS.items():
        if fixed.get(name) is None or fixed[name] == values[name]:
            continue
        if ctx.get_parameter_source(parameter) == click.core.ParameterSource.COMMANDLINE:
            raise click.UsageError(
                f"{flag}: the resumed run {resume} was trained with {flag} {fixed[name]} (its config.json); "
                f"a resumed run keeps its settings: drop {flag}, or train a new run without --resume"
            )
        values[name] = fixed[name]
    steps = {name: fixed[name] for name in RESUMED_STEPS if fixed.get(name) is not None}
    if fixed.get("es_sigma") is not None:
        steps["es_sigma"] = values["es_sigma"]
    return {**values, "actor_feedback": fixed["actor_feedback"], "resumed_steps": steps}
