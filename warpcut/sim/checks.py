"""Checks of a simulator's inputs and of its settled sheets, with messages that name the field and the fix."""

from __future__ import annotations

from typing import Any

import numpy as np

from warpcut.sim.config import SETTLED_REACH_SHEETS, SimConfig, SimulationDiverged
from warpcut.validation import fail


def check_pinch_points(points: np.ndarray) -> None:
    """Raise ``ValueError`` naming the env unless each row of the (B, 2) ``points`` is finite or all NaN
    (no grasp): an infinite or half-NaN pinch point is a mistake, never a silent "no grasp"."""
    finite = np.isfinite(points)
    bad = ~(finite.all(axis=1) | np.isnan(points).all(axis=1))
    if bad.any():
        env = int(np.argmax(bad))
        raise ValueError(
            f"pinch_points: env {env}'s pinch point {points[env].tolist()} is not finite; give material "
            "coordinates (mm), or a row of NaN (None for all envs) for no grasp"
        )


def checked_pinch_points(pinch_points: Any, num_envs: int, width_mm: float, height_mm: float) -> np.ndarray:
    """``CuttingTask``'s ``pinch_points`` as a (B, 2) float array: one (x, y) for every env or one per env,
    finite (:func:`check_pinch_points`) and on the ``width_mm`` x ``height_mm`` sheet; None: no grasp (rows of
    NaN). Anything else: a ``ValueError`` naming ``pinch_points`` and the fix."""
    if pinch_points is None:
        return np.full((num_envs, 2), np.nan)
    raw = np.asarray(pinch_points) if not isinstance(pinch_points, str) else None
    if raw is None or raw.dtype.kind not in "iuf":  # a text, bools, objects: not coordinates
        fail("CuttingTask.pinch_points", "numbers: (x, y) in mm, or one (x, y) per env", pinch_points)
    points = raw.astype(np.float64)
    if points.shape == (2,):
        if not np.all(np.isfinite(points)):
            raise ValueError(
                f"pinch_points: the pinch point {points.tolist()} is not finite; give material "
                "coordinates (mm), or None for no grasp"
            )
        points = np.broadcast_to(points, (num_envs, 2)).copy()
    if points.shape != (num_envs, 2):
        raise ValueError(f"CuttingTask.pinch_points: expected (2,) or ({num_envs}, 2), got {points.shape}")
    check_pinch_points(points)
    w, h = width_mm, height_mm
    given = np.all(np.isfinite(points), axis=1)
    off = given & ((points[:, 0] < 0) | (points[:, 0] > w) | (points[:, 1] < 0) | (points[:, 1] > h))
    if off.any():
        raise ValueError(
            f"pinch_points: {points[off][0].tolist()} lies off the {w:g} x {h:g} mm sheet; "
            "give material coordinates on the sheet"
        )
    return points


DIVERGENCE_REASONS = {
    1: "non-finite vertex positions",
    2: "vertices flung far from the sheet",
}
"""What :meth:`Simulator.divergence` codes mean, in words."""


def check_settled(settled: np.ndarray, divergence: np.ndarray, group_params: np.ndarray, config: SimConfig):
    """Raise :class:`SimulationDiverged` if a settled sheet (G, N, 3), one per parameter group, diverged
    or hangs farther than :data:`SETTLED_REACH_SHEETS` sheet sizes from its rest outline."""
    size = max(config.width_mm, config.height_mm)
    rest_high = np.array([config.width_mm, config.height_mm, 0.0])
    with np.errstate(invalid="ignore"):
        outside = np.maximum(-settled, 0.0) + np.maximum(settled - rest_high, 0.0)
        reach = np.linalg.norm(outside, axis=-1).max(axis=1)
    bad = (divergence != 0) | ~np.isfinite(reach) | (reach > SETTLED_REACH_SHEETS * size)
    if not bad.any():
        return
    g = int(np.argmax(bad))
    default = SimConfig()
    damping, dt, gravity, elasticity = (float(v) for v in group_params[g])
    if divergence[g] == 1 or not np.isfinite(reach[g]):
        what = "its vertex positions became non-finite"
    else:
        what = f"it hangs {reach[g]:.3g} mm from its rest outline, more than its size ({size:g} mm)"
    raise SimulationDiverged(
        f"simulation diverged while settling the sheet (gravity {gravity:g} mm/s^2, dt {dt:g} s, damping "
        f"{damping:g}, elasticity {elasticity:g}): {what}, the springs cannot hold a fall of "
        f"gravity * dt^2 = {gravity * dt * dt:.3g} mm per update; lower gravity or dt (defaults "
        f"{default.gravity:g} mm/s^2 and {default.dt:g} s: {default.gravity * default.dt**2:.2g} mm per "
        "update), or raise sweeps"
    )


def settled_figures(sim) -> tuple[float, float, float]:
    """The settled sheet of env 0 in the figures docs/physics.md compares: the sag at the centre vertex
    (mm, below the rest plane) and the largest and mean relative stretch of the structural springs (%)."""
    grid = sim.grid
    p = sim.settled_positions()[0].reshape(grid.ny, grid.nx, 3)
    hx, hy = grid.spacing_mm
    stretch = np.concatenate(
        [
            (np.linalg.norm(p[:, 1:] - p[:, :-1], axis=-1) / hx - 1).ravel(),
            (np.linalg.norm(p[1:] - p[:-1], axis=-1) / hy - 1).ravel(),
        ]
    )
    centre = p[grid.ny // 2, grid.nx // 2]
    return float(-centre[2]), float(100 * stretch.max()), float(100 * stretch.mean())
