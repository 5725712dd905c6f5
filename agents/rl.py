"""Learned tensioners: train a PPO policy for one contour, and run a trained one in evaluations.

A run directory (``warpcut train``) holds rsl-rl's ``config.json``, checkpoints and TensorBoard events
(:func:`agents.train.train`), plus ``options.json`` (the :class:`~envs.options.PatternCutOptions` the
policy was trained on, so its env can be rebuilt without guessing) and ``evaluation.json`` (the trained
policy against no tension). Runs written before ``options.json`` existed hold ``scenario.json``, which
:func:`load_options` still reads.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import torch

from agents.config import EVALUATION_TRIALS, VALIDATION_TRIALS, TrainConfig
from agents.evaluation import Method, MethodResult, evaluate_suite
from agents.export import load_policy
from agents.methods import StepCallbacks
from agents.train import train
from envs.options import PatternCutOptions
from envs.rsl import PatternCutRslEnv
from envs.vector import PatternCutVecEnv
from warpcut.io import read_json, write_json
from warpcut.sim.config import SimConfig
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
) -> dict:
    """Train a PPO tensioner for ``options`` into ``out_dir``, then evaluate it.

    With ``validation_trials > 0`` the deterministic policy is scored on that many held-out episodes
    (seed ``cfg.seed + VALIDATION_SEED_OFFSET``) before training and every ``cfg.validation_interval``
    iterations, and the best one is the run's policy (``best.pt``; see :func:`agents.train.train`).

    Args:
        options: Contour, pinch point (None: the default, resolved and saved), segments, simulation
            settings, observations and actions; ``options.device`` is the simulator's Warp device (not
            saved: a run evaluates on any device).
        out_dir: Run directory.
        cfg: PPO settings (``cfg.torch_device`` is torch's device).
        resume: Run directory or checkpoint to continue from.
        eval_trials: Trials of the final evaluation against no tension.
        progress: Show the progress bar.
        validation_trials: Held-out episodes per validation; 0 disables validation (the run's policy is
            then the last one).
        step_callbacks: Step callbacks of the final evaluation's batches (see :func:`evaluate_run`).

    Returns:
        ``{"summary": training summary, "evaluation": evaluation of the run's policy}``.
    """
    if cfg.discrete != (options.action_type == "discrete"):
        raise ValueError(
            f"cfg.discrete={cfg.discrete} does not match the options' {options.action_type} actions"
        )
    out_dir = Path(out_dir)
    shared = options.candidates is not None
    if shared and validation_trials < 1:
        raise ValueError("validation_trials: options with candidates need validation to choose one (>= 1)")
    out_dir.mkdir(parents=True, exist_ok=True)
    if not shared:
        pinch = options.per_env(1)[1][0]
        options = dataclasses.replace(options, pinch_point=[float(v) for v in pinch])
    write_json(out_dir / OPTIONS_FILE, dataclasses.replace(options, device=None).to_dict())
    env = training_env(options, cfg)
    validate = None
    if validation_trials > 0:
        candidates = len(options.candidates) if shared else 1
        per_candidate = max(CANDIDATE_VALIDATION_MIN, -(-validation_trials // candidates)) if shared else None
        validation_env = PatternCutVecEnv(
            per_candidate * candidates if shared else validation_trials, options
        )

        def validate(actor: torch.nn.Module) -> np.ndarray:
            """Validation errors (vertices), (episodes, candidates): env i pinches candidate i % K."""
            seed = cfg.seed + VALIDATION_SEED_OFFSET
            return policy_errors(actor, validation_env, seed)["error_vertices"].reshape(-1, candidates)

        def candidate_errors(actor: torch.nn.Module) -> np.ndarray:
            """Mean validation error (vertices) per candidate."""
            return validate(actor).mean(axis=0)

    summary = train(env, cfg, out_dir, resume=resume, progress=progress, validate=validate)
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
    return int(read_json(path)["chosen"])


def is_run(run_dir: str | Path) -> bool:
    """Whether ``run_dir`` holds a trained run's options (so :func:`load_options` can read it)."""
    run_dir = Path(run_dir)
    return (run_dir / OPTIONS_FILE).is_file() or (run_dir / LEGACY_SCENARIO_FILE).is_file()


def load_options(run_dir: str | Path, device: str | None = None) -> PatternCutOptions:
    """The options a run was trained on, for the Warp ``device``; a shared policy's run gives those of the
    candidate it chose (as its evaluation uses)."""
    run_dir = Path(run_dir)
    if (run_dir / OPTIONS_FILE).is_file():
        options = PatternCutOptions.from_dict(read_json(run_dir / OPTIONS_FILE))
    elif (run_dir / LEGACY_SCENARIO_FILE).is_file():
        options = _from_scenario(read_json(run_dir / LEGACY_SCENARIO_FILE))
    else:
        raise FileNotFoundError(
            f"{run_dir}: no {OPTIONS_FILE}; give a run directory written by 'warpcut train'"
        )
    return dataclasses.replace(options, device=device)


def _from_scenario(scenario: dict) -> PatternCutOptions:
    """The options of a run's legacy ``scenario.json`` (its fields, renamed)."""
    fields = dict(scenario)
    renamed = {
        "contour": fields.pop("contour"),
        "pinch_point": fields.pop("pinch", None),
        "sim_config": SimConfig(**fields.pop("sim", {})),
    }
    return PatternCutOptions.from_dict({**fields, **renamed})


def policy_options(run_dir: str | Path, device: str | None = None) -> PatternCutOptions:
    """The options a run's policy is evaluated on: a shared policy's at the candidate its run chose."""
    options = load_options(run_dir, device)
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
) -> dict:
    """Run the trained policy (deterministic: argmax action) for ``trials`` seeded episodes at once.

    Trials differ by their fiducials and process-noise streams. Returns per-trial errors (vertices,
    mm^2) and the pinch point used. ``on_step(task, moves)`` is called after the reset (moves ``None``)
    and after every step, as in :meth:`warpcut.task.CuttingTask.run` (e.g. a recorder's callback).
    ``paired_noise``: see :func:`policy_errors`.
    """
    env = PatternCutVecEnv(trials, policy_options(run_dir, device))
    return policy_errors(load_policy(run_dir), env, seed=seed, on_step=on_step, paired_noise=paired_noise)


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


def benchmark_training(device: str | None = None, num_envs: int = 64, iterations: int = 4) -> float:
    """PPO env steps per second (collection + updates) training ``fls-circle`` on ``num_envs`` envs."""
    import tempfile

    cfg = TrainConfig(num_envs=num_envs, iterations=iterations, num_steps_per_env=32, save_interval=10**6)
    options = PatternCutOptions(contour="fls-circle", device=device)
    with tempfile.TemporaryDirectory() as out:
        return float(train(training_env(options, cfg), cfg, out, progress=False)["steps_per_s"])
