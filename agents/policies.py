"""Trained policies as tensioners: a run directory's options and policy, its rollouts (the ``rl`` column of
an evaluation), its evaluation against no tension, and the checks that a run is the policy asked for.

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
from rsl_rl.models import MLPModel
from rsl_rl.utils import resolve_class
from tensordict import TensorDict

from agents.checkpoints import (
    layout_difference,
    layout_mismatch,
    policy_checkpoint,
    policy_layout,
    read_checkpoint,
)
from agents.config import EVALUATION_TRIALS
from agents.evaluation import Method, MethodResult, evaluate_suite
from agents.methods import StepCallbacks
from agents.models import torch_threads
from envs.observations import observation_bounds
from envs.options import ContourSpec, EnvConfig, PatternCutOptions, plain
from envs.vector import PatternCutVecEnv
from warpcut.contours import Contour
from warpcut.io import read_json
from warpcut.task import StepCallback

OPTIONS_FILE = "options.json"
"""The run directory's :class:`~envs.options.PatternCutOptions` (``to_dict()``), what its policy acts in."""

VALIDATION_SEED_OFFSET = 7919
"""Validation episodes use seed ``seed + VALIDATION_SEED_OFFSET``: neither training's seed nor the
evaluations' small seeds, so model selection never sees an evaluation episode."""


def load_policy(
    source: str | Path, acting_in: EnvConfig | None = None, described_by: str = "", fix: str = ""
) -> MLPModel:
    """Rebuild a trained actor on the CPU, in eval mode, from a run directory or checkpoint (a checkpoint
    describes its own policy: :mod:`agents.checkpoints`).

    Args:
        source: Run directory (its ``best.pt`` if training validated, else ``latest.pt``) or a checkpoint.
        acting_in: The env the policy is to act in: it must observe and act as that env does
            (:func:`check_layout`, with ``described_by``, what says so, and ``fix``).

    Returns:
        The actor; ``actor(obs_tensordict)`` returns deterministic actions.

    Raises:
        FileNotFoundError: No checkpoint.
        ValueError: The checkpoint cannot be read, its policy description does not fit its weights, or the
            policy does not fit ``acting_in``; the message names the file and the fix.
    """
    checkpoint = policy_checkpoint(source)
    state = read_checkpoint(checkpoint)
    try:
        policy = state["policy"]
        obs = TensorDict(
            {group: torch.zeros(1, *shape) for group, shape in policy["obs_shapes"].items()}, batch_size=[1]
        )
        actor_class, actor_cfg = resolve_class(dict(policy["actor"]))
        actor = actor_class(obs, policy["obs_groups"], "actor", policy["num_actions"], **actor_cfg)
    except (KeyError, TypeError, AttributeError, ValueError, ImportError) as exc:
        raise ValueError(
            f"{checkpoint}: its policy description cannot be read ({type(exc).__name__}: {exc}); retrain"
        ) from None
    saved = state["actor_state_dict"]
    if hasattr(actor, "upgrade_state"):  # a network that has grown since: the saved one as it would be now
        saved = actor.upgrade_state(saved)
    mismatch = layout_mismatch(saved, actor.state_dict(), "its description")
    if mismatch:
        raise ValueError(f"{checkpoint}: {mismatch}; the file is damaged: retrain, or use another checkpoint")
    if acting_in is not None:
        check_layout(saved, checkpoint, acting_in, described_by, fix)
    actor.load_state_dict(saved)
    return actor.eval()


def policy_runs(source: str | Path) -> list[tuple[Path, str]]:
    """The policies a directory holds, as ``(run directory or checkpoint, what it is)``: a checkpoint file;
    a ``warpcut train`` run; a ``warpcut run`` directory (the policy of the candidate it chose; stopped
    before it chose, each candidate's with a checkpoint); an ``evaluate`` directory (each contour's policy in
    ``policies/``).

    Raises:
        FileNotFoundError: ``source`` does not exist.
        ValueError: ``source`` holds no policy (the message says what would).
    """
    source = Path(source)
    if not source.exists():
        raise FileNotFoundError(f"{source}: no such run directory or checkpoint")
    if source.is_file() or is_run(source) or any(source.glob("*.pt")):  # a checkpoint, or train()'s run
        return [(source, f"{'checkpoint' if source.is_file() else 'train run'} {source}")]
    results = source / "results.json"
    report = read_json(results) if results.is_file() else {}
    if isinstance(report, dict) and report.get("policy") == "rl" and report.get("candidates"):
        chosen = report["candidates"][int(report["chosen_candidate"])]
        run = source / chosen["run"]
        return [(run, f"run {source}: the chosen pinch candidate's policy ({run.relative_to(source)})")]
    policies = sorted(d for d in (source / "policies").glob("*") if is_run(d))
    if policies:
        return [(d, f"evaluate {source}: {d.name}'s policy") for d in policies]
    candidates = sorted(d for d in (source / "rl").glob("candidate-*") if is_run(d) and any(d.glob("*.pt")))
    if candidates:  # a run stopped before it chose a candidate: each candidate's policy so far
        return [(d, f"run {source} (unfinished, no candidate chosen): {d.name}'s policy") for d in candidates]
    raise ValueError(
        f"{source}: holds no trained policy; give a run directory of 'warpcut train', 'warpcut run "
        "--policy rl' or 'warpcut evaluate' with rl, or a .pt checkpoint"
    )


def is_run(run_dir: str | Path) -> bool:
    """Whether ``run_dir`` holds a trained run's options (so :func:`load_options` can read it)."""
    return (Path(run_dir) / OPTIONS_FILE).is_file()


def load_options(run_dir: str | Path, device: str | None = None) -> PatternCutOptions:
    """The options a run was trained on, for the Warp ``device``.

    Raises:
        FileNotFoundError: ``run_dir`` holds no ``options.json``.
        ValueError: ``run_dir`` is a file, or its options file cannot be read as options (the message names
            the file and the field).
    """
    run_dir = Path(run_dir)
    if run_dir.is_file():
        raise ValueError(
            f"{run_dir}: is a file, not a run directory; give the directory 'warpcut train' wrote"
            + (f" (e.g. {run_dir.parent})" if is_run(run_dir.parent) else "")
        )
    path = run_dir / OPTIONS_FILE
    if path.exists() and not path.is_file():
        raise ValueError(f"{path}: is a directory, not a file; remove it, or retrain the run")
    if not path.is_file():
        raise FileNotFoundError(
            f"{run_dir}: no {OPTIONS_FILE}; give a run directory written by 'warpcut train'"
        )
    try:
        options = PatternCutOptions.from_dict(read_json(path))
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}; restore the file, or retrain the run") from None
    return dataclasses.replace(options, device=device)


def policy_options(run_dir: str | Path, device: str | None = None) -> PatternCutOptions:
    """The options a run's policy is evaluated on: its own, on the nominal parameters (a policy trained with
    domain randomisation too: :meth:`PatternCutOptions.nominal`)."""
    return load_options(run_dir, device).nominal()


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
    mm^2), the pinch point used and why it is not a feasible grasp (``pinch_problem``; None: it is), which
    the run's options must allow (``allow_infeasible_pinch``, or in ``overrides``). ``on_step(task,
    moves)`` is called after the reset (moves ``None``) and after every step, as in
    :meth:`warpcut.task.CuttingTask.run` (e.g. a recorder's callback).
    ``paired_noise``: see :func:`policy_errors`. ``overrides``: options fields to change from the run's
    (e.g. per-env ``gravity``, or ``resolution``, for :mod:`agents.pipelines.robustness`).
    """
    options = dataclasses.replace(policy_options(run_dir, device), **(overrides or {}))
    actor = load_policy(run_dir, options, str(Path(run_dir) / OPTIONS_FILE), OPTIONS_FIX)
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


LAYOUT_FIELDS = ("num_fiducials", "contour_features", "lookahead", "action_type", "allow_z")
"""The :class:`~envs.options.PatternCutOptions` fields that set what a policy observes and how its actions
act (:func:`check_policy_run` compares them)."""

RESUME_FIX = "resume with the options the run was trained with ('warpcut train --resume RUN')"
OPTIONS_FIX = "its options file does not describe this policy: restore it, or retrain the run"


def options_layout(options: EnvConfig) -> tuple[int, int]:
    """``(observations, outputs)`` of a policy acting in ``options``' env, as
    :func:`agents.checkpoints.policy_layout` reads them from a policy: the observation's size
    (:func:`envs.observations.observation_bounds`) and the action choices (discrete: stay and +-1 mm per
    axis) or axes (continuous)."""
    low, _ = observation_bounds(options.num_fiducials, options.contour_features, options.lookahead)
    axes = 3 if options.allow_z else 2
    return int(low.size), 1 + 2 * axes if options.action_type == "discrete" else axes


def check_layout(actor_state: dict, checkpoint: Path, options: EnvConfig, source: str, fix: str) -> None:
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
    run: PatternCutOptions, options: EnvConfig, fields: Sequence[str], ours: str, theirs: str
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
        ValueError: Naming the run and the mismatch: unfinished training (set ``allow_partial`` or resume
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
    check_layout(state["actor_state_dict"], checkpoint, run_options, str(run_dir / OPTIONS_FILE), OPTIONS_FIX)
    return policy_options(run_dir)


def _check_finished(run_dir: Path) -> None:
    """A ``ValueError`` unless ``run_dir``'s ``summary.json`` says its training completed."""
    path = run_dir / "summary.json"
    partial = "set allow_partial=true to evaluate its last saved policy, or resume the training"
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
    return options.contours(1)[0]


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
    with torch.inference_mode(), torch_threads(1):  # the actor runs on the CPU, beside the simulator
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
    pinch = env.task.pinch_points[0].copy()
    keys = ("error_vertices", "error_mm2", "separated", "dropped_fraction")
    problem = env.task.pinch_problems[0]
    return {**{k: np.asarray(final[k]) for k in keys}, "pinch": pinch, "pinch_problem": problem}


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
    """The trained policy against no tension on its own options (paired by trial); ``pinch_feasible`` false
    and ``pinch_problem`` say where the run's pinch point is not a grasp the gripper could make (its options
    allowed it: ``allow_infeasible_pinch``).

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
        "pinch_feasible": row["rl_pinch_feasible"],
        "pinch_problem": row["rl_pinch_problem"],
        "seconds": time.perf_counter() - start,
    }
