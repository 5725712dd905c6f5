"""The paper's baseline tensioners, batched: no tension, fixed pinch, analytic (error-opposing).

A tensioner chooses a pinch point for a contour (:meth:`pinch_point`) and then, each env step, maps
the :class:`~warpcut.task.CuttingTask` to a (B, 3) grasp move in mm (``__call__``). Moves are clipped
by the simulator to ``max_step_mm`` per axis and ``max_displacement_mm`` in total.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from warpcut.contours import Contour
from warpcut.planning import ArmModel, default_pinch, pinch_candidates
from warpcut.sim.config import AUTHORS_UNITS_PER_MM, PINCH_CANDIDATES, SimConfig
from warpcut.sim.memory import batch_named
from warpcut.task import CuttingTask, SimulationDiverged


@dataclass
class NoTension:
    """Single-arm cutting: no grasp; only the corner clips hold the sheet."""

    name: str = "none"

    def pinch_point(
        self, contour: Contour, config: SimConfig, device: str | None = None, seed: int = 0
    ) -> np.ndarray | None:
        return None

    def __call__(self, task: CuttingTask) -> np.ndarray | None:
        return None


@dataclass
class FixedTension:
    """Pinch a disc and hold it still.

    Attributes:
        pinch: Material point (mm) to pinch; ``None``: random search over ``candidates`` feasible points
            (plus the centroid when feasible), all simulated as one batch, keeping the best.
        candidates: Number of random feasible points the search tries (paper: 30).
    """

    pinch: tuple[float, float] | None = None
    candidates: int = PINCH_CANDIDATES
    name: str = "fixed"

    def pinch_point(
        self, contour: Contour, config: SimConfig, device: str | None = None, seed: int = 0
    ) -> np.ndarray:
        if self.pinch is not None:
            return np.asarray(self.pinch, dtype=np.float64)
        return search_fixed_pinch(contour, config, self.candidates, device=device, seed=seed)[0]

    def __call__(self, task: CuttingTask) -> np.ndarray | None:
        return None


@dataclass
class AnalyticTension:
    """Pinch at the contour's centroid; each step move against the tracking error, the vector from the
    scissor tip to the contour point it is about to cut (where the sheet has carried it).

    Attributes:
        gain: Grasp move (mm) per mm of tracking error, per step. The paper's gain is 0.01 per unit of
            its simulator (4.8 units/mm, moves in mm), i.e. 0.048 mm/mm here.
        pinch: Override the centroid (mm).
        feasible: Without ``pinch``: when the centroid is not a feasible pinch point (e.g. on the cut line
            of a crescent), pinch at the feasible point nearest to it
            (:func:`warpcut.planning.default_pinch`); False: the centroid wherever it is. A cut plan's
            arm footprint is applied by the caller (:attr:`warpcut.planning.Plan.analytic_pinch`).
    """

    gain: float = 0.01 * AUTHORS_UNITS_PER_MM
    pinch: tuple[float, float] | None = None
    feasible: bool = True
    name: str = "analytic"

    def pinch_point(
        self, contour: Contour, config: SimConfig, device: str | None = None, seed: int = 0
    ) -> np.ndarray:
        if self.pinch is not None:
            return np.asarray(self.pinch, dtype=np.float64)
        if self.feasible:
            return default_pinch(contour, config)
        return np.asarray(contour.centroid, dtype=np.float64)

    def __call__(self, task: CuttingTask) -> np.ndarray:
        move = -self.gain * task.tracking_error()
        move[:, 2] = 0.0  # the gripper moves in the x-y plane (paper A4)
        return np.nan_to_num(move, nan=0.0)


def search_fixed_pinch(
    contour: Contour,
    config: SimConfig,
    candidates: int = PINCH_CANDIDATES,
    device: str | None = None,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random search for the best fixed pinch point, every candidate in one simulator batch.

    Returns:
        ``(best, points, errors)``: the best point (2,), all candidates (K, 2) and their errors (K,) in
        vertices.
    """
    return search_fixed_pinches([contour], config, candidates, device, seed)[0]


def search_fixed_pinches(
    contours: list[Contour],
    config: SimConfig,
    candidates: int = PINCH_CANDIDATES,
    device: str | None = None,
    seed: int = 0,
    arm: ArmModel = ArmModel(),
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """:func:`search_fixed_pinch` for several contours at once: all their candidates form one batch.

    Candidates are scored noise-free, so the search is deterministic for a seed; they are feasible with the
    cutting ``arm`` (:func:`warpcut.planning.pinch_candidates`).

    Raises:
        SimulationDiverged: A candidate's simulation diverged (its error is NaN, so no best could be told).
    """
    rng = np.random.default_rng(seed)
    points = [pinch_candidates(c, config, num=candidates, rng=rng, arm=arm) for c in contours]
    owners = [c for c, p in zip(contours, points, strict=True) for _ in range(len(p))]
    with batch_named(  # the task would name num_envs, a count nobody gave
        "fixed's pinch search (one env per candidate pinch point)",
        "give fixed a pinch point (simulate --pinch X,Y) and it searches none, or lower sim.resolution",
    ):
        task = CuttingTask(
            config.replace(noise_std=0.0), owners, pinch_points=np.vstack(points), device=device, seed=seed,
            arm=arm,
        )  # fmt: skip
    score = task.run(None)
    if score.diverged is not None and score.diverged.any():
        bad = sorted({owners[e].name for e in np.flatnonzero(score.diverged)})
        raise SimulationDiverged(
            f"simulation diverged in {int(score.diverged.sum())} of {len(owners)} fixed-pinch candidates "
            f"(of {', '.join(bad)}), scored noise-free: lower gravity or dt, or raise sweeps"
        )
    errors = np.split(score.error_vertices, np.cumsum([len(p) for p in points])[:-1])
    return [(p[int(np.argmin(e))], p, e) for p, e in zip(points, errors, strict=True)]
