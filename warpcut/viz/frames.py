"""What a recorder's step callback copies out of a task: per recorded step a :class:`Frame`, and when an
episode starts a :class:`TaskSetup` of what its frames are drawn with. Both travel unchanged to the writer,
in this process or through the pipe to the recorder process."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from warpcut.contours import Contour
from warpcut.sim.config import SheetGrid, SimConfig


@dataclass
class Frame:
    """The recorded envs' state after one step."""

    step: int
    update: int
    state: np.ndarray
    """(n, V, 4) float32: positions (mm) and alive (1.0, or 0.0 where cut), as
    :meth:`~warpcut.sim.simulator.Simulator.read_state` copies them."""
    displacements: np.ndarray | None
    """(n, 3) float64, None when no recorded env is grasped."""
    action: np.ndarray | None
    """(n, 3) float64, or None at the reset and for policies that return no moves."""
    path_start: int = 0
    """The first update of ``path``."""
    path: np.ndarray | None = None
    """(n, U, 3) float32: the traced cut path (material x, y, status) of updates ``path_start ..
    path_start + U - 1``, those since the previous frame; None where the task does not trace it."""


@dataclass
class EnvSetup:
    """One recorded env of one task, copied when the episode starts (so that the writer never reads a task
    that the caller goes on changing)."""

    env: int
    contour: Contour
    tip: np.ndarray
    """(T, 4) the scissor trajectory."""
    pinch: np.ndarray
    disc: np.ndarray | None
    """(V,) bool grasped vertices, None without a grasp."""
    step_s: float
    """Simulated seconds per env step."""
    fiducials: np.ndarray | None
    """(K, 2) material points of the env's fiducials; None: the writer draws them."""
    shaft_radius_mm: float
    """The cutting arm's shaft radius, which hides the fiducials under it (mm)."""
    arc: np.ndarray | None = None
    """(T,) arc length along the contour of the point each update meant to cut (the path's order); None
    where the task does not trace the cut path."""


@dataclass
class TaskSetup:
    """What every recorded env of one task shares, and the envs."""

    grid: SheetGrid
    config: SimConfig
    envs: list[EnvSetup]
