"""What a pattern-cutting policy observes: time, grasp displacement, fiducials, optional contour features
and pinch point.

The layout of one env's observation (float32, ``D = 4 + 3 * num_fiducials [+ 7] [+ 2]``):

=================  =====  =====================================================================  ==========
slice              size   quantity                                                               bounds
=================  =====  =====================================================================  ==========
``[0]``            1      time index ``step / num_steps`` (progress of the whole cut)           [0, 1]
``[1:4]``          3      grasp displacement / ``max_displacement_mm``                          [-1, 1]
``[4:4+3K]``       3K     fiducial ``k`` at ``[4+3k : 7+3k]``: world position, normalised       [-2, 2]
``[4+3K:7+3K]``    3      (``contour_features``) scissor tip position, normalised               [-2, 2]
``[7+3K]``         1      (``contour_features``) 1 while the tip cuts, 0 while it travels       [0, 1]
``[8+3K:11+3K]``   3      (``contour_features``) tracking error / ``max_displacement_mm``       [-5, 5]
last 2             2      (``observe_pinch``) the pinch point (material x, y), normalised       [-1, 1]
=================  =====  =====================================================================  ==========

*Normalised* positions are ``(p - (W/2, H/2, 0)) / (max(W, H) / 2)``: the sheet at rest spans [-1, 1] in
x and y, and its ~15 mm sag is about -0.3 in z. The tracking error is ``target_world() - tip``, the vector
from the next scissor position to where the sheet has carried the contour point it is about to cut (what
:class:`agents.baselines.AnalyticTension` opposes); zero while the tip travels or once the cut is done.
Every entry is clipped to its bounds, so observations always lie in the observation space (only a
piece that has been cut free and falls ever reaches the position bounds, 100 mm from the sheet centre).

Fiducials are material points, drawn at random, whose world position is read by bilinear interpolation
over their grid cell, as a camera tracks markers on the gauze. A fiducial is *hidden* when its cell has
lost a vertex to the scissors, or when it lies under the cutting arm's shaft: a cylinder of radius
``shaft_radius_mm`` from the scissor tip toward +x (``x > tip_x`` and distance to the line
``{y = tip_y, z = tip_z}`` below the radius). A hidden fiducial reports its last visible position; at reset
every fiducial reports its position on the settled sheet.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely

from warpcut.config import SheetGrid, SimConfig
from warpcut.contours import Contour
from warpcut.task import interpolate, material_cells

POSITION_LIMIT = 2.0
"""Bound on normalised positions (fiducials, tip): 100 mm from the sheet centre on a 100 mm sheet."""
TRACKING_LIMIT = 5.0
"""Bound on the normalised tracking error: 50 mm at the default ``max_displacement_mm`` of 10 mm."""


def observation_bounds(
    num_fiducials: int, contour_features: bool, observe_pinch: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """``(low, high)`` float32 bounds of one env's observation, in the layout of the module docstring."""
    low = [0.0, -1.0, -1.0, -1.0] + [-POSITION_LIMIT] * (3 * num_fiducials)
    high = [1.0, 1.0, 1.0, 1.0] + [POSITION_LIMIT] * (3 * num_fiducials)
    if contour_features:
        low += [-POSITION_LIMIT] * 3 + [0.0] + [-TRACKING_LIMIT] * 3
        high += [POSITION_LIMIT] * 3 + [1.0] + [TRACKING_LIMIT] * 3
    if observe_pinch:
        low += [-1.0, -1.0]
        high += [1.0, 1.0]
    return np.array(low, dtype=np.float32), np.array(high, dtype=np.float32)


def normalise_positions(points: np.ndarray, config: SimConfig) -> np.ndarray:
    """World positions (..., 3) in mm to the observation's unit scale (see the module docstring)."""
    centre = np.array([config.width_mm / 2, config.height_mm / 2, 0.0])
    return (points - centre) / (max(config.width_mm, config.height_mm) / 2)


def sample_fiducials(
    rng: np.random.Generator,
    num: int,
    contours: Sequence[Contour],
    pinch_points: np.ndarray,
    config: SimConfig,
) -> np.ndarray:
    """``num`` random material points per env, preferably where they stay informative.

    Points are drawn uniformly over the sheet; those at least one cut radius from the env's contour (away
    from the kerf) and outside its grasp disc (which moves rigidly with the gripper) are taken first, and
    only if too few are found are the others used.

    Args:
        rng: Random source.
        num: Fiducials per env.
        contours: (B,) each env's contour.
        pinch_points: (B, 2) each env's pinch point (mm); NaN rows for no grasp.
        config: Simulation parameters (sheet size, cut and grasp radii).

    Returns:
        (B, num, 2) material coordinates (mm).
    """
    num_envs = len(contours)
    draws = rng.uniform([0.0, 0.0], [config.width_mm, config.height_mm], size=(num_envs, 16 * num, 2))
    preferred = np.ones(draws.shape[:2], dtype=bool)
    for contour in {id(c): c for c in contours}.values():
        envs = np.array([c is contour for c in contours])
        line = shapely.LinearRing(contour.points) if contour.closed else shapely.LineString(contour.points)
        distance = shapely.distance(shapely.points(draws[envs].reshape(-1, 2)), line).reshape(-1, 16 * num)
        preferred[envs] = distance >= config.cut_radius
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
        world = self.world(positions)
        uncut = np.all(np.take_along_axis(alive[:, None], self._cells[0], axis=2), axis=2)
        off_axis = np.linalg.norm(world[..., 1:] - tip[:, None, 1:3], axis=2)
        shaded = (world[..., 0] > tip[:, None, 0]) & (off_axis < self.shaft_radius_mm)
        self.visible = uncut & ~shaded
        self.last_visible = np.where(self.visible[..., None], world, self.last_visible)
        return self.last_visible.copy()
