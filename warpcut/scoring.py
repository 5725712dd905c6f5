"""Cut quality: the symmetric difference between the intended and the achieved region.

Both regions are compared in *material* coordinates, i.e. on the sheet's rest layout
(:attr:`SheetGrid.material`), so a cut is scored by which material ended up separated, however the
tensioned sheet was deformed while it was cut. Regions are sets of vertices; each vertex stands for an
``hx * hy`` cell, so a vertex count times :attr:`SheetGrid.vertex_area_mm2` is an area in mm^2.

* **Intended**: vertices whose rest position lies in the intended region (a shapely polygon: the inside
  of a closed contour, or the piece an open contour cuts off the sheet).
* **Achieved**: the material the cut actually separated from the sheet. The alive vertices are split into
  pieces by 4-connectivity; the piece holding the most alive vertices *outside* the intended region is the
  sheet and every other alive vertex is separated. Removed vertices (the kerf) take the label of their
  nearest alive vertex, so the achieved region's boundary runs along the centre line of the cut.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from scipy import ndimage

from warpcut.config import SheetGrid

Region = shapely.Polygon | shapely.MultiPolygon


@dataclass
class Score:
    """Per-env cut error; ``B`` envs on a grid of ``V = ny * nx`` vertices."""

    error_vertices: np.ndarray
    """(B,) float64: vertices in exactly one of the intended and achieved regions."""
    error_mm2: np.ndarray
    """(B,) float64: ``error_vertices * grid.vertex_area_mm2`` (mm^2)."""
    missed_vertices: np.ndarray
    """(B,) float64: vertices intended but not separated."""
    excess_vertices: np.ndarray
    """(B,) float64: vertices separated but not intended."""
    achieved: np.ndarray
    """(B, V) bool: vertices separated from the sheet."""
    intended: np.ndarray
    """(V,) bool for one region shared by all envs, or (B, V) bool for one region per env."""


def intended_mask(region: Region, grid: SheetGrid) -> np.ndarray:
    """Vertices whose rest position lies in ``region`` (boundary included).

    Args:
        region: Intended region in material coordinates (mm), a shapely ``Polygon`` or ``MultiPolygon``.
        grid: The sheet's rest layout.

    Returns:
        (ny * nx,) bool mask.

    Raises:
        TypeError: ``region`` is not polygonal.
    """
    if not isinstance(region, Region):
        raise TypeError(f"region: expected a shapely Polygon or MultiPolygon, got {type(region).__name__}")
    # An open contour's region is bounded by the sheet's edges, where whole rows and columns of vertices
    # lie exactly on the boundary; a tolerance far below the spacing keeps them in despite round-off.
    tolerance = 1e-9 * min(grid.spacing_mm)
    x, y = grid.material.T
    return shapely.intersects_xy(region.buffer(tolerance), x, y)


def achieved_mask(alive: np.ndarray, intended: np.ndarray, grid: SheetGrid) -> np.ndarray:
    """Vertices the cut separated from the sheet, kerf included.

    Two alive vertices belong to the same piece when they are joined by a path of alive grid
    4-neighbours. Diagonal (shear) springs are ignored, which assumes the cut radius is at least one
    spacing ``h`` (the default): two diagonal neighbours fall into different pieces only if the scissor
    path crossed the segment between them, and every point of that segment lies within ``h / sqrt(2)`` of
    one of them, so one of the two was removed and their spring is gone with it.

    The sheet is the piece with the most alive vertices outside the intended region (ties: the larger
    piece, then the one whose first vertex comes first in ``v = row * nx + col`` order); every other alive
    vertex is separated. Each removed vertex takes the label of its nearest alive vertex in rest-position
    distance (physical spacings ``hx``, ``hy``; ties are broken by scipy's Euclidean distance transform).
    An env with no alive vertex has separated nothing.

    Args:
        alive: (B, ny * nx) or (ny * nx,) bool; False where the scissors removed the vertex.
        intended: (ny * nx,) bool shared by all envs, or (B, ny * nx) bool, from :func:`intended_mask`.
        grid: The sheet's rest layout.

    Returns:
        (B, ny * nx) bool; ``B = 1`` for a 1-D ``alive``.

    Raises:
        ValueError: ``alive`` or ``intended`` has the wrong shape.
    """
    alive = _batch_mask(alive, "alive", grid)
    outside = ~np.broadcast_to(_batch_mask(intended, "intended", grid, alive.shape[0]), alive.shape)
    hx, hy = grid.spacing_mm
    achieved = np.zeros(alive.shape, dtype=bool)
    for env, (env_alive, env_outside) in enumerate(zip(alive, outside, strict=True)):
        if not env_alive.any():
            continue
        pieces, count = ndimage.label(env_alive.reshape(grid.ny, grid.nx))
        pieces = pieces.ravel()
        size = np.bincount(pieces, minlength=count + 1)[1:]
        size_outside = np.bincount(pieces[env_outside], minlength=count + 1)[1:]
        # size <= V, so this key orders by size_outside first and size second; argmax takes the first
        # (lowest) label among equal keys.
        sheet = 1 + np.argmax(size_outside * (grid.num_vertices + 1) + size)
        separated = (env_alive & (pieces != sheet)).reshape(grid.ny, grid.nx)
        nearest_alive = ndimage.distance_transform_edt(
            ~env_alive.reshape(grid.ny, grid.nx),
            sampling=(hy, hx),
            return_distances=False,
            return_indices=True,
        )
        achieved[env] = separated[nearest_alive[0], nearest_alive[1]].ravel()
    return achieved


def symmetric_difference(
    alive: np.ndarray, region_or_regions: Region | Sequence[Region], grid: SheetGrid
) -> Score:
    """Score a batch of cuts against the intended region(s).

    Args:
        alive: (B, ny * nx) or (ny * nx,) bool; False where the scissors removed the vertex.
        region_or_regions: The intended region in material coordinates (mm), one polygon for all envs or
            a sequence of ``B`` polygons, one per env.
        grid: The sheet's rest layout.

    Returns:
        The :class:`Score` of each env (``B = 1`` for a 1-D ``alive``).

    Raises:
        ValueError: ``alive`` has the wrong shape, or the number of regions is not ``B``.
        TypeError: A region is not polygonal.
    """
    alive = _batch_mask(alive, "alive", grid)
    if isinstance(region_or_regions, shapely.Geometry):
        intended = intended_mask(region_or_regions, grid)
    else:
        regions = list(region_or_regions)
        if len(regions) != alive.shape[0]:
            raise ValueError(
                f"region_or_regions: got {len(regions)} regions for {alive.shape[0]} envs; "
                "give one polygon for all envs or one per env"
            )
        intended = np.stack([intended_mask(region, grid) for region in regions])
    achieved = achieved_mask(alive, intended, grid)
    missed = (intended & ~achieved).sum(axis=1).astype(np.float64)
    excess = (achieved & ~intended).sum(axis=1).astype(np.float64)
    error = missed + excess
    return Score(
        error_vertices=error,
        error_mm2=error * grid.vertex_area_mm2,
        missed_vertices=missed,
        excess_vertices=excess,
        achieved=achieved,
        intended=intended,
    )


def improvement_pct(e_none: np.ndarray | float, e_method: np.ndarray | float) -> np.ndarray | float:
    """Relative error reduction of a tensioning method over cutting without tensioning (%).

    Args:
        e_none: Error without tensioning (any unit, > 0), scalar or array.
        e_method: Error with the method, in the same unit, broadcastable against ``e_none``.

    Returns:
        ``100 * (e_none - e_method) / e_none``: 100 for a perfect cut, 0 for no gain, negative when the
        method does worse.

    Raises:
        ValueError: Some ``e_none`` is not > 0 (the improvement is undefined).
    """
    e_none = np.asarray(e_none, dtype=np.float64)
    e_method = np.asarray(e_method, dtype=np.float64)
    if not np.all(e_none > 0):
        raise ValueError(
            f"e_none: the error without tensioning must be > 0 to measure an improvement over it "
            f"(got min {np.min(e_none)})"
        )
    return 100.0 * (e_none - e_method) / e_none


def _batch_mask(mask: np.ndarray, name: str, grid: SheetGrid, batch: int | None = None) -> np.ndarray:
    """``mask`` as a (B, V) bool array, (1, V) for a 1-D mask; with ``batch`` given, B must be 1 or it."""
    mask = np.asarray(mask, dtype=bool)
    batched = mask[None] if mask.ndim == 1 else mask
    num_vertices = grid.num_vertices
    if (
        batched.ndim != 2
        or batched.shape[1] != num_vertices
        or (batch is not None and batched.shape[0] not in (1, batch))
    ):
        envs = "B" if batch is None else str(batch)
        raise ValueError(
            f"{name}: expected shape ({envs}, {num_vertices}) or ({num_vertices},) for a "
            f"{grid.ny} x {grid.nx} grid (ny x nx), got {mask.shape}"
        )
    return batched
