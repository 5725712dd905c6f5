"""Settled sheets: each distinct set of the parameters that shape a hanging sheet is settled once, noise-free,
and kept for the envs (and later episodes) that share it."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from warpcut.sim.checks import check_settled
from warpcut.sim.config import SimConfig

SETTLE_PARAMETERS = ("damping", "dt", "gravity", "elasticity")
"""The physical parameters that shape a settled sheet (``noise_std`` does not: settling is noise-free)."""
SETTLE_CACHE_SHEETS = 4096
"""Settled sheets a simulator keeps for parameters that come back (about 7.5 kB each at 25 x 25)."""


class SettledSheets:
    """Settled sheets by their (damping, dt, gravity, elasticity), at most :data:`SETTLE_CACHE_SHEETS`.

    Args:
        simulator: What settles a batch: called as ``simulator(config, num_envs, device)``, it returns a
            batch with ``reset_flat``, ``update``, ``positions`` and ``divergence``
            (:class:`~warpcut.sim.simulator.Simulator`, which passes itself in: the simulator uses this
            cache, so this module does not import it).
    """

    def __init__(self, simulator: Callable[[SimConfig, int, str], Any]):
        self._simulator = simulator
        self._sheets: dict[tuple[float, ...], np.ndarray] = {}

    def __len__(self) -> int:
        return len(self._sheets)

    def sheets(self, config: SimConfig, group_params: np.ndarray, device: str) -> np.ndarray:
        """(G, N, 3) the settled sheet of each row of ``group_params`` (G, 4), in :data:`SETTLE_PARAMETERS`
        order, after ``config.settle_updates`` noise-free updates; those not kept yet are settled as one
        batch (:class:`~warpcut.sim.config.SimulationDiverged` if one does not hang)."""
        keys = [tuple(float(v) for v in row) for row in group_params]
        missing = [g for g, key in enumerate(keys) if key not in self._sheets]
        if missing:
            rows = group_params[missing]
            changes = {k: rows[:, c].tolist() for c, k in enumerate(SETTLE_PARAMETERS)}
            sheet = self._simulator(config.replace(**changes, noise_std=0.0), len(rows), device)
            sheet.reset_flat()
            for _ in range(config.settle_updates):
                sheet.update()
            settled = sheet.positions()
            check_settled(settled, sheet.divergence(), rows, config)
            if len(self._sheets) + len(missing) > SETTLE_CACHE_SHEETS:
                self._sheets.clear()
            self._sheets.update({keys[g]: settled[i] for i, g in enumerate(missing)})
        return np.stack([self._sheets[key] for key in keys])
