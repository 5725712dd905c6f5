"""The plan optimiser: an open-loop plan of grasp moves, optimised by Adam through the differentiable
simulator (:mod:`warpcut.gradients`) or by evolution strategies through the batched one
(:class:`~agents.plan_optimizer.estimators.SmoothedGradient`, ``GradConfig.estimator == "es"``), and the
``grad`` method that plays it.

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
(``GradConfig.es_randomize``: errors weighed relative to no tension on each sheet,
:class:`~agents.plan_optimizer.estimators.RelativeWeights`; the held-out episodes randomised too,
:class:`~agents.plan_optimizer.estimators.HeldOut`).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from agents.adam import Adam
from agents.plan_optimizer.config import GRAD_CONFIG, GRAD_SEED_OFFSET, GradConfig
from agents.plan_optimizer.estimators import HeldOut, SmoothedGradient, TapeGradient, Tether
from agents.plan_optimizer.plan import PlanResult
from warpcut.contours import Contour
from warpcut.planning import ArmModel
from warpcut.planning.feasibility import check_pinch, pinch_feasible, pinch_problems
from warpcut.sim.config import SimConfig
from warpcut.sim.memory import batch_named
from warpcut.task import CuttingTask

if TYPE_CHECKING:
    from agents.evaluation import MethodResult
    from agents.methods import StepCallbacks
    from warpcut.planning import Plan
    from warpcut.task import StepCallback


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
    anchor: np.ndarray | None = None,
    tether: float = 0.0,
) -> PlanResult:
    """Optimise a plan (open or closed loop: ``es_feedback_phases``) for ``contour`` at ``pinch`` (module).

    Args:
        contour, pinch: The contour; the pinch point (material mm), e.g. the plan's chosen one.
        segments: The polylines cut in order (default: the contour as one segment).
        config: Simulation settings (default ``SimConfig()``), with the evaluation's noise.
        settings: The optimiser's (:class:`~agents.plan_optimizer.config.GradConfig`).
        device, seed: Warp device; seed (the episodes use ``seed + GRAD_SEED_OFFSET``).
        arm: The cutting arm whose footprint the pinch point must avoid (default: the paper's).
        log: Called with a progress line every few iterations.
        state_file: The optimiser's state is written here (atomically) after every iteration, and an
            optimisation interrupted (Ctrl-C, a crash) continues from it when it exists (it must be of
            the same contour, pinch point and settings).
        allow_infeasible_pinch: Optimise at a ``pinch`` the gripper could not hold instead of refusing it.
        anchor: ``(T, 3)`` moves (mm), e.g. a student's on this cut, to start from instead of a still grasp
            (cut or padded with still steps); iteration 0 then also records ``still_error_vertices``.
        tether: With ``anchor`` (es): the weight (vertices per mm²) of a cost on leaving it, added to every
            error the optimiser ranks and selects by (:class:`~agents.plan_optimizer.estimators.Tether`):
            guided policy search's trust region, which keeps the plan near the student it teaches.
    """
    settings, config, arm = settings.validated(), (config or SimConfig()).validated(), arm or ArmModel()
    pinch = np.asarray(pinch, dtype=np.float64).reshape(2)
    check_pinch(pinch, contour, config, segments, arm, allow=allow_infeasible_pinch)  # InfeasiblePinch
    es = settings.estimator == "es"
    if tether and (anchor is None or not es):
        raise ValueError("tether: needs an anchor plan and the es estimator; give both, or tether 0")
    b, batch = _batch(settings)
    cost = None

    def engine(point: np.ndarray) -> TapeGradient | SmoothedGradient:
        task = _episodes(contour, point, segments, config, b, device, seed + GRAD_SEED_OFFSET, batch)
        if es:
            return SmoothedGradient(task, settings, config.max_step_mm, seed, cost)
        return TapeGradient(task, settings, seed + GRAD_SEED_OFFSET)

    def checker(point: np.ndarray) -> HeldOut | None:
        v, held_out = settings.validation_trials, seed + GRAD_SEED_OFFSET + 1
        task = _episodes(contour, point, segments, config, v, device, held_out, _VALIDATION) if v else None
        return None if task is None else HeldOut(task, settings, held_out)

    rollout, validation = engine(pinch), checker(pinch)
    steps = rollout.num_steps
    plan = np.zeros((steps, 3), dtype=np.float32)
    identity = {"contour": contour.name, "pinch": pinch.tolist(), "steps": steps}
    identity.update(dataclasses.asdict(settings))
    if anchor is not None:
        plan = _fitted(anchor, steps, config.max_step_mm)
        identity.update(anchor=plan.tolist(), tether=float(tether))
        if tether:
            cost = rollout.tether = Tether(plan.copy(), float(tether))
    phases = settings.es_feedback_phases
    shape = (phases, 3, 4 if settings.es_feedback_sag else 2)  # 3 x 4: scheduled on the sag
    gains, gain_moves = (np.zeros(shape, np.float32) if phases else None), Adam(shape, settings.learning_rate)
    moves, pinch_moves = Adam(plan.shape, settings.learning_rate), Adam((2,), settings.pinch_learning_rate)
    history, best, first, elapsed = [], None, 0, 0.0
    state = _read_state(state_file, identity)
    if state is not None:
        first, history, elapsed = state["iteration"], state["history"], state["seconds"]
        plan, pinch, gains, best = _resumed(state, {"moves": moves, "pinch_moves": pinch_moves,
                                                    "gain_moves": gain_moves}, rollout)  # fmt: skip
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
            if anchor is not None and iteration == 0:
                still = None if gains is None else np.zeros_like(gains)
                record["still_error_vertices"] = validation(np.zeros_like(plan), still)
        if cost is not None:  # selection on the tethered objective, as the ranking
            record["tether_vertices"] = float(cost.cost(plan, config.max_step_mm))
            error = error + record["tether_vertices"]
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
            optimizers = {"moves": moves, "pinch_moves": pinch_moves, "gain_moves": gain_moves}
            _save_state(state_file, identity, iteration + 1, history, start, plan, pinch, gains, optimizers,
                        best, rollout)  # fmt: skip
    _, best_iteration, best_plan, best_pinch, best_gains = best
    env_steps = settings.iterations * b * steps if es else (settings.iterations + 1) * b * steps
    return PlanResult(
        contour.name, [float(v) for v in best_pinch], best_plan, best_iteration, history,
        time.perf_counter() - start, env_steps, best_gains,
    )  # fmt: skip


def _fitted(anchor: np.ndarray, steps: int, max_step: float) -> np.ndarray:
    """``anchor``'s moves as a plan of ``steps`` moves: cut, or padded with still steps, each axis clipped to
    ``max_step``; ``ValueError`` for moves that are not ``(T, 3)`` finite numbers."""
    moves = np.asarray(anchor, dtype=np.float32)
    if moves.ndim != 2 or moves.shape[1] != 3 or not np.all(np.isfinite(moves)):
        raise ValueError(f"anchor: must be (T, 3) finite moves in mm (got shape {moves.shape})")
    plan = np.zeros((steps, 3), dtype=np.float32)
    plan[: min(steps, len(moves))] = moves[:steps]
    return np.clip(plan, -max_step, max_step).astype(np.float32)


def _resumed(state: dict, optimizers: dict, rollout) -> tuple:
    """From :func:`optimize_plan`'s saved ``state``: ``(plan, pinch, gains, best)``, with its Adam
    ``optimizers`` (by name) and the estimator ``rollout`` loaded as they were."""
    for name, adam in optimizers.items():
        adam.load(state[name])
    rollout.load(state["estimator"])
    plan, pinch = np.asarray(state["plan"], np.float32), np.asarray(state["pinch"])
    gains = None if state["gains"] is None else np.asarray(state["gains"], np.float32)
    error, it, best_plan, best_pinch, best_gains = state["best"]
    best_gains = None if best_gains is None else np.asarray(best_gains, np.float32)
    return (
        plan,
        pinch,
        gains,
        (error, it, np.asarray(best_plan, np.float32), np.asarray(best_pinch), best_gains),
    )


def _save_state(
    state_file, identity, iteration, history, start, plan, pinch, gains, optimizers, best, rollout
) -> None:
    """Write :func:`optimize_plan`'s state after an iteration (atomically), what a resume continues from."""
    from warpcut.io import write_json

    error, it, best_plan, best_pinch, best_gains = best
    listed = [None if g is None else g.tolist() for g in (gains, best_gains)]
    state = {
        "identity": identity, "iteration": iteration, "history": history,
        "seconds": time.perf_counter() - start, "plan": plan.tolist(), "pinch": pinch.tolist(),
        "gains": listed[0], **{name: adam.state() for name, adam in optimizers.items()},
        "best": [error, it, best_plan.tolist(), best_pinch.tolist(), listed[1]],
        "estimator": rollout.state(),
    }  # fmt: skip
    write_json(state_file, state)


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
    *,
    anchor: np.ndarray | None = None,
    tether: float = 0.0,
) -> PlanResult:
    """:func:`optimize_plan`, kept in ``folder/NAME.json`` (a plan found there is used as it is; the
    optimiser's state is kept in ``NAME.state.json`` while it runs, and an interrupted optimisation
    continues from it). ``count``: the progress line's prefix, e.g. "[2/26] "; ``anchor``, ``tether``:
    :func:`optimize_plan`'s (the file's settings record the tether, where there is an anchor)."""
    from warpcut.io import read_json, safe_name, write_json

    done = state = None
    wanted = dataclasses.asdict(settings)
    if anchor is not None:
        wanted["tether"] = float(tether)
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
        contour, pinch, segments, config, settings, device, seed, arm, log, state, allow_infeasible_pinch,
        anchor, tether,
    )  # fmt: skip
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
