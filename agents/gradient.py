"""Gradient-based tensioning: an open-loop plan of grasp moves, optimised by Adam through the differentiable
simulator (:mod:`warpcut.gradients`) or by evolution strategies through the batched one
(:class:`SmoothedGradient`, ``GradConfig.estimator == "es"``), and the ``grad`` method that plays it.

The tape estimator's objective is the path surrogate (the mean squared distance between where the scissors
cut and where they meant to, in material coordinates), averaged over ``GradConfig.trials`` noisy episodes
whose seeds stay the same from step to step (common random numbers) and differ from the evaluation's; the
es estimator's is the path score itself, smoothed by Gaussian perturbations of the plan. Every move is
projected back onto ``max_step_mm`` per axis after each step; the simulator applies the displacement cap.
Every iterate is also played on ``GradConfig.validation_trials`` held-out episodes (other seeds again) and
scored with the path score: the iterate with the lowest mean validation error, the initial still grasp
(iteration 0, fixed tensioning) included, is the result (without validation episodes: the lowest error
on the optimiser's own episodes).

With es the plan may be closed loop (``GradConfig.es_feedback_phases``: feedback gains on the tracking
error, optimised with the plan or, with ``es_feedback_only``, alone) and the episodes' sheets randomised
(``GradConfig.es_randomize``: errors weighed relative to no tension on each sheet, :class:`RelativeWeights`;
the held-out episodes randomised too, :class:`HeldOut`).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from agents.adam import Adam
from agents.config import (
    GRAD_CONFIG,
    GRAD_SEED_OFFSET,
    GradConfig,
)
from warpcut.contours import Contour
from warpcut.planning import ArmModel
from warpcut.planning.feasibility import check_pinch, pinch_feasible, pinch_problems
from warpcut.sim.config import SimConfig, randomize_ranges, sample_parameters
from warpcut.sim.memory import batch_named
from warpcut.task import CuttingTask, NoTensionReference

if TYPE_CHECKING:
    from agents.evaluation import MethodResult
    from agents.methods import StepCallbacks
    from warpcut.planning import Plan
    from warpcut.task import StepCallback


@dataclass
class PlanResult:
    """An optimised plan and how it was found."""

    contour: str
    pinch: list[float]
    """The pinch point (material mm) the plan is played at (the optimiser moves it with
    ``optimize_pinch``)."""
    plan: np.ndarray
    """(T, 3) grasp moves (mm), one per env step."""
    best_iteration: int
    """The iterate kept (0: the initial still grasp)."""
    history: list[dict] = field(default_factory=list)
    """Per iterate: ``iteration``, ``surrogate`` (mm^2) and ``error_vertices`` (mean over the episodes;
    es: no surrogate, the perturbed plans' mean error, none for the last iterate), ``pinch``,
    ``validation_error_vertices`` (the held-out episodes', when there are some; weighed under
    ``es_randomize``), ``seconds`` since the
    start."""
    seconds: float = 0.0
    """Wall time of the optimisation."""
    env_steps: int = 0
    """Env steps the optimiser simulated forward (episodes x steps; the held-out validation episodes not
    counted); each backward pass of the tape estimator replays as many again."""
    gains: np.ndarray | None = None
    """(P, 3, F) feedback gains (mm of move per mm of x-y tracking error), one matrix per phase of the
    episode (``GradConfig.es_feedback_phases``); F = 2, or 4 with gains scheduled on the sheet's sag
    (``GradConfig.es_feedback_sag``, :func:`feedback_features`); None: an open-loop plan."""

    def to_json(self) -> dict:
        return {
            "contour": self.contour,
            "pinch": [float(v) for v in self.pinch],
            # every float32 bit: a plan read back must play as the one found (the sheet is chaotic: moves
            # rounded to 1e-6 mm changed trials by vertices)
            "plan": np.asarray(self.plan, dtype=np.float32).astype(np.float64).tolist(),
            "best_iteration": self.best_iteration,
            "history": self.history,
            "seconds": self.seconds,
            "env_steps": self.env_steps,
            "gains": None
            if self.gains is None
            else np.asarray(self.gains, np.float32).astype(float).tolist(),
        }

    @classmethod
    def from_json(cls, data: dict) -> PlanResult:
        plan = np.asarray(data["plan"], dtype=np.float32).reshape(-1, 3)
        gains = data.get("gains")  # a plan without gains is open loop
        return cls(
            data["contour"], list(data["pinch"]), plan, int(data["best_iteration"]), list(data["history"]),
            float(data["seconds"]), int(data["env_steps"]),
            None if gains is None else _gain_matrices(gains),
        )  # fmt: skip

    @staticmethod
    def policy(results: Sequence[PlanResult], trials: int) -> PlanPolicy:
        """The :class:`PlanPolicy` playing ``results`` (contour by contour, ``trials`` envs each), closed
        loop where they have gains."""
        return PlanPolicy([r.plan for r in results], trials, [r.gains for r in results])


class PlanPolicy:
    """The ``grad`` tensioner: plays plans, env ``e`` the plan of contour ``e // trials`` (the layout of
    :func:`agents.evaluation.run_method`); a plan shorter than the episode holds still after it. With
    ``gains`` (per plan, (P, 3, F) or None; :attr:`PlanResult.gains`) it is closed loop: each move is the
    plan's plus the phase's gain matrix times :func:`feedback_features` (the x-y tracking error, and with
    F = 4 that error times the sheet's sag), clipped to ``max_step_mm`` per axis; the last phase's gains act
    after the plan's end. Plans with F = 2 beside plans with F = 4 get zero sag gains."""

    def __init__(
        self, plans: Sequence[np.ndarray], trials: int = 1, gains: Sequence[np.ndarray | None] | None = None
    ):
        self.plans = [np.asarray(p, dtype=np.float32).reshape(-1, 3) for p in plans]
        self.trials = int(trials)
        self.gains: list[np.ndarray] | None = None
        if gains is not None and any(g is not None for g in gains):
            if len(gains) != len(self.plans):
                raise ValueError(f"gains: {len(gains)} for {len(self.plans)} plan(s); give one per plan")
            matrices = [None if g is None else _gain_matrices(g) for g in gains]
            width = max(g.shape[-1] for g in matrices if g is not None)
            self.gains = [
                np.zeros((1, 3, width), np.float32)
                if g is None
                else np.pad(g, ((0, 0), (0, 0), (0, width - g.shape[-1])))
                for g in matrices
            ]

    def __call__(self, task: CuttingTask) -> np.ndarray:
        if task.num_envs != len(self.plans) * self.trials:
            raise ValueError(
                f"plans: {len(self.plans)} plan(s) x {self.trials} trial(s) for a batch of "
                f"{task.num_envs} envs"
            )
        t = task.step_index
        moves = [p[t] if t < len(p) else np.zeros(3, np.float32) for p in self.plans]
        moves = np.repeat(np.asarray(moves, dtype=np.float32), self.trials, axis=0)
        if self.gains is None:
            return moves
        pairs = zip(self.plans, self.gains, strict=True)
        phases = [g[min(t * len(g) // max(len(p), 1), len(g) - 1)] for p, g in pairs]
        gains = np.repeat(np.asarray(phases), self.trials, axis=0)  # (B, 3, F)
        features = feedback_features(task, scheduled=gains.shape[-1] == 4)
        step = task.config.max_step_mm
        return np.clip(moves + np.einsum("bij,bj->bi", gains, features), -step, step).astype(np.float32)


SAG_SCALE_MM = 10.0
"""The unit of :func:`sheet_sag`: the default sheet settles to a mean depth of 12.4 mm (0 mm without gravity,
16.0 mm at twice the default's)."""


def sheet_sag(task: CuttingTask) -> np.ndarray:
    """(B,) how far each env's sheet hangs, before the grasp or the scissors touch it: the settled sheet's
    mean depth below its clamped corners, in units of :data:`SAG_SCALE_MM`. What a depth camera sees of the
    sheet at the start; 0 for a sheet that hangs flat (no gravity)."""
    return -task.sim.settled_positions()[..., 2].mean(axis=1) / SAG_SCALE_MM


def feedback_features(task: CuttingTask, scheduled: bool = False) -> np.ndarray:
    """(B, 2) the x-y tracking error (mm; :meth:`CuttingTask.tracking_error`, 0 where there is none) that
    feedback gains act on; ``scheduled``: (B, 4), that error and the error times :func:`sheet_sag`, so a
    gain matrix of 3 x 4 is scheduled on the sag (``GradConfig.es_feedback_sag``)."""
    error = np.nan_to_num(task.tracking_error()[:, :2], nan=0.0)
    if not scheduled:
        return error
    return np.concatenate([error, error * sheet_sag(task)[:, None].astype(error.dtype)], axis=1)


def _gain_matrices(gains) -> np.ndarray:
    """``gains`` as (P, 3, F) float32 matrices, F = 2 or 4 (:attr:`PlanResult.gains`); ``ValueError`` naming
    the field otherwise."""
    matrices = np.asarray(gains, dtype=np.float32)
    if matrices.ndim != 3 and matrices.size % 6 == 0:
        matrices = matrices.reshape(-1, 3, 2)  # a flat list of 3 x 2 matrices
    if matrices.ndim != 3 or matrices.shape[1:] not in ((3, 2), (3, 4)):
        raise ValueError(
            f"gains: expected 3 x 2 or 3 x 4 matrices, one per phase, got shape {matrices.shape}; give the "
            "gains an optimisation wrote (warpcut optimize), or none"
        )
    return matrices


def _read_state(state_file: Path | None, identity: dict) -> dict | None:
    """The optimiser's saved state if ``state_file`` exists; ``ValueError`` if it is another run's."""
    from warpcut.io import read_json

    if state_file is None or not Path(state_file).is_file():
        return None
    state = read_json(state_file)
    if plan_settings(state.get("identity")) != identity:
        raise ValueError(
            f"{state_file}: an optimisation of other settings ({state.get('identity')}); delete it, or start "
            "a new run"
        )
    return state


def plan_settings(saved: dict | None) -> dict | None:
    """Settings (or an identity holding them) read from a file, with the :class:`GradConfig` fields it
    lacks at their defaults (e.g. ``es_feedback_sag``), the behaviour of a plan without them."""
    if saved is None or "estimator" not in saved:
        return saved
    return {**dataclasses.asdict(GradConfig()), **saved}


_VALIDATION = ("grad.validation_trials", "set grad.validation_trials to at most {fits} (0: none)")
"""The held-out batch as a refusal too big for memory names it, and its fix."""


def _batch(settings: GradConfig) -> tuple[int, tuple[str, str]]:
    """The optimiser's batch: its envs, and its name and fix where it does not fit in memory
    (:func:`warpcut.sim.memory.batch_named`): es's population x trials, or the tape's trials."""
    if settings.estimator != "es":
        return settings.trials, ("grad.trials", "set grad.trials to at most {fits}")
    population, trials = settings.es_population, settings.es_trials
    return population * trials, (
        f"es's batch (grad.es_population x grad.es_trials = {population} x {trials})",
        "lower grad.es_population (even) or grad.es_trials to at most {fits} envs in all",
    )


def _episodes(contour, point, segments, config, count: int, device, seed: int, batch) -> CuttingTask:
    """``count`` noisy episodes of cutting ``contour`` (``segments``) with the grasp at ``point``, which
    :func:`optimize_plan` judged (a pinch point it moves stays feasible); ``batch``: the batch's name and fix
    where it does not fit in memory (:func:`warpcut.sim.memory.batch_named`)."""
    cut = None if segments is None else [segments] * count
    points, contours = np.tile(point, (count, 1)), [contour] * count
    with batch_named(*batch):
        return CuttingTask(
            config, contours, pinch_points=points, segments=cut, device=device, seed=seed,
            allow_infeasible_pinch=True,
        )  # fmt: skip


class TapeGradient:
    """The tape estimator (``GradConfig.estimator == "tape"``): the path surrogate's gradient through
    ``wp.Tape`` (:class:`warpcut.gradients.DifferentiableRollout`), averaged over the episodes of ``task``
    (``GradConfig.trials``; the noise of ``seed``, the same every step); ``pinch_grad`` holds the last
    step's gradient with respect to the pinch point."""

    def __init__(self, task: CuttingTask, settings: GradConfig, seed: int):
        from warpcut.gradients import DifferentiableRollout

        self.rollout, self.settings, self.seed = DifferentiableRollout(task), settings, seed
        self.pinch_grad: np.ndarray | None = None

    @property
    def num_steps(self) -> int:
        return self.rollout.num_steps

    def state(self) -> None:
        return None  # nothing random: the episodes' noise is the seed's

    def load(self, state: None) -> None:
        pass

    def step(self, plan: np.ndarray, gains: None, last: bool) -> tuple[dict, np.ndarray | None, None]:
        """``(history fields, gradient, None)`` for :func:`optimize_plan` (no feedback gains); the last
        iterate has no backward pass."""
        batch = np.broadcast_to(plan, (self.settings.trials, *plan.shape))
        if last:
            forward, grads = self.rollout.forward(batch, seed=self.seed), None
        else:
            forward, grads = self.rollout.value_and_grad(batch, seed=self.seed, window=self.settings.window)
        self.pinch_grad = None if grads is None else grads.pinch.mean(axis=0)
        record = {
            "surrogate": float(np.nanmean(forward.surrogate)),
            # a diverged episode is NaN (and has no gradient)
            "error_vertices": float(np.nanmean(forward.score.error_vertices)),
        }
        return record, None if grads is None else grads.actions.mean(axis=0), None


class SmoothedGradient:
    """The es estimator (``GradConfig.estimator == "es"``): the gradient of the path score averaged over
    Gaussian perturbations of the plan, ``∇ E[error(plan + σε)]``, estimated from ``es_population`` perturbed
    plans in antithetic pairs (``+ε``, ``-ε``), each played on ``es_trials`` noisy episodes, all in one
    simulator batch. Errors are replaced by their centred ranks (robust to the score's outliers and scale;
    Salimans et al. 2017), a diverged plan ranking last. Forward passes only: no surrogate, no tape; what is
    smoothed is the score the evaluation reports.

    ``task``: the ``es_population x es_trials`` episodes (plan ``p``'s trials are envs ``p * es_trials ...``);
    ``seed``: the perturbations' random stream (NumPy's PCG64; :meth:`state` and :meth:`load` keep it across
    a resume)."""

    def __init__(self, task: CuttingTask, settings: GradConfig, max_step: float, seed: int):
        self.task, self.settings, self.max_step = task, settings, float(max_step)
        self.rng = np.random.default_rng(seed)
        self.ranges = randomize_ranges(settings.es_randomize, settings.es_randomize_ranges)
        self.weights = RelativeWeights(task.config) if self.ranges else None

    @property
    def num_steps(self) -> int:
        return self.task.num_steps

    def state(self) -> dict:
        return self.rng.bit_generator.state

    def load(self, state: dict) -> None:
        self.rng.bit_generator.state = state

    def step(
        self, plan: np.ndarray, gains: np.ndarray | None, last: bool
    ) -> tuple[dict, np.ndarray | None, np.ndarray | None]:
        """``(history fields, plan's gradient, gains' gradient)`` for :func:`optimize_plan`; the last
        iterate is only validated."""
        if last:
            return {"surrogate": None, "error_vertices": None}, None, None
        error, grad, gains_grad = self(plan, gains)
        return {"surrogate": None, "error_vertices": error}, grad, gains_grad

    def __call__(
        self, plan: np.ndarray, gains: np.ndarray | None = None
    ) -> tuple[float, np.ndarray, np.ndarray | None]:
        """``(mean error of the perturbed plans in vertices (weighed, with es_randomize), gradient estimate
        shaped like plan, like gains (None without))``."""
        population, trials, sigma = (
            self.settings.es_population,
            self.settings.es_trials,
            self.settings.es_sigma_mm,
        )
        if self.settings.es_feedback_only:  # the plan stays as it is (zero): only the gains move
            eps = np.zeros((population, *plan.shape), dtype=np.float32)
        else:
            half = self.rng.standard_normal((population // 2, *plan.shape)).astype(np.float32)
            eps = np.concatenate([half, -half])
        plans = np.clip(plan + sigma * eps, -self.max_step, self.max_step).astype(np.float32)
        perturbed, eps_gains = None, None
        if gains is not None:
            half = self.rng.standard_normal((population // 2, *gains.shape)).astype(np.float32)
            eps_gains = np.concatenate([half, -half])
            perturbed = list(gains + sigma * eps_gains)
        if self.ranges:  # the same draws for every perturbed plan: env p * trials + k draws trial k's
            draws = sample_parameters(self.rng, self.ranges, trials)
            self.task.set_params(**{k: np.tile(v, population) for k, v in draws.items()})
        errors = self.task.run(PlanPolicy(list(plans), trials, perturbed)).error_vertices
        if self.weights is not None:
            errors = errors * self.weights(self.task)
        errors = errors.reshape(population, trials)
        finite = np.isfinite(errors).all(axis=1)
        fitness = np.where(finite, errors.mean(axis=1), np.inf)
        ranks = np.empty(population)
        ranks[np.argsort(fitness, kind="stable")] = np.arange(population)
        centred = ranks / (population - 1) - 0.5  # the highest error +0.5
        grad = np.tensordot(centred, eps, axes=1) / (population * sigma)
        gains_grad = (
            None if eps_gains is None else np.tensordot(centred, eps_gains, axes=1) / (population * sigma)
        )
        mean = float(np.mean(fitness[finite])) if finite.any() else float("nan")
        return mean, grad, gains_grad


class RelativeWeights:
    """Each env's weight under ``GradConfig.es_randomize``: the nominal sheet's no-tension error over that of
    the env's own sheet (:class:`warpcut.task.NoTensionReference`), so a sheet that hangs flat counts as much
    as the nominal one, as in the evaluation's relative improvement."""

    def __init__(self, nominal: SimConfig):
        self.nominal, self.reference = nominal, NoTensionReference()

    def __call__(self, task: CuttingTask) -> np.ndarray:
        return self.reference.scale(task, self.nominal)


class HeldOut:
    """The held-out episodes every iterate is scored on (``GradConfig.validation_trials``): their mean path
    error in vertices; with ``settings.es_randomize`` (over ``es_randomize_ranges``) they draw their
    parameters once, seeded by ``seed``, and each error is weighed as the es estimator weighs its own
    (:class:`RelativeWeights`)."""

    def __init__(self, task: CuttingTask, settings: GradConfig, seed: int):
        self.task, ranges = task, randomize_ranges(settings.es_randomize, settings.es_randomize_ranges)
        self.weights = RelativeWeights(task.config) if ranges else None
        if ranges:
            task.set_params(**sample_parameters(np.random.default_rng(seed), ranges, task.num_envs))

    def __call__(self, plan: np.ndarray, gains: np.ndarray | None) -> float:
        errors = self.task.run(PlanPolicy([plan], self.task.num_envs, [gains])).error_vertices
        if self.weights is not None:
            errors = errors * self.weights(self.task)
        return float(np.nanmean(errors))


def optimize_plan(
    contour: Contour,
    pinch: np.ndarray,
    segments: list[np.ndarray] | None = None,
    config: SimConfig | None = None,
    settings: GradConfig = GRAD_CONFIG,
    device: str | None = None,
    seed: int = 0,
    arm: ArmModel | None = None,
    log: Callable[[str], None] = lambda _: None,
    state_file: Path | None = None,
    allow_infeasible_pinch: bool = False,
) -> PlanResult:
    """Optimise a plan (open or closed loop: ``es_feedback_phases``) for ``contour`` at ``pinch`` (module).

    Args:
        contour, pinch: The contour; the pinch point (material mm), e.g. the plan's chosen one.
        segments: The polylines cut in order (default: the contour as one segment).
        config: Simulation settings (default ``SimConfig()``), with the evaluation's noise.
        settings: The optimiser's (:class:`~agents.config.GradConfig`).
        device, seed: Warp device; seed (the episodes use ``seed + GRAD_SEED_OFFSET``).
        arm: The cutting arm whose footprint the pinch point must avoid (default: the paper's).
        log: Called with a progress line every few iterations.
        state_file: The optimiser's state is written here (atomically) after every iteration, and an
            optimisation interrupted (Ctrl-C, a crash) continues from it when it exists (it must be of
            the same contour, pinch point and settings).
        allow_infeasible_pinch: Optimise at a ``pinch`` the gripper could not hold instead of refusing it.
    """
    from warpcut.io import write_json

    settings, config, arm = settings.validated(), (config or SimConfig()).validated(), arm or ArmModel()
    pinch = np.asarray(pinch, dtype=np.float64).reshape(2)
    check_pinch(pinch, contour, config, segments, arm, allow=allow_infeasible_pinch)  # InfeasiblePinch
    es = settings.estimator == "es"
    b, batch = _batch(settings)

    def engine(point: np.ndarray) -> TapeGradient | SmoothedGradient:
        task = _episodes(contour, point, segments, config, b, device, seed + GRAD_SEED_OFFSET, batch)
        if es:
            return SmoothedGradient(task, settings, config.max_step_mm, seed)
        return TapeGradient(task, settings, seed + GRAD_SEED_OFFSET)

    def checker(point: np.ndarray) -> HeldOut | None:
        v, held_out = settings.validation_trials, seed + GRAD_SEED_OFFSET + 1
        task = _episodes(contour, point, segments, config, v, device, held_out, _VALIDATION) if v else None
        return None if task is None else HeldOut(task, settings, held_out)

    rollout, validation = engine(pinch), checker(pinch)
    steps = rollout.num_steps
    plan = np.zeros((steps, 3), dtype=np.float32)
    phases = settings.es_feedback_phases
    shape = (phases, 3, 4 if settings.es_feedback_sag else 2)  # 3 x 4: scheduled on the sag
    gains, gain_moves = (np.zeros(shape, np.float32) if phases else None), Adam(shape, settings.learning_rate)
    moves, pinch_moves = Adam(plan.shape, settings.learning_rate), Adam((2,), settings.pinch_learning_rate)
    history, best, first, elapsed = [], None, 0, 0.0
    identity = {
        "contour": contour.name,
        "pinch": pinch.tolist(),
        "steps": steps,
        **dataclasses.asdict(settings),
    }
    state = _read_state(state_file, identity)
    if state is not None:
        first, history, elapsed = state["iteration"], state["history"], state["seconds"]
        plan, pinch = np.asarray(state["plan"], np.float32), np.asarray(state["pinch"])
        moves.load(state["moves"])
        pinch_moves.load(state["pinch_moves"])
        gain_moves.load(state["gain_moves"])
        rollout.load(state["estimator"])
        gains = None if state["gains"] is None else np.asarray(state["gains"], np.float32)
        error, it, best_plan, best_pinch, best_gains = state["best"]
        best_gains = None if best_gains is None else np.asarray(best_gains, np.float32)
        best = (error, it, np.asarray(best_plan, np.float32), np.asarray(best_pinch), best_gains)
        if not np.allclose(pinch, identity["pinch"]):
            rollout, validation = engine(pinch), checker(pinch)
        log(f"  continuing from iteration {first} ({state_file})")
    start = time.perf_counter() - elapsed
    for iteration in range(first, settings.iterations + 1):
        last = iteration == settings.iterations
        fields, step, gains_step = rollout.step(plan, gains, last)
        record = {"iteration": iteration, **fields, "pinch": [float(v) for v in pinch]}
        error = record["error_vertices"]  # es: the perturbed plans'; the plan itself is validated
        if validation is not None:  # model selection on held-out episodes
            error = record["validation_error_vertices"] = validation(plan, gains)
        record["seconds"] = time.perf_counter() - start
        history.append(record)
        if best is None or error < best[0]:
            best = (error, iteration, plan.copy(), pinch.copy(), None if gains is None else gains.copy())
        if iteration % 5 == 0 or last:
            surrogate = "" if es else f"surrogate {record['surrogate']:.2f} mm^2, "
            log(f"  iteration {iteration}: {surrogate}error {error:.2f} vertices ({record['seconds']:.0f} s)")
        if last:
            break
        plan = np.clip(plan + moves.step(step), -config.max_step_mm, config.max_step_mm).astype(np.float32)
        if gains is not None:
            gains = (gains + gain_moves.step(gains_step)).astype(np.float32)
        if settings.optimize_pinch:
            moved = pinch + pinch_moves.step(rollout.pinch_grad)
            segments_path = None if segments is None else [np.asarray(s) for s in segments]
            if pinch_feasible(moved[None], contour, config, segments_path, arm)[0]:
                pinch = moved
                rollout, validation = engine(pinch), checker(pinch)
        if state_file is not None:
            error, it, best_plan, best_pinch, best_gains = best
            listed = [None if g is None else g.tolist() for g in (gains, best_gains)]
            state = {
                "identity": identity, "iteration": iteration + 1, "history": history,
                "seconds": time.perf_counter() - start, "plan": plan.tolist(), "pinch": pinch.tolist(),
                "gains": listed[0], "moves": moves.state(), "pinch_moves": pinch_moves.state(),
                "gain_moves": gain_moves.state(),
                "best": [error, it, best_plan.tolist(), best_pinch.tolist(), listed[1]],
                "estimator": rollout.state(),
            }  # fmt: skip
            write_json(state_file, state)
    _, best_iteration, best_plan, best_pinch, best_gains = best
    env_steps = settings.iterations * b * steps if es else (settings.iterations + 1) * b * steps
    return PlanResult(
        contour.name, [float(v) for v in best_pinch], best_plan, best_iteration, history,
        time.perf_counter() - start, env_steps, best_gains,
    )  # fmt: skip


def grad_result(
    contours: Sequence[Contour],
    pinches: Sequence[np.ndarray],
    segments: Sequence[list[np.ndarray] | None],
    trials: int,
    config: SimConfig,
    settings: GradConfig = GRAD_CONFIG,
    device: str | None = None,
    seed: int = 0,
    folder: Path | None = None,
    log: Callable[[str], None] = lambda _: None,
    arm: ArmModel | None = None,
    on_step: StepCallback | None = None,
    allow_infeasible_pinch: bool = False,
) -> tuple[MethodResult, list[PlanResult]]:
    """The ``grad`` method on a suite: a plan per contour, then every (contour, trial) played in one batch
    with the evaluation's noise (paired with the baselines'); ``(MethodResult, [PlanResult])``.

    ``folder``: each contour's plan is kept in ``NAME.json`` (a plan found there is used as it is) and its
    optimiser's state in ``NAME.state.json`` while it runs (an interrupted optimisation continues).
    ``on_step``: the evaluation batch's step callback (:meth:`CuttingTask.run`), e.g. the regions plot's.
    ``allow_infeasible_pinch``: optimise and play at pinch points the gripper could not hold (the result's
    ``pinch_problems`` say which) instead of refusing them."""
    from agents.evaluation import run_method

    n = len(contours)
    results = [
        cached_plan(
            contour, pinch, cut, config, settings, device, seed, folder, log, arm, f"[{k + 1}/{n}] ",
            allow_infeasible_pinch,
        )
        for k, (contour, pinch, cut) in enumerate(zip(contours, pinches, segments, strict=True))
    ]  # fmt: skip
    method = run_method(
        contours, [np.asarray(r.pinch) for r in results], PlanResult.policy(results, trials),
        trials, config, device, seed, on_step, segments=list(segments), arm=arm,
        allow_infeasible_pinch=allow_infeasible_pinch,
    )  # fmt: skip
    return method, results


def cached_plan(
    contour: Contour,
    pinch: np.ndarray,
    segments: list[np.ndarray] | None,
    config: SimConfig,
    settings: GradConfig = GRAD_CONFIG,
    device: str | None = None,
    seed: int = 0,
    folder: Path | None = None,
    log: Callable[[str], None] = lambda _: None,
    arm: ArmModel | None = None,
    count: str = "",
    allow_infeasible_pinch: bool = False,
) -> PlanResult:
    """:func:`optimize_plan`, kept in ``folder/NAME.json`` (a plan found there is used as it is; the
    optimiser's state is kept in ``NAME.state.json`` while it runs, and an interrupted optimisation
    continues from it). ``count``: the progress line's prefix, e.g. "[2/26] "."""
    from warpcut.io import read_json, safe_name, write_json

    done = state = None
    wanted = dataclasses.asdict(settings)
    if folder is not None:
        done = Path(folder) / f"{safe_name(contour.name)}.json"
        state = done.with_suffix(".state.json")
        if done.is_file():
            data = read_json(done)
            if plan_settings(data.get("settings", wanted)) != wanted:  # none kept: as wanted
                raise ValueError(
                    f"{done}: a plan optimised with other settings ({data['settings']}, here {wanted}); "
                    "delete it to optimise again, or run with its settings"
                )
            started = data["history"][0]["pinch"] if data.get("history") else data["pinch"]
            if not np.allclose(started, pinch):
                raise ValueError(
                    f"{done}: a plan optimised at the pinch point {started}, not {list(pinch)}; delete it to "
                    "optimise again"
                )
            return PlanResult.from_json(data)
    log(
        f"  {count}optimising a plan for {contour.name} ({settings.iterations} iterations, "
        f"{settings.estimator} estimator)"
    )
    result = optimize_plan(
        contour, pinch, segments, config, settings, device, seed, arm, log, state, allow_infeasible_pinch
    )
    if done is not None:
        problem = pinch_problems(np.asarray(result.pinch)[None], contour, config, None, arm or ArmModel())[0]
        marked = {"pinch_feasible": problem is None, "pinch_problem": problem}  # the file says it, too
        write_json(done, {**result.to_json(), **marked, "settings": wanted})
        state.unlink(missing_ok=True)
    return result


def grad_column(
    contours: list[Contour],
    plans: list[Plan] | None,
    out: Path,
    trials: int,
    config: SimConfig,
    settings: tuple[GradConfig, ArmModel],
    device: str | None,
    seed: int,
    log: Callable[[str], None],
    step_callbacks: StepCallbacks | None = None,
) -> tuple[MethodResult, Callable[[dict], None]]:
    """:func:`agents.pipelines.table.evaluate_table`'s grad column (:func:`grad_result`, kept in
    ``out/grad``) at
    the planned pinch points and segments (unplanned: the feasible centroid, the contour as one loop);
    ``settings`` is the optimiser's config and the cutting arm. Returns the result and ``note(table)``,
    which adds each row's ``grad_best_iteration``, ``grad_seconds`` and ``grad_env_steps``, and how many
    contours kept the initial plan (``grad_initial_plan_contours``)."""
    from warpcut.planning.feasibility import default_pinch

    grad, arm = settings
    if plans is not None:
        pinches, segments = [p.chosen["pinch"] for p in plans], [p.ordered_segments() for p in plans]
    else:
        pinches, segments = [default_pinch(c, config, arm) for c in contours], [None] * len(contours)
    started = time.perf_counter()
    on_step = None if step_callbacks is None else step_callbacks("grad", 0)
    method, optimized = grad_result(
        contours, pinches, segments, trials, config, grad, device, seed, out / "grad", log, arm, on_step
    )
    log(f"  grad: {len(contours)} plan(s) in {time.perf_counter() - started:.0f} s")

    def note(table: dict) -> None:
        for row, result in zip(table["rows"], optimized, strict=True):
            row["grad_best_iteration"], row["grad_seconds"] = result.best_iteration, result.seconds
            row["grad_env_steps"] = result.env_steps
        table["grad_initial_plan_contours"] = sum(1 for r in optimized if r.best_iteration == 0)

    return method, note
