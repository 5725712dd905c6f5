"""What a recording's colours show: the sheet's vertex colours (strain or height on a viridis ramp) and the
fixed colours of the scissor tip and the fiducials, all as rerun's packed ``0xRRGGBBAA`` (cheaper to
convert than RGB triples)."""

from __future__ import annotations

import math

import numpy as np

from warpcut.sim.config import SheetGrid
from warpcut.sim.springs import spring_colours

COLOUR_FIELDS = ("strain", "height")
"""What the sheet's vertex colours can show (``Recorder(colour_by=...)``)."""

STRAIN_FULL_SCALE = 0.05
"""Strain at the top of the colour ramp: a vertex whose live springs are stretched or compressed by 5% on
average is drawn yellow. A settled sheet sits well below it except next to the corner clips, and a grasp
pulling the sheet raises its neighbourhood towards it."""

# Low (dark blue) to high (yellow): viridis, from five stops to 256 entries.
_VIRIDIS_STOPS = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]])
_RAMP_RGB = np.stack(
    [np.interp(np.linspace(0, 4, 256), np.arange(5), _VIRIDIS_STOPS[:, c]) for c in range(3)], axis=1
).astype(np.uint32)
_RAMP_RGBA = (_RAMP_RGB[:, 0] << 24) | (_RAMP_RGB[:, 1] << 16) | (_RAMP_RGB[:, 2] << 8) | 0xFF

CUTTING_RGB, TRAVEL_RGB = (230, 40, 40), (150, 150, 150)
"""The scissor tip while it cuts, and while it travels."""
VISIBLE_RGB, HIDDEN_RGB = (40, 200, 60), (110, 110, 110)
"""A fiducial the camera sees, and one it cannot (cut away or under the cutting arm's shaft)."""
GRASP_RGB = (230, 0, 200)
"""The grasp: the gripper's disc on the sheet."""
CUTTING_RGBA, TRAVEL_RGBA, VISIBLE_RGBA, HIDDEN_RGBA = (
    (r << 24) | (g << 16) | (b << 8) | 0xFF for r, g, b in (CUTTING_RGB, TRAVEL_RGB, VISIBLE_RGB, HIDDEN_RGB)
)


def ramp_image(height: int = 16) -> np.ndarray:
    """The colour ramp as a (height, 256, 3) uint8 RGB image, low (dark blue) on the left to high (yellow)
    on the right: the colour bar of a recording (``/legend/colour_bar``)."""
    return np.broadcast_to(_RAMP_RGB.astype(np.uint8)[None], (height, len(_RAMP_RGB), 3)).copy()


def colour_legend(colour_by: str) -> str:
    """What a recording's colours mean, as Markdown (``/legend/colour_scale``): the sheet's ramp for
    ``colour_by`` (:data:`COLOUR_FIELDS`) with its ends, and the fixed colours."""
    if colour_by == "strain":
        scale = (
            "**Sheet colour: strain.** Per vertex, the mean relative stretch |length / rest - 1| of its "
            f"live springs, on the bar from **0%** (dark blue, left) to **{STRAIN_FULL_SCALE:.0%}** "
            "(yellow, right) and above."
        )
    elif colour_by == "height":
        scale = (
            "**Sheet colour: height.** Per vertex, z from the env's lowest vertex (dark blue, left of the "
            "bar) to its highest (yellow, right) at its first frame; each env's range (mm) is in its info."
        )
    else:
        raise ValueError(f"colour_by: must be one of {', '.join(COLOUR_FIELDS)} (got {colour_by!r})")
    return (
        f"{scale}\n\n"
        "**Fixed colours.** Scissor tip: red while it cuts, grey while it travels. Fiducials: green where "
        "the camera sees them, grey where it cannot (cut away, or under the cutting arm). Grasp: the magenta "
        "disc (the gripper's pad, of the grasp radius) and the arrow of its displacement. Black line: the "
        "intended contour, flat at z = 0 (the sheet at rest), where the traced cut path is drawn too."
    )


def ramp_rgba(values: np.ndarray, low: float, high: float) -> np.ndarray:
    """Packed RGBA (uint32) of ``values`` on a viridis ramp from ``low`` to ``high`` (clipped)."""
    top = len(_RAMP_RGBA) - 1
    t = (np.asarray(values, dtype=np.float32) - np.float32(low)) * np.float32(top / (high - low))
    np.clip(t, 0.0, top, out=t)
    return _RAMP_RGBA[t.astype(np.intp)]


def vertex_strain(
    positions: np.ndarray,
    alive: np.ndarray,
    grid: SheetGrid,
    springs: tuple[str, ...] = ("structural", "shear"),
) -> np.ndarray:
    """Per vertex, the mean relative stretch ``|length / rest - 1|`` of its live springs.

    Args:
        positions: (F, V, 3) vertex positions (mm) of F frames of one sheet.
        alive: (F, V) bool; a spring is live while both its ends are alive.
        grid: The sheet's rest layout (V = ny * nx vertices).
        springs: The spring families simulated (:attr:`~warpcut.sim.config.SimConfig.springs`).

    Returns:
        (F, V) float32; 0 for a vertex without live springs.
    """
    frames = len(positions)
    ny, nx = grid.ny, grid.nx
    # Component-major, so that every spring direction is a pair of shifted slices of the grid: no gather.
    p = np.ascontiguousarray(np.moveaxis(np.asarray(positions, dtype=np.float32), -1, 0))
    p = p.reshape(3, frames, ny, nx)
    a = np.asarray(alive, dtype=bool).reshape(frames, ny, nx)
    total = np.zeros((frames, ny, nx), dtype=np.float32)
    count = np.zeros((frames, ny, nx), dtype=np.float32)
    for di, dj, rest in _spring_directions(grid, springs):
        start = (slice(0, ny - dj), slice(max(0, -di), nx - max(0, di)))
        end = (slice(dj, ny), slice(max(0, di), nx + min(0, di)))
        d = p[(slice(None), slice(None), *end)] - p[(slice(None), slice(None), *start)]
        d *= d
        strain = np.sqrt(d[0] + d[1] + d[2])
        strain *= np.float32(1.0 / rest)
        strain -= 1.0
        np.abs(strain, out=strain)
        live = a[(slice(None), *start)] & a[(slice(None), *end)]
        strain *= live
        for ends in (start, end):
            total[(slice(None), *ends)] += strain
            count[(slice(None), *ends)] += live
    return (total / np.maximum(count, 1.0)).reshape(frames, ny * nx)


def _spring_directions(grid: SheetGrid, springs: tuple[str, ...]) -> list[tuple[int, int, float]]:
    """The springs of ``springs``' families as ``(di, dj, rest length in mm)``: every vertex ``(row, col)``
    with ``(row + dj, col + di)`` on the grid has one (both parities of each colour)."""
    directions = sorted({(c.di, c.dj) for c in spring_colours(springs)})
    return [(di, dj, math.hypot(di * grid.spacing_mm[0], dj * grid.spacing_mm[1])) for di, dj in directions]
