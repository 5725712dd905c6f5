"""The cut path a :class:`~warpcut.sim.simulator.Simulator` traces: after every cutting update, where the
scissor tip went through the material (its material point, found in the deformed mesh), for the path
score (docs/architecture.md, "Tracing the cut path")."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from warpcut.sim import kernels
from warpcut.sim._warp import launch, wp

if TYPE_CHECKING:
    from warpcut.sim.config import SheetGrid, SimConfig


class PathTracing:
    """The path-tracing methods of :class:`~warpcut.sim.simulator.Simulator`, which it inherits (one module
    per concern; the simulator's own module holds the stepping, which calls :meth:`_map_flat` after an
    update while :meth:`_tracing`). They read the simulator's env-major state (``x``, ``alive``, ``tip``)
    and write :attr:`path`."""

    num_envs: int
    device: str
    config: SimConfig
    grid: SheetGrid
    update_count: int
    x: wp.array
    alive: wp.array
    tip: wp.array
    _is_cpu: bool
    path: wp.array | None
    _removed_at: wp.array | None
    _search: kernels.TipSearch | None

    def trace_path(self, horizon: int | None) -> None:
        """Map the scissor tip of each of the first ``horizon`` updates after a reset into material (rest)
        coordinates, into :attr:`path`; ``None`` stops tracing.

        After every cutting update the tip is located in the deformed mesh (two triangles per grid cell,
        projected on x-y) and its material position interpolated barycentrically. A triangle may carry the
        tip while each of its vertices is alive or was cut within the last :attr:`path_window` updates: the
        tip always sits on freshly cut material, older cuts are holes. Where several layers lie under the
        tip, the one nearest it in height is taken. The cells around the previous update's material point
        are searched first, then :attr:`path_reach` cells around the tip's x-y read as a material point; a
        tip over no such triangle there (off the sheet, over a hole) is dropped. Updates with ``tape_mode``
        are not traced.
        """
        if horizon is None:
            self.path = self._removed_at = None
            return
        if not isinstance(horizon, int) or horizon < 1:
            raise ValueError(f"horizon: must be a positive number of updates (got {horizon!r})")
        b, n = self.num_envs, self.grid.num_vertices
        self._search = self.tip_search()
        self.path = wp.full(
            (b, horizon), wp.vec3(0.0, 0.0, kernels.PATH_IDLE), dtype=wp.vec3, device=self.device
        )
        self._removed_at = wp.full(b * n, -1, dtype=wp.int32, device=self.device)

    @property
    def path_window(self) -> int:
        """Updates for which a cut vertex still carries the tip: twice the tip's travel from first touching
        a cell's corner to leaving the cell (cut radius plus a cell diagonal)."""
        hx, hy = self.grid.spacing_mm
        reach_mm = self.config.cut_radius + math.hypot(hx, hy)
        return math.ceil(2.0 * reach_mm / self.config.trajectory_spacing_mm)

    @property
    def path_reach(self) -> int:
        """Cells around the tip searched first: the grasp's largest displacement plus the cut radius."""
        reach_mm = self.config.max_displacement_mm + self.config.cut_radius
        return math.ceil(reach_mm / min(self.grid.spacing_mm))

    def path_reader(self, count: int) -> Callable[[int, int], np.ndarray]:
        """A function ``read(start, stop)`` returning a copy of :attr:`path` of the first ``count`` envs for
        updates ``start .. stop - 1``, (count, stop - start, 3): what a recorder's step callback calls every
        step. On the CPU it copies out of a NumPy view made here, once (much cheaper than a Warp slice per
        call); elsewhere it copies only that slice to the host."""
        if self.path is None:
            raise ValueError("path_reader: the path is not traced; call trace_path(horizon) first")
        path = self.path
        if self._is_cpu:
            view = path.numpy()[:count]
            return lambda start, stop: view[:, start:stop].copy()
        return lambda start, stop: np.array(path[:count, start:stop].numpy())

    def tip_search(self) -> kernels.TipSearch:
        """What the tip search needs to know of the sheet (made once per :meth:`trace_path`)."""
        search = kernels.TipSearch()
        search.nx, search.ny = self.grid.nx, self.grid.ny
        search.hx, search.hy = (float(h) for h in self.grid.spacing_mm)
        search.window, search.reach = self.path_window, self.path_reach
        return search

    def _map_flat(self) -> None:
        """Trace every env's tip from the env-major state."""
        launch(
            kernels.map_tip_kernel,
            dim=self.num_envs,
            inputs=[
                self._search,
                self.update_count,
                self.x,
                self.alive,
                self.tip,
                self._removed_at,
            ],
            outputs=[self.path],
            device=self.device,
        )

    def _tracing(self) -> bool:
        return self.path is not None and self.update_count < self.path.shape[1]
