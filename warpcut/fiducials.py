"""Fiducials: material points of the gauze that a camera tracks, as the paper's policy observes them.

Fiducials are material points, drawn at random, whose world position is read by bilinear interpolation
over their grid cell, as a camera tracks markers on the gauze. A fiducial is *hidden* when its cell has
lost a vertex to the scissors, or when it lies under the cutting arm's shaft: a cylinder of radius
``shaft_radius_mm`` from the scissor tip toward +x (``x > tip_x`` and distance to the line
``{y = tip_y, z = tip_z}`` below the radius). A hidden fiducial reports its last visible position; at reset
every fiducial reports its position on the settled sheet.

The envs (:mod:`envs.observations`) observe them; recordings (:mod:`warpcut.viz.rerun_writer`) show them,
visible or hidden, with the same rule (:func:`visible`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely

from warpcut.contours import Contour
from warpcut.sim.config import SheetGrid, SimConfig
from warpcut.sim.material import interpolate, interpolate_state, material_cells

NUM_FIDUCIALS = 12
"""Fiducials per sheet (the paper's 12)."""

SHAFT_RADIUS_MM = 5.0
"""Radius of the cutting arm's shaft, which hides the fiducials under it (mm)."""


def visible(
    world: np.ndarray, alive: np.ndarray, cells: np.ndarray, tip: np.ndarray, shaft_radius_mm: float
) -> np.ndarray:
    """Which fiducials a camera sees: their cell keeps all its vertices and the shaft does not cover them.

    Args:
        world: (B, K, 3) fiducial world positions (mm); B sheets (or frames of one sheet).
        alive: (B, N) bool, False where the scissors removed the vertex.
        cells: (B, K, 4) (or (1, K, 4)) vertex indices of each fiducial's cell (:func:`material_cells`).
        tip: (B, 3 or 4) scissor tip (mm); the shaft runs from it toward +x.
        shaft_radius_mm: Radius of the shaft (mm).

    Returns:
        (B, K) bool.
    """
    cells = np.broadcast_to(cells, world.shape[:2] + (4,))
    return visible_corners(world, np.take_along_axis(alive[:, None], cells, axis=2), tip, shaft_radius_mm)


def visible_corners(
    world: np.ndarray, corner_alive: np.ndarray, tip: np.ndarray, shaft_radius_mm: float
) -> np.ndarray:
    """:func:`visible` from each fiducial's cell corners' alive flags ``corner_alive`` (B, K, 4) (non-zero
    where uncut) instead of the whole sheet's: the cell is whole and the shaft (a cylinder of radius
    ``shaft_radius_mm`` from each ``tip`` toward +x) does not cover the point."""
    # Written out component by component (the values of np.linalg.norm and np.all over the last axis, bit
    # for bit, in a third of their time: the envs observe this every step).
    whole = corner_alive[..., 0] != 0
    for corner in range(1, corner_alive.shape[-1]):
        whole &= corner_alive[..., corner] != 0
    return visible_cells(world, whole, tip, shaft_radius_mm)


def visible_cells(
    world: np.ndarray, whole: np.ndarray, tip: np.ndarray, shaft_radius_mm: float
) -> np.ndarray:
    """:func:`visible` from whether each fiducial's cell is whole, ``whole`` (B, K) bool, instead of the
    sheet's alive flags (e.g. from :meth:`warpcut.Simulator.interpolator`)."""
    dy, dz = world[..., 1] - tip[:, None, 1], world[..., 2] - tip[:, None, 2]
    shaded = (world[..., 0] > tip[:, None, 0]) & (np.sqrt(dy * dy + dz * dz) < shaft_radius_mm)
    return whole & ~shaded


def sample_fiducials(
    rng: np.random.Generator,
    num: int,
    contours: Sequence[Contour],
    pinch_points: np.ndarray,
    config: SimConfig,
    part: tuple[int, int] | None = None,
) -> np.ndarray:
    """``num`` random material points per env, preferably where they stay informative.

    Points are drawn uniformly over the sheet; those farther than one cut radius from the env's contour (away
    from the kerf) and outside its grasp disc (which moves rigidly with the gripper) are taken first, and
    only if too few are found are the others used.

    Args:
        rng: Random source.
        num: Fiducials per env.
        contours: (B,) each env's contour.
        pinch_points: (B, 2) each env's pinch point (mm); NaN rows for no grasp.
        config: Simulation parameters (sheet size, cut and grasp radii).
        part: ``(first, total)``: the envs are ``first, first + 1, ...`` of a batch of ``total``, and draw
            what those envs of the whole batch draw from the same ``rng``.

    Returns:
        (B, num, 2) material coordinates (mm).
    """
    num_envs = len(contours)
    first, total = part or (0, num_envs)
    draws = rng.uniform([0.0, 0.0], [config.width_mm, config.height_mm], size=(total, 16 * num, 2))
    draws = draws[first : first + num_envs]
    preferred = np.ones(draws.shape[:2], dtype=bool)
    for contour in {id(c): c for c in contours}.values():
        envs = np.array([c is contour for c in contours])
        line = shapely.LinearRing(contour.points) if contour.closed else shapely.LineString(contour.points)
        shapely.prepare(line)  # within the cut radius: 4x faster than the distances themselves
        near = shapely.dwithin(shapely.points(draws[envs].reshape(-1, 2)), line, config.cut_radius)
        preferred[envs] = ~near.reshape(-1, 16 * num)
    with np.errstate(invalid="ignore"):  # NaN pinch points (no grasp) exclude nothing
        preferred &= ~(np.linalg.norm(draws - pinch_points[:, None], axis=2) <= config.grasp_radius)
    order = np.argsort(~preferred, axis=1, kind="stable")[:, :num]
    return np.take_along_axis(draws, order[:, :, None], axis=1)


class Fiducials:
    """Material points tracked on every sheet of a batch, with occlusion and cut-away (module docstring).

    Args:
        grid: The sheet's rest layout.
        shaft_radius_mm: Radius of the cutting arm's shaft, a cylinder from the tip toward +x (mm).

    Attributes:
        material: (B, K, 2) material coordinates (mm); set by :func:`sample_fiducials` or by hand, then call
            :meth:`reset`.
        last_visible: (B, K, 3) world position (mm) each fiducial was last seen at.
        visible: (B, K) bool, whether each fiducial was seen at the last :meth:`track`.
    """

    def __init__(self, grid: SheetGrid, shaft_radius_mm: float):
        self.grid = grid
        self.shaft_radius_mm = shaft_radius_mm
        self.material = np.zeros((0, 0, 2))
        self.last_visible = np.zeros((0, 0, 3))
        self.visible = np.zeros((0, 0), dtype=bool)
        self._cells = (np.zeros((0, 0, 4), dtype=np.int64), np.zeros((0, 0, 4)))

    def world(self, positions: np.ndarray) -> np.ndarray:
        """(B, K, 3) world positions (mm) of the fiducials on sheets at ``positions`` (B, N, 3)."""
        return interpolate(positions, *self._cells)

    def reset(self, positions: np.ndarray) -> None:
        """Start an episode: every fiducial is seen where it lies on sheets at ``positions`` (B, N, 3)."""
        self._cells = material_cells(self.material, self.grid)
        self.last_visible = self.world(positions)
        self.visible = np.ones(self.material.shape[:2], dtype=bool)

    def track(self, positions: np.ndarray, alive: np.ndarray, tip: np.ndarray) -> np.ndarray:
        """See the fiducials that are visible now; return every fiducial's last visible position.

        Args:
            positions: (B, N, 3) vertex positions (mm).
            alive: (B, N) bool, False where the scissors removed the vertex.
            tip: (B, 3 or 4) scissor tip (mm); the shaft runs from it toward +x.

        Returns:
            (B, K, 3) last visible world positions (mm), a copy.
        """
        corners = np.take_along_axis(positions[:, None], self._cells[0][..., None], axis=2)
        corner_alive = np.take_along_axis(alive[:, None], self._cells[0], axis=2)
        return self.track_corners(np.concatenate([corners, corner_alive[..., None]], axis=3), tip)

    @property
    def cells(self) -> tuple[np.ndarray, np.ndarray]:
        """``(vertices, weights)``, each (B, K, 4): every fiducial's cell (:func:`material_cells`), the same
        object until the next :meth:`reset`."""
        return self._cells

    @property
    def cell_vertices(self) -> np.ndarray:
        """(B, 4K) the corner vertices of every fiducial's cell, fiducial by fiducial: the vertices whose
        state :meth:`track_corners` takes (e.g. from :meth:`warpcut.Simulator.gather`)."""
        return self._cells[0].reshape(len(self._cells[0]), -1)

    def track_corners(self, state: np.ndarray, tip: np.ndarray) -> np.ndarray:
        """:meth:`track` from the state (B, K, 4, 4) of each fiducial's cell corners only: x, y, z (mm) and
        alive (non-zero where uncut); ``Simulator.gather(cell_vertices)`` reshaped."""
        return self.track_cells(*interpolate_state(state, self._cells[1]), tip)

    def track_cells(self, world: np.ndarray, whole: np.ndarray, tip: np.ndarray) -> np.ndarray:
        """:meth:`track` from the fiducials' world positions now (B, K, 3) and whether their cells are whole
        (B, K) bool: what ``Simulator.interpolator(*cells)`` reads (the envs' observations)."""
        self.visible = visible_cells(world, whole, tip, self.shaft_radius_mm)
        self.last_visible = np.where(self.visible[..., None], world, self.last_visible)
        return self.last_visible.copy()
