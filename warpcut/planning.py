"""Where the gripper may pinch: the feasible region for pinch points."""

from __future__ import annotations

import numpy as np
import shapely

from warpcut.config import SheetGrid, SimConfig
from warpcut.contours import Contour

CORNER_MARGIN_MM = 15.0
"""Pinch points stay this far from a corner clip (mm): the clip and the gripper would collide."""


def pinch_feasible(points: np.ndarray, contour: Contour, config: SimConfig) -> np.ndarray:
    """Which material points (M, 2) are feasible pinch points for cutting ``contour``.

    Feasible = on the sheet at least one grasp radius from its edges, at least
    :data:`CORNER_MARGIN_MM` from the corners, not on fixture vertices, and far enough from the contour
    that the gripped disc never reaches the scissors' cut (grasp radius + cut radius).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    w, h = config.width_mm, config.height_mm
    edge = config.grasp_radius
    ok = (
        (points[:, 0] >= edge)
        & (points[:, 0] <= w - edge)
        & (points[:, 1] >= edge)
        & (points[:, 1] <= h - edge)
    )
    corners = np.array([[0.0, 0.0], [w, 0.0], [0.0, h], [w, h]])
    ok &= np.min(np.linalg.norm(points[:, None] - corners[None], axis=2), axis=1) >= CORNER_MARGIN_MM
    grid = SheetGrid.from_config(config)
    fixed = grid.material[grid.fixture_mask(config.fixture)]
    ok &= np.min(np.linalg.norm(points[:, None] - fixed[None], axis=2), axis=1) > config.grasp_radius
    line = shapely.LinearRing(contour.points) if contour.closed else shapely.LineString(contour.points)
    clearance = config.grasp_radius + config.cut_radius
    ok &= shapely.distance(shapely.points(points), line) >= clearance
    return ok


def sample_pinch_candidates(
    contour: Contour,
    config: SimConfig,
    num: int = 30,
    rng: np.random.Generator | None = None,
    include_centroid: bool = True,
) -> np.ndarray:
    """``num`` feasible pinch points drawn uniformly (rejection sampling), plus the contour's centroid
    first when it is feasible (the paper's candidate set). Returns (K, 2) material mm."""
    rng = rng if rng is not None else np.random.default_rng(0)
    chosen: list[np.ndarray] = []
    if include_centroid and pinch_feasible(contour.centroid, contour, config)[0]:
        chosen.append(np.asarray(contour.centroid, dtype=np.float64))
    need = num
    for _ in range(100):
        if need <= 0:
            break
        draws = rng.uniform([0.0, 0.0], [config.width_mm, config.height_mm], size=(max(4 * need, 64), 2))
        good = draws[pinch_feasible(draws, contour, config)][:need]
        chosen.extend(good)
        need -= len(good)
    if not chosen:
        raise ValueError(
            f"contour {contour.name!r}: no feasible pinch point on the sheet; the contour leaves "
            "no room for the gripper (give --pinch explicitly)"
        )
    return np.asarray(chosen)


def nearest_feasible(point: np.ndarray, contour: Contour, config: SimConfig) -> np.ndarray:
    """The feasible grid of 0.5 mm points' member nearest to ``point`` (the point itself if feasible)."""
    point = np.asarray(point, dtype=np.float64)
    if pinch_feasible(point, contour, config)[0]:
        return point
    xs = np.arange(0.0, config.width_mm + 1e-9, 0.5)
    ys = np.arange(0.0, config.height_mm + 1e-9, 0.5)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    grid = grid[pinch_feasible(grid, contour, config)]
    if not len(grid):
        raise ValueError(f"contour {contour.name!r}: no feasible pinch point on the sheet")
    return grid[np.argmin(np.linalg.norm(grid - point, axis=1))]
