"""The sheet's springs, grouped into colours: sets of springs that share no vertex, relaxed in parallel.

Plain NumPy: imported where Warp is not (the recorder process colours the sheet by strain with them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from warpcut.sim.config import SheetGrid


@dataclass(frozen=True)
class SpringColour:
    """Springs ``(row, col) -> (row + dj, col + di)`` whose start has ``(key // divisor) % 2 == parity``,
    ``key`` being the row (``on_rows``) or the column. No two springs of one colour share a vertex."""

    family: str
    di: int
    dj: int
    on_rows: bool
    divisor: int
    parity: int

    def rest_length(self, spacing: tuple[float, float]) -> float:
        return math.hypot(self.di * spacing[0], self.dj * spacing[1])


def spring_colours(springs: tuple[str, ...]) -> list[SpringColour]:
    """The colours of the chosen spring families, in sweep order (structural, shear, bending)."""
    directions = {
        "structural": [(1, 0, False, 1), (0, 1, True, 1)],
        "shear": [(1, 1, False, 1), (-1, 1, True, 1)],
        "bending": [(2, 0, False, 2), (0, 2, True, 2)],
    }
    return [
        SpringColour(family, di, dj, on_rows, divisor, parity)
        for family in ("structural", "shear", "bending")
        if family in springs
        for di, dj, on_rows, divisor in directions[family]
        for parity in (0, 1)
    ]


def colour_springs(grid: SheetGrid, springs: tuple[str, ...]) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Per colour, in sweep order: (start vertex indices, end vertex indices, rest length in mm)."""
    colours = []
    rows, cols = np.divmod(np.arange(grid.num_vertices), grid.nx)
    for colour in spring_colours(springs):
        key = rows if colour.on_rows else cols
        r2, c2 = rows + colour.dj, cols + colour.di
        inside = (r2 >= 0) & (r2 < grid.ny) & (c2 >= 0) & (c2 < grid.nx)
        keep = ((key // colour.divisor) % 2 == colour.parity) & inside
        colours.append(
            (np.flatnonzero(keep), r2[keep] * grid.nx + c2[keep], colour.rest_length(grid.spacing_mm))
        )
    return colours
