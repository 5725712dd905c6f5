"""What an optimised plan is (:class:`PlanResult`: its moves, feedback gains, pinch point and history) and
how it is played (:class:`PlanPolicy`, the ``grad`` tensioner: open loop, or closed loop on the tracking
error, with gains scheduled on the sheet's sag)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from warpcut.task import CuttingTask


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
