"""Learned tensioners: train a PPO policy for one contour, and run a trained one in evaluations.

A run directory (``warpcut train``) holds rsl-rl's ``config.json``, checkpoints and TensorBoard events
(:func:`agents.train.train`), plus ``scenario.json`` (the env options the policy was trained on, so it
can be rebuilt without guessing) and ``evaluation.json`` (the trained policy against no tension).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from agents.export import load_policy
from agents.train import TrainConfig, train
from envs.pattern_cut import PatternCutOptions
from envs.rsl import PatternCutRslEnv
from envs.vector import PatternCutVecEnv
from warpcut.contours import Contour, load_contour
from warpcut.io import write_json
from warpcut.planning import nearest_feasible
from warpcut.sim.config import SimConfig
from warpcut.task import CuttingTask, default_segments


@dataclass
class Scenario:
    """What a policy is trained and evaluated on (everything but the batch size and seed).

    Attributes:
        contour: Built-in name or path of the contour file.
        pinch: Pinch point (mm, material); default: the centroid or the feasible point nearest to it.
        sim: SimConfig fields that differ from the defaults (e.g. ``{"noise_std": 0.05}``).
        num_fiducials: Fiducial points observed (paper: 12).
        contour_features: Add the tip and the tracking error to the observation.
        segments: Material polylines cut in this order (a plan's ``ordered_segments()``); default: the
            whole contour as one segment.
        dense_reward: Add the env's per-step cut-deviation shaping (the path score's increment) to the
            sparse final reward.
        action_type: ``discrete`` (paper: stay, +-x, +-y at 1 mm) or ``continuous`` (x-y moves up to
            1 mm per axis; a policy that outputs zero holds the grasp still, like fixed tensioning).
        allow_z: Let the grasp move along z too (``+-z``; lifting the sheet into the scissors' reach).
        observe_pinch: Add the pinch point to the observation (a policy shared across pinch points).
        candidates: Several pinch candidates for one shared policy, each ``{"pinch": [x, y], "segments":
            polylines or None}`` (a plan's candidate with its best order): env ``i`` pinches candidate
            ``i % K`` and cuts its segments; the pinch point is observed. ``pinch`` and ``segments`` must
            then be None; :meth:`at_candidate` is the single-pinch scenario of one candidate.
    """

    contour: str
    pinch: list[float] | None = None
    sim: dict = field(default_factory=dict)
    num_fiducials: int = 12
    contour_features: bool = False
    action_type: str = "discrete"
    dense_reward: bool = False
    segments: list[list[list[float]]] | None = None
    allow_z: bool = False
    observe_pinch: bool = False
    candidates: list[dict] | None = None

    def __post_init__(self):
        if self.candidates is None:
            return
        if not self.candidates or any(not isinstance(c, dict) or "pinch" not in c for c in self.candidates):
            raise ValueError('candidates: give a non-empty list of {"pinch": [x, y], "segments": ...}')
        if self.pinch is not None or self.segments is not None:
            raise ValueError("candidates: leave pinch and segments None; each candidate carries its own")
        self.observe_pinch = True

    def load_contour(self) -> Contour:
        return load_contour(self.contour)

    def sim_config(self) -> SimConfig:
        return SimConfig(**self.sim).validated()

    def pinch_point(self) -> np.ndarray:
        if self.candidates is not None:
            raise ValueError("pinch_point: a scenario with candidates has several; use at_candidate(k)")
        if self.pinch is not None:
            return np.asarray(self.pinch, dtype=np.float64)
        contour = self.load_contour()
        return nearest_feasible(contour.centroid, contour, self.sim_config())

    def at_candidate(self, k: int) -> Scenario:
        """The single-pinch scenario of candidate ``k`` (its pinch observed, as the shared policy expects)."""
        if self.candidates is None:
            raise ValueError("at_candidate: this scenario has no candidates")
        if not 0 <= k < len(self.candidates):
            raise ValueError(f"candidate: {k} is not in 0..{len(self.candidates) - 1}")
        c = self.candidates[k]
        fields = {**asdict(self), "candidates": None, "observe_pinch": True}
        return Scenario(**{**fields, "pinch": [float(v) for v in c["pinch"]], "segments": c.get("segments")})

    def vec_env(self, num_envs: int, device: str | None = None) -> PatternCutVecEnv:
        if self.candidates is None:
            pinch, segments = self.pinch_point(), self.segments
        else:  # env i: candidate i % K
            picks = [self.candidates[i % len(self.candidates)] for i in range(num_envs)]
            pinch = np.array([c["pinch"] for c in picks], dtype=np.float64)
            whole = [p.tolist() for p in default_segments(self.load_contour())]
            segments = [c.get("segments") or whole for c in picks]
        options = PatternCutOptions(
            contour=self.load_contour(),
            pinch_point=pinch,
            sim_config=self.sim_config(),
            device=device,
            num_fiducials=self.num_fiducials,
            contour_features=self.contour_features,
            action_type=self.action_type,
            allow_z=self.allow_z,
            dense_reward=self.dense_reward,
            segments=segments,
            observe_pinch=self.observe_pinch,
        )
        return PatternCutVecEnv(num_envs, options)


RECIPE = {"dense_reward": True, "contour_features": True, "allow_z": True}
"""warpcut's default learning recipe (Scenario fields; ``warpcut train``, ``evaluate`` and ``run`` use it):
dense cut-deviation shaping, contour-aware observations and x-y-z moves. Together with
``TrainConfig.stay_prior`` (start at "hold still") and validation-based model selection; see
docs/learning.md for the measurements behind each choice. The paper's setting is sparse reward,
fiducials only, x-y moves and a uniform initial policy."""

STAY_PRIOR = 0.9
"""``TrainConfig.stay_prior`` of the recipe: the initial policy holds still with probability 0.9."""


def recipe_config(**fields) -> TrainConfig:
    """A :class:`TrainConfig` for the recipe: ``fields`` with the recipe's ``stay_prior``."""
    return TrainConfig(**{"stay_prior": STAY_PRIOR, **fields})


VALIDATION_SEED_OFFSET = 7919
"""Validation episodes use seed ``cfg.seed + VALIDATION_SEED_OFFSET``: neither training's ``cfg.seed`` nor the
evaluations' small seeds, so model selection never sees an evaluation episode."""


def train_contour(
    scenario: Scenario,
    out_dir: str | Path,
    cfg: TrainConfig,
    resume: str | Path | None = None,
    eval_trials: int = 10,
    progress: bool = True,
    device: str | None = None,
    validation_trials: int = 16,
    on_step: Callable[[str], Callable[[CuttingTask, np.ndarray | None], None] | None] | None = None,
) -> dict:
    """Train a PPO tensioner for ``scenario`` into ``out_dir``, then evaluate it.

    With ``validation_trials > 0`` the deterministic policy is scored on that many held-out episodes
    (seed ``cfg.seed + VALIDATION_SEED_OFFSET``) before training and every ``cfg.validation_interval``
    iterations, and the best one is the run's policy (``best.pt``; see :func:`agents.train.train`).

    Args:
        scenario: Contour, pinch point and simulation settings.
        out_dir: Run directory.
        cfg: PPO settings (``cfg.device`` is torch's device).
        resume: Run directory or checkpoint to continue from.
        eval_trials: Trials of the final evaluation against no tension.
        progress: Show the progress bar.
        device: Warp device of the simulator.
        validation_trials: Held-out episodes per validation; 0 disables validation (the run's policy is
            then the last one).
        on_step: Step-callback factory for the final evaluation (see :func:`evaluate_run`), e.g. a
            recorder's ``on_step``.

    Returns:
        ``{"summary": training summary, "evaluation": evaluation of the run's policy}``.
    """
    if cfg.discrete != (scenario.action_type == "discrete"):
        raise ValueError(
            f"cfg.discrete={cfg.discrete} does not match the scenario's {scenario.action_type} actions"
        )
    out_dir = Path(out_dir)
    shared = scenario.candidates is not None
    if shared and validation_trials < 1:
        raise ValueError(
            "validation_trials: a scenario with candidates needs validation to choose one (>= 1)"
        )
    out_dir.mkdir(parents=True, exist_ok=True)
    if not shared:
        scenario = Scenario(**{**asdict(scenario), "pinch": [float(v) for v in scenario.pinch_point()]})
    write_json(out_dir / "scenario.json", asdict(scenario))
    env = PatternCutRslEnv(scenario.vec_env(cfg.num_envs, device=device), device=cfg.device, seed=cfg.seed)
    validate = None
    if validation_trials > 0:
        candidates = len(scenario.candidates) if shared else 1
        per_candidate = max(CANDIDATE_VALIDATION_MIN, -(-validation_trials // candidates)) if shared else None
        validation_env = scenario.vec_env(per_candidate * candidates if shared else validation_trials, device)

        def candidate_errors(actor: torch.nn.Module) -> np.ndarray:
            """Mean validation error (vertices) per candidate (env i pinches candidate i % K)."""
            seed = cfg.seed + VALIDATION_SEED_OFFSET
            errors = policy_errors(actor, validation_env, scenario, seed)["error_vertices"]
            return errors.reshape(-1, candidates).mean(axis=0)

        def validate(actor: torch.nn.Module) -> float:
            return float(candidate_errors(actor).min())  # the candidate the pipeline would choose

    summary = train(env, cfg, out_dir, resume=resume, progress=progress, validate=validate)
    if shared:
        errors = candidate_errors(load_policy(out_dir))
        chosen = int(np.argmin(errors))  # the first (the better fixed rank, as ordered) among ties
        selection = {
            "chosen": chosen,
            "pinch": [float(v) for v in scenario.candidates[chosen]["pinch"]],
            "validation_error_vertices": [float(e) for e in errors],
            "validation_episodes_per_candidate": per_candidate,
        }
        write_json(out_dir / CANDIDATES_FILE, selection)
        summary["candidates"] = selection
    evaluation = evaluate_run(out_dir, trials=eval_trials, seed=cfg.seed + 1, device=device, on_step=on_step)
    write_json(out_dir / "evaluation.json", evaluation)
    return {"summary": summary, "evaluation": evaluation}


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
    return int(json.loads(path.read_text())["chosen"])


def load_scenario(run_dir: str | Path) -> Scenario:
    path = Path(run_dir) / "scenario.json"
    if not path.is_file():
        raise FileNotFoundError(
            f"{run_dir}: no scenario.json; give a run directory written by 'warpcut train'"
        )
    return Scenario(**json.loads(path.read_text()))


def rollout_errors(
    run_dir: str | Path,
    trials: int,
    seed: int = 0,
    device: str | None = None,
    scenario: Scenario | None = None,
    on_step: Callable[[CuttingTask, np.ndarray | None], None] | None = None,
    paired_noise: tuple[int, int] | None = None,
) -> dict:
    """Run the trained policy (deterministic: argmax action) for ``trials`` seeded episodes at once.

    Trials differ by their fiducials and process-noise streams. Returns per-trial errors (vertices,
    mm^2) and the pinch point used. ``on_step(task, moves)`` is called after the reset (moves ``None``)
    and after every step, as in :meth:`warpcut.task.CuttingTask.run` (e.g. a recorder's callback).
    ``paired_noise``: see :func:`policy_errors`.
    """
    scenario = scenario or load_scenario(run_dir)
    if scenario.candidates is not None:  # a shared policy: at the candidate its run chose
        scenario = scenario.at_candidate(chosen_candidate(run_dir))
    actor = load_policy(run_dir)
    env = scenario.vec_env(trials, device=device)
    return policy_errors(actor, env, scenario, seed=seed, on_step=on_step, paired_noise=paired_noise)


def policy_errors(
    actor: torch.nn.Module,
    env: PatternCutVecEnv,
    scenario: Scenario,
    seed: int,
    on_step: Callable[[CuttingTask, np.ndarray | None], None] | None = None,
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
    with torch.inference_mode():
        for _ in range(env.task.num_steps):
            obs_td = {"policy": torch.as_tensor(obs)}
            action = actor(_tensordict(obs_td, trials)).cpu().numpy().reshape(trials, -1)
            if scenario.action_type == "discrete":
                action = action[:, 0].astype(np.int64)
            obs, _, terminated, truncated, info = env.scene.step(action)
            if on_step is not None:
                on_step(env.task, env.scene.moves(action))
            if terminated or truncated:
                final = info
                break
    if final is None or "error_vertices" not in final:
        raise RuntimeError(f"{scenario.contour}: the episode did not end within {env.task.num_steps} steps")
    pinch = None if scenario.candidates is not None else scenario.pinch_point()
    keys = ("error_vertices", "error_mm2", "separated", "dropped_fraction")
    return {**{k: np.asarray(final[k]) for k in keys}, "pinch": pinch}


def _tensordict(groups: dict[str, torch.Tensor], batch: int):
    from tensordict import TensorDict

    return TensorDict(groups, batch_size=[batch])


def evaluate_run(
    run_dir: str | Path,
    trials: int = 10,
    seed: int = 1,
    device: str | None = None,
    on_step: Callable[[str], Callable[[CuttingTask, np.ndarray | None], None] | None] | None = None,
) -> dict:
    """The trained policy against no tension on its own scenario (paired by trial).

    ``on_step`` maps a method's name (``"rl"``, ``"none"``) to the step callback of its batch, as in
    :func:`agents.evaluation.evaluate_suite` (e.g. ``recorder.on_step``).
    """
    from agents.evaluation import MethodSpec, ci95, paired_improvement, run_method

    scenario = load_scenario(run_dir)
    if scenario.candidates is not None:
        scenario = scenario.at_candidate(chosen_candidate(run_dir))
    contour = scenario.load_contour()
    start = time.perf_counter()
    hook = on_step or (lambda method: None)
    rl = rollout_errors(
        run_dir,
        trials,
        seed=seed,
        device=device,
        scenario=scenario,
        on_step=hook("rl"),
        paired_noise=(seed, 0),
    )
    segments = None if scenario.segments is None else [[np.asarray(p) for p in scenario.segments]]
    none = run_method(
        [contour],
        MethodSpec([None], None),
        trials,
        scenario.sim_config(),
        device,
        seed,
        on_step=hook("none"),
        segments=segments,
    ).errors
    improvement = paired_improvement(none[0], rl["error_vertices"])
    return {
        "contour": contour.name,
        "trials": trials,
        "none_error_vertices": float(none[0].mean()),
        "rl_error_vertices": float(rl["error_vertices"].mean()),
        "rl_error_mm2": float(rl["error_mm2"].mean()),
        "rl_improvement_pct": float(np.nanmean(improvement))
        if np.isfinite(improvement).any()
        else float("nan"),
        "rl_ci95": ci95(improvement),
        "pinch": [float(v) for v in rl["pinch"]],
        "seconds": time.perf_counter() - start,
    }


def benchmark_training(device: str | None = None, num_envs: int = 64, iterations: int = 4) -> float:
    """PPO env steps per second (collection + updates) training ``fls-circle`` on ``num_envs`` envs."""
    import tempfile

    cfg = TrainConfig(num_envs=num_envs, iterations=iterations, num_steps_per_env=32, save_interval=10**6)
    scenario = Scenario(contour="fls-circle")
    with tempfile.TemporaryDirectory() as out:
        env = PatternCutRslEnv(scenario.vec_env(num_envs, device=device), device=cfg.device, seed=cfg.seed)
        return float(train(env, cfg, out, progress=False)["steps_per_s"])
