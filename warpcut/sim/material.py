"""Material points on the sheet: the grid cell holding each, and their world positions by bilinear
interpolation over it (the scissors' targets, the intended contour in recordings, the fiducials).

Plain NumPy: imported where Warp is not (the recorder process).
"""

from __future__ import annotations

import numpy as np

from warpcut.sim.config import SheetGrid


def material_cells(points: np.ndarray, grid: SheetGrid) -> tuple[np.ndarray, np.ndarray]:
    """The grid cell holding each material point, for bilinear interpolation.

    Args:
        points: (..., 2) material coordinates (mm); clipped onto the sheet.
        grid: The sheet's rest layout.

    Returns:
        ``(vertices, weights)``: (..., 4) indices of the cell's corner vertices and their (..., 4)
        bilinear weights.
    """
    points = np.asarray(points, dtype=np.float64)
    hx, hy = grid.spacing_mm
    u = np.clip(points[..., 0] / hx, 0.0, grid.nx - 1 - 1e-9)
    v = np.clip(points[..., 1] / hy, 0.0, grid.ny - 1 - 1e-9)
    col, row = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
    fu, fv = u - col, v - row
    corner = row * grid.nx + col
    vertices = np.stack([corner, corner + 1, corner + grid.nx, corner + grid.nx + 1], axis=-1)
    weights = np.stack([(1 - fu) * (1 - fv), fu * (1 - fv), (1 - fu) * fv, fu * fv], axis=-1)
    return vertices, weights


def interpolate(positions: np.ndarray, vertices: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """World positions (B, K, 3) of material points whose cells are ``vertices``/``weights`` (B, K, 4)
    on sheets at ``positions`` (B, N, 3)."""
    corners = np.take_along_axis(positions[:, None], vertices[..., None], axis=2)  # (B, K, 4, 3)
    return interpolate_corners(corners, weights)


def interpolate_corners(corners: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """World positions (B, K, 3) of material points from their cells' corner positions (B, K, 4, 3) (e.g.
    :meth:`warpcut.Simulator.gather` of the ``vertices`` of :func:`material_cells`) and ``weights``.

    Each corner's weighted position, summed in pairs: ``(p0 + p1) + (p2 + p3)``. That is the order of the
    batched (1 x 4) @ (4 x 3) product NumPy computed here before (OpenBLAS's, bit for bit on this machine),
    written out so that it does not depend on a BLAS build, and the order of the ``simd`` backend's kernel
    (:meth:`warpcut.Simulator.interpolator`), which the envs' observations use: the same bits either way."""
    products = weights[..., :, None] * corners
    return (products[..., 0, :] + products[..., 1, :]) + (products[..., 2, :] + products[..., 3, :])


def interpolate_state(state: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(world, whole)`` from the state (B, K, 4, 4) of material points' cell corners (x, y, z in mm and
    alive, non-zero where uncut; e.g. ``Simulator.gather`` of their cells, reshaped) and ``weights``: the
    points' world positions (B, K, 3) (:func:`interpolate_corners`) and whether each cell is whole (B, K)."""
    return interpolate_corners(state[..., :3], weights), (state[..., 3] != 0).all(axis=-1)


def material_to_world(points: np.ndarray, positions: np.ndarray, grid: SheetGrid) -> np.ndarray:
    """World positions of material points on one sheet, by bilinear interpolation over their cells.

    Args:
        points: (M, 2) material coordinates (mm).
        positions: (N, 3) vertex positions of one sheet (mm).
        grid: The sheet's rest layout.

    Returns:
        (M, 3) world positions (mm).
    """
    vertices, weights = material_cells(points, grid)
    return interpolate(np.asarray(positions, dtype=np.float64)[None], vertices[None], weights[None])[0]
