"""Plain NumPy implementation of the simulator's physics: the correctness oracle and the speed baseline.

It is written independently of the Warp kernels: springs are enumerated explicitly as index pairs per
colour (the kernels derive a vertex's partner from its grid position). All arithmetic is float32 in the
kernels' order of operations, so on the CPU the two agree bit for bit (a cut sheet amplifies any rounding
difference, Chebyshev sweeps more than plain ones: tests/test_reference.py). Process noise is not
reproduced (Warp's random stream is its own); compare the two noise-free.
"""

from __future__ import annotations

import numpy as np

from warpcut.sim.config import SheetGrid, SimConfig
from warpcut.sim.springs import colour_springs


class ReferenceSheet:
    """One sheet (no batch), stepped with NumPy: same update as :class:`warpcut.Simulator`.

    Args:
        config: Simulation parameters; per-env parameters must be single values.
        positions: (N, 3) starting positions (mm), e.g. ``Simulator.settled_positions()[env]``.
        pinch_point: Material coordinates (mm) of the pinch point, or ``None`` for no grasp.
    """

    def __init__(self, config: SimConfig, positions: np.ndarray, pinch_point: np.ndarray | None = None):
        self.config = config.validated()
        self.grid = SheetGrid.from_config(self.config)
        for name in ("damping", "dt", "gravity", "elasticity"):
            if np.size(getattr(self.config, name)) != 1:
                raise ValueError(f"{name}: the reference simulates one sheet; give a single value")
        if np.any(np.asarray(self.config.noise_std) != 0):
            raise ValueError(
                "noise_std: the reference is noise-free (Warp's random stream is its own); give 0"
            )
        self.damping = np.float32(np.ravel(self.config.damping)[0])
        dt = np.float32(np.ravel(self.config.dt)[0])
        self.gravity_step = np.float32(np.ravel(self.config.gravity)[0]) * dt * dt
        self.elasticity = np.float32(np.ravel(self.config.elasticity)[0])
        self.springs = colour_springs(self.grid, self.config.springs)
        self.x = np.asarray(positions, dtype=np.float32).reshape(-1, 3).copy()
        self.x_prev = self.x.copy()
        self.anchor = self.x.copy()
        self.alive = np.ones(self.grid.num_vertices, dtype=bool)
        self.fixed = self.grid.fixture_mask(self.config.fixture)
        self.grasp = np.zeros_like(self.fixed)
        if pinch_point is not None:
            self.grasp = self.grid.disc_mask(pinch_point, self.config.grasp_radius) & ~self.fixed
        self.displacement = np.zeros(3, dtype=np.float32)

    def move_grasp(self, action: np.ndarray) -> None:
        if not self.grasp.any():
            return
        limit = np.float32(self.config.max_step_mm)
        step = np.clip(np.asarray(action, dtype=np.float32), -limit, limit)
        u = self.displacement + step
        norm = np.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])  # float32, in the kernel's order
        cap = np.float32(self.config.max_displacement_mm)
        if norm > cap:
            u = u * (cap / norm)
        self.displacement = u.astype(np.float32)

    def update(self, tip: np.ndarray | None = None) -> None:
        """Integrate, relax, cut at ``tip = (x, y, z, cutting)`` (world mm) if given."""
        free = self.alive & ~self.fixed & ~self.grasp
        velocity = (self.x - self.x_prev) * self.damping
        if self.config.first_order_z:
            velocity[:, 2] = 0.0
        new = self.x.copy()
        new[free] = self.x[free] + velocity[free] - np.array([0, 0, self.gravity_step], dtype=np.float32)
        new[self.fixed] = self.anchor[self.fixed]
        new[self.grasp] = self.anchor[self.grasp] + self.displacement
        self.x_prev, self.x = self.x, new
        movable = self.alive & ~self.fixed & ~self.grasp
        older = [self.x.copy(), None]  # the positions two sweeps back, by sweep parity (Chebyshev)
        for k, weight in enumerate(self.config.sweep_weights, start=1):
            for starts, ends, rest in self.springs:
                self._relax(starts, ends, rest, movable)
            if self.config.chebyshev_rho > 0:
                if k > 1:
                    self.x = older[k % 2] + (self.x - older[k % 2]) * weight
                older[k % 2] = self.x.copy()
        if tip is not None and tip[3] > 0.5:
            d2 = (self.x[:, 0] - tip[0]) ** 2 + (self.x[:, 1] - tip[1]) ** 2
            hit = (d2 <= np.float32(self.config.cut_radius) ** 2) & (
                np.abs(self.x[:, 2] - tip[2]) <= self.config.cut_height
            )
            self.alive &= ~hit

    def _relax(self, starts: np.ndarray, ends: np.ndarray, rest: float, movable: np.ndarray) -> None:
        live = self.alive[starts] & self.alive[ends]
        a, b = starts[live], ends[live]
        d = self.x[b] - self.x[a]
        length = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])
        ok = length >= 1e-9
        a, b, d, length = a[ok], b[ok], d[ok], length[ok]
        ma, mb = movable[a], movable[b]
        # Each free end moves toward the other by its share (half, or all of it when the other is pinned),
        # in the kernels' float order (the Chebyshev extrapolation would amplify a difference in rounding).
        for ends_, toward, moves, other_moves in ((a, d, ma, mb), (b, -d, mb, ma)):
            share = np.where(other_moves, np.float32(0.5), np.float32(1.0))
            scale = self.elasticity * share * (length - np.float32(rest)) / length
            self.x[ends_[moves]] = self.x[ends_[moves]] + toward[moves] * scale[moves, None]
