"""Learned tensioners: train a PPO policy for one contour, and run a trained one in evaluations.

A run directory (``warpcut train``) holds rsl-rl's ``config.json``, checkpoints and TensorBoard events
(:func:`agents.train.train`), plus ``options.json`` (the :class:`~envs.options.PatternCutOptions` the
policy was trained on, so its env can be rebuilt without guessing) and ``evaluation.json`` (the trained
policy against no tension). Runs written before ``options.json`` existed hold ``scenario.json``, which
:func:`load_options` still reads.

Before a run's policy is scored as a contour's (e.g. ``warpcut evaluate --checkpoints``),
:func:`check_policy_run` checks that it was trained on that contour, observes and acts as asked, and finished.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from agents.config import EVALUATION_TRIALS, RECIPE, VALIDATION_TRIALS, TrainConfig
from agents.evaluation import Method, MethodResult, evaluate_suite
from agents.export import load_policy
from agents.methods import StepCallbacks
from agents.train import (
    layout_difference,
    make_run_dir,
    policy_checkpoint,
    policy_layout,
    read_checkpoint,
    resume_checkpoint,
    train,
)
from envs.observations import observation_bounds
from envs.options import ContourSpec, PatternCutOptions, plain
from envs.rsl import PatternCutRslEnv
from envs.vector import PatternCutVecEnv
from warpcut.contours import Contour, builtin_names, load_contour
from warpcut.io import read_json, write_json
from warpcut.task import StepCallback

VALIDATION_SEED_OFFSET = 7919
"""Validation episodes use seed ``cfg.seed + VALIDATION_SEED_OFFSET``: neither training's ``cfg.seed`` nor the
evaluations' small seeds, so model selection never sees an evaluation episode."""


OPTIONS_FILE = "options.json"
"""The run directory's :class:`~envs.options.PatternCutOptions` (``to_dict()``), what its policy acts in."""

LEGACY_SCENARIO_FILE = "scenario.json"
"""What runs written before :data:`OPTIONS_FILE` hold instead (read by :func:`load_options`)."""


def train_contour(
    options: PatternCutOptions,
    out_dir: str | Path,
    cfg: TrainConfig,
    resume: str | Path | None = None,
    eval_trials: int = EVALUATION_TRIALS,
    progress: bool = True,
    validation_trials: int = VALIDATION_TRIALS,
    step_callbacks: StepCallbacks | None = None,
    label: str | None = None,
) -> dict:
    """Train a PPO tensioner for ``options`` into ``out_dir``, then evaluate it.

    With ``validation_trials > 0`` the deterministic policy is scored on that many held-out episodes
    (seed ``cfg.seed + VALIDATION_SEED_OFFSET``) before training and every ``cfg.validation_interval``
    iterations, and the best one is the run's policy (``best.pt``; see :func:`agents.train.train`).

    Args:
        options: Contour, pinch point (None: the default, resolved and saved), segments, simulation
            settings, observations and actions; ``options.device`` is the simulator's Warp device (not
            saved: a run evaluates on any device).
        out_dir: Run directory; its ``options.json`` is written once the options are known to fit
            ``resume``'s policy.
        cfg: PPO settings (``cfg.torch_device`` is torch's device).
        resume: Run directory or checkpoint to continue from (see :func:`agents.train.resume_checkpoint`);
            its policy must observe and act as ``options`` do.
        eval_trials: Trials of the final evaluation against no tension.
        progress: Show the progress bar.
        validation_trials: Held-out episodes per validation; 0 disables validation (the run's policy is
            then the last one).
        step_callbacks: Step callbacks of the final evaluation's batches (see :func:`evaluate_run`).
        label: The progress bar's label (default: "ALGORITHM CONTOUR", e.g. "PPO fls-circle").

    Returns:
        ``{"summary": training summary, "evaluation": evaluation of the run's policy}``.

    Raises:
        ValueError: ``resume`` holds no readable checkpoint, or its policy observes or acts otherwise than
            ``options`` (the message names the options that differ from its run's), or it validated on other
            episodes than ``validation_trials`` and ``cfg.seed`` give (see :func:`resume_settings`).
    """
    if cfg.discrete != (options.action_type == "discrete"):
        raise ValueError(
            f"cfg.discrete={cfg.discrete} does not match the options' {options.action_type} actions"
        )
    shared = options.candidates is not None
    if shared and validation_trials < 1:
        raise ValueError("validation_trials: options with candidates need validation to choose one (>= 1)")
    candidates = len(options.candidates) if shared else 1
    per_candidate = max(CANDIDATE_VALIDATION_MIN, -(-validation_trials // candidates)) if shared else None
    out_dir = make_run_dir(out_dir)
    if resume is not None:  # before options.json is written: a resume with other options changes nothing
        checkpoint, state, _ = resume_checkpoint(resume)
        _check_layout(state["actor_state_dict"], checkpoint, options, "the env", _RESUME_FIX)
        if validation_trials > 0:
            _check_validation(checkpoint, state, cfg.seed, per_candidate or validation_trials, candidates)
    if not shared:
        pinch = options.per_env(1)[1][0]
        options = dataclasses.replace(options, pinch_point=[float(v) for v in pinch])
    env = training_env(options, cfg)  # before options.json: options the env refuses leave no run behind
    write_json(out_dir / OPTIONS_FILE, dataclasses.replace(options, device=None).to_dict())
    validate = None
    if validation_trials > 0:
        validation_env = PatternCutVecEnv(
            per_candidate * candidates if shared else validation_trials, options
        )

        def validate(actor: torch.nn.Module) -> np.ndarray:
            """Validation errors (vertices), (episodes, candidates): env i pinches candidate i % K."""
            seed = cfg.seed + VALIDATION_SEED_OFFSET
            errors = policy_errors(actor, validation_env, seed)["error_vertices"]
            if options.relative_reward:  # selection on the reward's scale: a flat sheet's error counts
                errors = errors * validation_env.scene.reward_scale
            return errors.reshape(-1, candidates)

        def candidate_errors(actor: torch.nn.Module) -> np.ndarray:
            """Mean validation error (vertices) per candidate."""
            return validate(actor).mean(axis=0)

    label = label or f"{cfg.algorithm.upper()} {options.contours(1)[0].name}"
    summary = train(env, cfg, out_dir, resume=resume, progress=progress, validate=validate, label=label)
    if shared:
        errors = candidate_errors(load_policy(out_dir))
        chosen = int(np.argmin(errors))  # the first (the better fixed rank, as ordered) among ties
        selection = {
            "chosen": chosen,
            "pinch": [float(v) for v in options.candidates[chosen]["pinch"]],
            "validation_error_vertices": [float(e) for e in errors],
            "validation_episodes_per_candidate": per_candidate,
        }
        write_json(out_dir / CANDIDATES_FILE, selection)
        summary["candidates"] = selection
    evaluation = evaluate_run(
        out_dir, trials=eval_trials, seed=cfg.seed + 1, device=options.device, step_callbacks=step_callbacks
    )
    write_json(out_dir / "evaluation.json", evaluation)
    return {"summary": summary, "evaluation": evaluation}


def resume_settings(resume: str | Path) -> dict:
    """What a run fixes beyond its options, so that resuming it validates on the episodes it started with
    (model selection compares every validation with the first, episode by episode).

    Args:
        resume: Run directory or checkpoint (as :func:`train_contour` takes it).

    Returns:
        ``seed``: the run's PPO seed (its ``config.json``'s; the validation episodes derive from it);
        ``validation_trials``: its ``train_contour`` argument (for a shared policy, the episodes per
        candidate times the candidates), None where the run never validated; and the PPO batch and prior
        the run was trained with, and its step sizes (:data:`RESUMED_TRAIN_FIELDS` of its ``config.json``;
        None where it holds none); ``actor_feedback``: whether its actor has the feedback path (read from the
        checkpoint, so runs from before the field say False).
    """
    checkpoint, state, _ = resume_checkpoint(resume)
    train = _run_train_config(checkpoint.parent)
    fixed = {name: train.get(name) for name in RESUMED_TRAIN_FIELDS}
    fixed["actor_feedback"] = any(key.startswith("mlp.feedback.") for key in state["actor_state_dict"])
    baseline = (state.get("infos") or {}).get("validation_baseline")
    if not baseline:
        return {**fixed, "seed": train.get("seed"), "validation_trials": None}
    return {**fixed, "seed": train.get("seed"), "validation_trials": len(baseline) * len(baseline[0])}


RESUMED_TRAIN_FIELDS = (
    "num_envs", "num_steps_per_env", "stay_prior", "algorithm", "es_population", "learning_rate", "es_sigma",
    "es_feedback_sigma", "es_feedback_learning_rate",
)  # fmt: skip
"""The :class:`~agents.config.TrainConfig` fields a resumed run keeps (its batch, the prior its policy
was initialised with, how it learns, es's population, and its step sizes: a default changed since the run
was trained does not change how it goes on), besides the seed and the actor's feedback path
(:func:`resume_settings`)."""


def _run_train_config(run_dir: Path) -> dict:
    """The ``train`` section of a run's ``config.json`` (empty if it holds none)."""
    path = run_dir / "config.json"
    config = read_json(path) if path.is_file() else {}
    train = config.get("train") if isinstance(config, dict) else None
    return train if isinstance(train, dict) else {}


def _check_validation(checkpoint: Path, state: dict, seed: int, episodes: int, candidates: int) -> None:
    """A ``ValueError`` if the run of ``checkpoint`` (contents ``state``) validated on other episodes than
    ``episodes`` per candidate seeded from ``seed`` would be."""
    baseline = (state.get("infos") or {}).get("validation_baseline")
    if not baseline:
        return
    if len(baseline) != episodes:
        trials = len(baseline) * candidates
        raise ValueError(
            f"validation_trials: {checkpoint} validated on {trials} episode(s), these settings on "
            f"{episodes * candidates}: resume with validation_trials={trials} (--validation-trials)"
        )
    trained = _run_train_config(checkpoint.parent).get("seed")
    if trained is not None and trained != seed:
        raise ValueError(
            f"seed: {checkpoint.parent} was trained with seed {trained} (its config.json), these settings "
            f"have {seed}; its validation episodes derive from the seed: resume with seed={trained} (--seed)"
        )


def training_env(options: PatternCutOptions, cfg: TrainConfig) -> PatternCutRslEnv:
    """The rsl-rl env PPO trains in: ``cfg.num_envs`` envs of ``options``, seeded with ``cfg.seed``."""
    env = PatternCutVecEnv(cfg.num_envs, options)
    return PatternCutRslEnv(env, torch_device=cfg.torch_device, seed=cfg.seed)


CANDIDATES_FILE = "candidates.json"
"""In the run directory of a policy shared across pinch candidates: the chosen candidate (``chosen``, its
``pinch``) and every candidate's validation error with the run's policy."""

CANDIDATE_VALIDATION_MIN = 4
"""Validation episodes per candidate of a shared policy, at least (``validation_trials`` are split over the
candidates)."""


def chosen_candidate(run_dir: str | Path) -> int:
    """The candidate a shared policy's run chose (lowest validation error), from its ``candidates.json``."""
    path = Path(run_dir) / CANDIDATES_FILE
    if not path.is_file():
        raise FileNotFoundError(
            f"{run_dir}: no {CANDIDATES_FILE}; the shared policy's training did not finish"
        )
    data = read_json(path)
    if not isinstance(data, dict) or not isinstance(data.get("chosen"), int):
        raise ValueError(f"{path}: no candidate index 'chosen'; restore it, or resume the training")
    return data["chosen"]


def is_run(run_dir: str | Path) -> bool:
    """Whether ``run_dir`` holds a trained run's options (so :func:`load_options` can read it)."""
    run_dir = Path(run_dir)
    return (run_dir / OPTIONS_FILE).is_file() or (run_dir / LEGACY_SCENARIO_FILE).is_file()


def load_options(run_dir: str | Path, device: str | None = None) -> PatternCutOptions:
    """The options a run was trained on, for the Warp ``device`` (a shared policy's with all its candidates;
    :func:`policy_options` gives those of the candidate it chose, as its evaluation uses).

    Raises:
        FileNotFoundError: ``run_dir`` holds neither ``options.json`` nor ``scenario.json``.
        ValueError: ``run_dir`` is a file, or its options file cannot be read as options (the message names
            the file and the field).
    """
    run_dir = Path(run_dir)
    if run_dir.is_file():
        raise ValueError(
            f"{run_dir}: is a file, not a run directory; give the directory 'warpcut train' wrote"
            + (f" (e.g. {run_dir.parent})" if is_run(run_dir.parent) else "")
        )
    for name in (OPTIONS_FILE, LEGACY_SCENARIO_FILE):
        if (run_dir / name).exists() and not (run_dir / name).is_file():
            raise ValueError(f"{run_dir / name}: is a directory, not a file; remove it, or retrain the run")
    if (run_dir / OPTIONS_FILE).is_file():
        path, read = run_dir / OPTIONS_FILE, PatternCutOptions.from_dict
    elif (run_dir / LEGACY_SCENARIO_FILE).is_file():
        path, read = run_dir / LEGACY_SCENARIO_FILE, _from_scenario
    else:
        raise FileNotFoundError(
            f"{run_dir}: no {OPTIONS_FILE}; give a run directory written by 'warpcut train'"
        )
    data = read_json(path)
    try:
        options = read(data)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}; restore the file, or retrain the run") from None
    for spec in options.contour if isinstance(options.contour, list | tuple) else [options.contour]:
        if isinstance(spec, str) and spec not in builtin_names() and not Path(spec).is_file():
            raise ValueError(
                f"{path}: contour {spec!r} is neither a built-in name nor a file from {Path.cwd()} (older "
                "runs stored a contour file's path as typed): run from the directory it was trained in, or "
                "put the contour's points in the file (as PatternCutOptions.to_dict writes them)"
            )
    return dataclasses.replace(options, device=device)


def _from_scenario(scenario: object) -> PatternCutOptions:
    """The options of a run's legacy ``scenario.json`` (its fields, renamed)."""
    if not isinstance(scenario, dict) or "contour" not in scenario:
        raise ValueError('expected a JSON object with a "contour" and the scenario\'s other fields')
    fields = dict(scenario)
    renamed = {
        "contour": fields.pop("contour"),
        "pinch_point": fields.pop("pinch", None),
        "sim_config": fields.pop("sim", {}),
    }
    return PatternCutOptions.from_dict({**fields, **renamed})


def policy_options(run_dir: str | Path, device: str | None = None) -> PatternCutOptions:
    """The options a run's policy is evaluated on: a shared policy's at the candidate its run chose, on the
    nominal parameters (a policy trained with domain randomisation too: :meth:`PatternCutOptions.nominal`)."""
    options = load_options(run_dir, device).nominal()
    if options.candidates is not None:
        options = options.at_candidate(chosen_candidate(run_dir))
    return options


def rollout_errors(
    run_dir: str | Path,
    trials: int,
    seed: int = 0,
    device: str | None = None,
    on_step: StepCallback | None = None,
    paired_noise: tuple[int, int] | None = None,
    overrides: dict | None = None,
) -> dict:
    """Run the trained policy (deterministic: argmax action) for ``trials`` seeded episodes at once.

    Trials differ by their fiducials and process-noise streams. Returns per-trial errors (vertices,
    mm^2) and the pinch point used. ``on_step(task, moves)`` is called after the reset (moves ``None``)
    and after every step, as in :meth:`warpcut.task.CuttingTask.run` (e.g. a recorder's callback).
    ``paired_noise``: see :func:`policy_errors`. ``overrides``: options fields to change from the run's
    (e.g. per-env ``gravity``, or ``resolution``, for :mod:`agents.robustness`).
    """
    options = dataclasses.replace(policy_options(run_dir, device), **(overrides or {}))
    actor = load_policy(run_dir)
    checkpoint = policy_checkpoint(run_dir)
    _check_layout(actor.state_dict(), checkpoint, options, _options_file(run_dir), _OPTIONS_FIX)
    env = PatternCutVecEnv(trials, options)
    return policy_errors(actor, env, seed=seed, on_step=on_step, paired_noise=paired_noise)


def nominal_validation_error(
    run_dir: str | Path, episodes: int, seed: int, device: str | None = None
) -> float:
    """The mean error (vertices) of a run's policy on ``episodes`` validation episodes of the nominal sheet
    (seed ``seed + VALIDATION_SEED_OFFSET``, as training validates): how a pipeline compares pinch
    candidates whose training validated elsewhere (domain randomisation, a relative reward)."""
    rollouts = rollout_errors(run_dir, episodes, seed=seed + VALIDATION_SEED_OFFSET, device=device)
    return float(np.nanmean(rollouts["error_vertices"]))


LAYOUT_FIELDS = (
    "num_fiducials",
    "contour_features",
    "observe_pinch",
    "observe_plan",
    "action_type",
    "allow_z",
    "residual_gain",
)
"""The :class:`~envs.options.PatternCutOptions` fields that set what a policy observes and how its actions
act (:func:`check_policy_run` compares them)."""

_RESUME_FIX = "resume with the options the run was trained with (load_options; 'warpcut train --resume RUN')"
_OPTIONS_FIX = "its options file does not describe this policy: restore it, or retrain the run"


def options_layout(options: PatternCutOptions) -> tuple[int, int]:
    """``(observations, outputs)`` of a policy acting in ``options``' env, as
    :func:`agents.train.policy_layout` reads them from a policy: the observation's size
    (:func:`envs.observations.observation_bounds`) and the action choices (discrete: stay and +-1 mm per
    axis) or axes (continuous)."""
    low, _ = observation_bounds(
        options.num_fiducials, options.contour_features, options.observe_pinch, options.observe_plan
    )
    axes = 3 if options.allow_z else 2
    return int(low.size), 1 + 2 * axes if options.action_type == "discrete" else axes


def _options_file(run_dir: str | Path) -> str:
    """The options file of a run (``options.json``, or a legacy run's ``scenario.json``)."""
    run_dir = Path(run_dir)
    legacy = not (run_dir / OPTIONS_FILE).is_file() and (run_dir / LEGACY_SCENARIO_FILE).is_file()
    return str(run_dir / (LEGACY_SCENARIO_FILE if legacy else OPTIONS_FILE))


def _check_layout(
    actor_state: dict, checkpoint: Path, options: PatternCutOptions, source: str, fix: str
) -> None:
    """A ``ValueError`` naming ``checkpoint`` if its policy (``actor_state``) does not observe and act as
    ``options`` (``source``, e.g. "the env") do, with the options that differ from its run's and ``fix``."""
    difference = layout_difference(policy_layout(actor_state), options_layout(options), source)
    if difference is None:
        return
    differing = ""
    if is_run(checkpoint.parent):
        with contextlib.suppress(ValueError, FileNotFoundError):
            run = load_options(checkpoint.parent)
            differing = ", ".join(_differences(run, options, LAYOUT_FIELDS, "the run", "here"))
    trained = f"the run was trained with other options ({differing})" if differing else "another policy"
    raise ValueError(f"{checkpoint}: {difference}: {trained}; {fix}")


def _differences(
    run: PatternCutOptions, options: PatternCutOptions, fields: Sequence[str], ours: str, theirs: str
) -> list[str]:
    """``field: VALUE in OURS, VALUE THEIRS`` for each of ``fields`` that differs between ``run`` and
    ``options``."""
    return [
        f"{name}={getattr(run, name)!r} in {ours}, {getattr(options, name)!r} {theirs}"
        for name in fields
        if getattr(run, name) != getattr(options, name)
    ]


def check_policy_run(
    run_dir: str | Path,
    requested: PatternCutOptions | ContourSpec,
    allow_partial: bool = False,
) -> PatternCutOptions:
    """Check that the run ``run_dir`` holds a policy for what is ``requested``, before it is scored as one
    (e.g. ``evaluate --checkpoints DIR``: ``DIR/NAME`` as contour ``NAME``'s policy).

    Checked, in this order: the training finished (its ``summary.json`` says ``completed``); the run's
    contour is the requested one (its points, closedness and sheet, not just its name); with requested
    options also the fields that set what the policy observes and how it acts (:data:`LAYOUT_FIELDS`) and
    the simulation settings (``options.config()``: physics, noise, score); and the run's policy checkpoint
    is readable and observes and acts as its options say.

    Args:
        run_dir: A run directory ``warpcut train`` wrote.
        requested: The options the policy is to be scored in (e.g. ``PatternCutOptions(contour=spec,
            sim_config=config, **recipe.options)``; ``pinch_point``, ``segments``, rewards and the device are
            not compared), or only the contour (a built-in name, a contour file or a ``Contour``).
        allow_partial: Accept a run whose training was interrupted or failed (or has no summary): its
            last saved policy is scored.

    Returns:
        The options the run's policy is evaluated in (:func:`policy_options`).

    Raises:
        FileNotFoundError: ``run_dir`` is not a run (no options file) or has no checkpoint.
        ValueError: Naming the run and the mismatch: unfinished training (pass ``--allow-partial`` or resume
            it), another contour, other observations, actions or simulation settings, or an unreadable
            checkpoint.
    """
    run_dir = Path(run_dir)
    run_options = load_options(run_dir)
    if not allow_partial:
        _check_finished(run_dir)
    options = requested if isinstance(requested, PatternCutOptions) else PatternCutOptions(contour=requested)
    wanted, trained = _single_contour(options, "requested"), _single_contour(run_options, str(run_dir))
    if not same_contour(trained, wanted):
        raise ValueError(
            f"{run_dir}: trained on contour {trained.name!r}, not on the requested {wanted.name!r}"
            + (" (same name, other points)" if trained.name == wanted.name else "")
            + "; give the run trained on it, or train one"
        )
    if isinstance(requested, PatternCutOptions):
        differing = _differences(run_options, options, LAYOUT_FIELDS, "the run", "requested")
        run_sim = plain(dataclasses.asdict(run_options.config()))
        sim = plain(dataclasses.asdict(options.config()))
        differing += [
            f"{name}={run_sim[name]!r} in the run, {sim[name]!r} requested"
            for name in sim
            if run_sim.get(name) != sim[name]
        ]
        if differing:
            raise ValueError(
                f"{run_dir}: trained with other settings than requested ({'; '.join(differing)}); "
                "evaluate with the run's settings, or train a run with these"
            )
    checkpoint = policy_checkpoint(run_dir)
    state = read_checkpoint(checkpoint)
    _check_layout(state["actor_state_dict"], checkpoint, run_options, _options_file(run_dir), _OPTIONS_FIX)
    return policy_options(run_dir)


def _check_finished(run_dir: Path) -> None:
    """A ``ValueError`` unless ``run_dir``'s ``summary.json`` says its training completed."""
    path = run_dir / "summary.json"
    partial = "pass --allow-partial to evaluate its last saved policy, or resume the training"
    resume = f"'warpcut train --resume {run_dir}'"
    if not path.is_file():
        raise ValueError(
            f"{run_dir}: no summary.json, its training never finished (or still runs); {partial} ({resume})"
        )
    summary = read_json(path)
    summary = summary if isinstance(summary, dict) else {}
    status = summary.get("status")
    if status != "completed":
        at = f" at iteration {summary['iterations']}" if "iterations" in summary else ""
        raise ValueError(
            f"{run_dir}: training {status or 'status unknown'}{at} ({path.name}); {partial} ({resume})"
        )


def _single_contour(options: PatternCutOptions, what: str) -> Contour:
    """The one contour of ``options`` (loaded); a ``ValueError`` naming ``what`` for several."""
    specs = options.contour if isinstance(options.contour, list | tuple) else [options.contour]
    if len(specs) != 1:
        raise ValueError(f"{what}: {len(specs)} contours (one per env); a policy run is checked for one")
    spec = specs[0]
    return spec if isinstance(spec, Contour) else load_contour(spec)


def same_contour(a: Contour, b: Contour) -> bool:
    """Whether two contours are the same cut: closedness, sheet and points (to 1 um); names may differ."""
    return (
        a.closed == b.closed
        and tuple(a.sheet_size) == tuple(b.sheet_size)
        and a.points.shape == b.points.shape
        and bool(np.allclose(a.points, b.points, rtol=0.0, atol=1e-3))
    )


def policy_errors(
    actor: torch.nn.Module,
    env: PatternCutVecEnv,
    seed: int,
    on_step: StepCallback | None = None,
    paired_noise: tuple[int, int] | None = None,
) -> dict:
    """One deterministic episode of ``actor`` in every env of ``env`` (reset with ``seed``); see
    :func:`rollout_errors`. Steps the env's scene directly, so the sheet is not reset after the last step
    (the vector env would reset it in the same call) and ``on_step`` sees the finished cut.

    ``paired_noise = (noise_seed, first_env)``: draw the process noise that envs ``first_env, first_env +
    1, ...`` of a :class:`~warpcut.task.CuttingTask` seeded ``noise_seed`` draw (e.g. the baselines'
    trials of this contour in :func:`agents.evaluation.evaluate_suite`'s batch), so that trial k of the
    policy and of each baseline see the same noise: paired trials. Default: the env's own noise.
    """
    trials = env.num_envs
    obs, _ = env.reset(seed=seed)
    if paired_noise is not None:
        noise_seed, first_env = paired_noise
        env.task.sim.first_noise_stream = int(first_env)
        env.task.reset(seed=int(noise_seed))  # the same settled sheet, the baselines' noise seed
    if on_step is not None:
        on_step(env.task, None)
    final = None
    discrete = env.options.action_type == "discrete"
    with torch.inference_mode():
        for _ in range(env.task.num_steps):
            obs_td = {"policy": torch.as_tensor(obs)}
            action = actor(_tensordict(obs_td, trials)).cpu().numpy().reshape(trials, -1)
            if discrete:
                action = action[:, 0].astype(np.int64)
            obs, _, terminated, truncated, info = env.scene.step(action)
            if on_step is not None:
                on_step(env.task, env.scene.last_moves)
            if terminated or truncated:
                final = info
                break
    if final is None or "error_vertices" not in final:
        name = env.task.contours[0].name
        raise RuntimeError(f"{name}: the episode did not end within {env.task.num_steps} steps")
    pinch = None if env.options.candidates is not None else env.task.pinch_points[0].copy()
    keys = ("error_vertices", "error_mm2", "separated", "dropped_fraction")
    return {**{k: np.asarray(final[k]) for k in keys}, "pinch": pinch}


def _tensordict(groups: dict[str, torch.Tensor], batch: int):
    from tensordict import TensorDict

    return TensorDict(groups, batch_size=[batch])


def evaluate_run(
    run_dir: str | Path,
    trials: int = EVALUATION_TRIALS,
    seed: int = 1,
    device: str | None = None,
    step_callbacks: StepCallbacks | None = None,
) -> dict:
    """The trained policy against no tension on its own options (paired by trial).

    ``step_callbacks(method, 0)`` gives the step callback of the ``"rl"`` and ``"none"`` batches, as in
    :func:`agents.evaluation.evaluate_suite` (e.g. a recorder's).
    """
    options = policy_options(run_dir, device)
    contour = options.contours(1)[0]
    start = time.perf_counter()
    callbacks = step_callbacks or (lambda method, first: None)
    rl = rollout_errors(
        run_dir, trials, seed=seed, device=device, on_step=callbacks("rl", 0), paired_noise=(seed, 0)
    )
    segments = None if options.segments is None else [[np.asarray(p) for p in options.segments]]
    table = evaluate_suite(
        [contour],
        [Method("rl", result=MethodResult.from_rollouts([rl]))],
        trials,
        options.config(),
        device,
        seed,
        segments=segments,
        step_callbacks=callbacks,
    )
    row = table["rows"][0]
    return {
        "contour": contour.name,
        "trials": trials,
        "none_error_vertices": row["none_error_vertices"],
        "rl_error_vertices": row["rl_error_vertices"],
        "rl_error_mm2": row["rl_error_mm2"],
        "rl_improvement_pct": row["rl_improvement_pct"],
        "rl_ci95": row["rl_ci95"],
        "pinch": row["rl_pinch"],
        "seconds": time.perf_counter() - start,
    }


BENCH_EPISODES = 3
"""Whole episodes the steady-state window of :func:`benchmark_training` covers."""


def benchmark_training(
    device: str | None = None, num_envs: int = TrainConfig.num_envs, episodes: int = BENCH_EPISODES
) -> dict[str, float]:
    """PPO throughput training ``fls-circle`` on ``num_envs`` envs with warpcut's recipe (:data:`RECIPE`:
    dense reward, contour features, x-y-z moves), in steady state: the env steps of the iterations after
    the first (start-up, kernel loading and the first iteration's allocations excluded; no validation runs)
    over their time, as many iterations as cover ``episodes`` whole episodes. The steps that end an episode
    (scoring, resets) cost several times a step; a median over iterations would leave them out.

    - ``train_steps_per_s``: env steps per second of those iterations, collection + PPO update;
    - ``train_collection_steps_per_s``: of their collection alone (policy forward passes, env steps,
      storage);

    and ``train_overall_steps_per_s``, the whole call's steps over its wall time (what a short run sees).
    """
    import tempfile

    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes: the steady state needs at least 1 whole episode (got {episodes!r})")
    cfg = TrainConfig(num_envs=num_envs, num_steps_per_env=32, save_interval=10**6)
    options = PatternCutOptions(contour="fls-circle", device=device, **RECIPE)
    env = training_env(options, cfg)
    steady_iterations = -(-episodes * env.max_episode_length // cfg.num_steps_per_env)
    cfg = dataclasses.replace(cfg, iterations=1 + steady_iterations)
    with tempfile.TemporaryDirectory() as out:
        summary = train(env, cfg, out, progress=False)
    steady = summary["history"][1:]
    steps = len(steady) * cfg.num_envs * cfg.num_steps_per_env

    def rate(key: str) -> float:
        return steps / sum(cfg.num_envs * cfg.num_steps_per_env / m[key] for m in steady)

    return {
        "train_steps_per_s": rate("iteration_steps_per_s"),
        "train_collection_steps_per_s": rate("collection_steps_per_s"),
        "train_overall_steps_per_s": float(summary["steps_per_s"]),
    }
