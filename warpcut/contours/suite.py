"""The built-in contour suite, drawn on the 100 x 100 mm FLS gauze.

Each shape is a dense sample of a parametric curve or a shapely outline, resampled evenly (at most
:data:`BUILTIN_SPACING_MM` apart) and validated. Closed shapes keep >= 8 mm from the edges (the corners
are clipped) and are several mm wide everywhere, as the simulation grid is ~4.2 mm; open ones end exactly
on the edges.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import lru_cache

import numpy as np
import shapely
from shapely.geometry import LineString, Point

from warpcut.contours.contour import DEFAULT_SHEET_MM, Contour, check_sheet_size, validate
from warpcut.contours.polyline import arc_lengths, resample_polyline

BUILTIN_SPACING_MM = 0.5
"""Largest distance between consecutive points of a built-in contour (mm)."""


def builtin_names() -> list[str]:
    """Names of the built-in contours: ``fls-circle`` first, then the other closed ones, then open ones."""
    return list(_SHAPES)


def builtin_contours(sheet_size: tuple[float, float] = DEFAULT_SHEET_MM) -> dict[str, Contour]:
    """The built-in suite, validated, keyed by name in :func:`builtin_names` order.

    The shapes are designed for the 100 x 100 mm FLS gauze. On another sheet size they are scaled per axis
    so that they keep their place on the sheet and open contours still end on the edges; on a non-square
    sheet circles therefore become ellipses.
    """
    width, height = check_sheet_size(sheet_size)
    return dict(_builtin_contours(width, height))


@lru_cache(maxsize=8)
def _builtin_contours(width: float, height: float) -> dict[str, Contour]:
    scale = np.array([width, height]) / 100.0
    contours = {}
    for name, (closed, shape) in _SHAPES.items():
        dense = shape()
        length = arc_lengths(dense, closed)[-1]
        points = resample_polyline(dense, length / math.ceil(length / BUILTIN_SPACING_MM), closed)
        if closed:
            # Start where scissors coming from +x meet the shape first.
            points = np.roll(points, -int(np.argmax(points[:, 0])), axis=0)
        contours[name] = validate(name, closed, points * scale, (width, height))
    return contours


# Shape generators: dense samples (mm) on the 100 x 100 mm sheet.

_DENSE = 4096


def _polar(
    cx: float, cy: float, radius, sx: float = 1.0, sy: float = 1.0, turn_deg: float = 0.0
) -> np.ndarray:
    """Closed curve ``(cx, cy) + radius(t) * (sx cos t, sy sin t)``, turned ``turn_deg`` about its centre."""
    t = np.linspace(0.0, 2 * np.pi, _DENSE, endpoint=False)
    r = radius(t) if callable(radius) else np.full_like(t, radius)
    c, s = math.cos(math.radians(turn_deg)), math.sin(math.radians(turn_deg))
    return np.stack([sx * r * np.cos(t), sy * r * np.sin(t)], axis=1) @ [[c, s], [-s, c]] + [cx, cy]


def _curve(xy: Callable[[np.ndarray], tuple], t0: float, t1: float) -> np.ndarray:
    """Dense sample of the parametric curve ``xy(t)`` for t from t0 to t1."""
    x, y = xy(np.linspace(t0, t1, _DENSE))
    return np.stack(np.broadcast_arrays(x, y), axis=1).astype(np.float64)


def _arc(cx: float, cy: float, r: float, a0_deg: float, a1_deg: float) -> np.ndarray:
    a = np.radians([a0_deg, a1_deg])
    return _curve(lambda t: (cx + r * np.cos(t), cy + r * np.sin(t)), a[0], a[1])


def _thick(skeletons: list, half_width: float, fillet: float = 2.0) -> np.ndarray:
    """Outline of polylines drawn with a round pen; inner corners get a ``fillet`` radius too (mm)."""
    stroke = shapely.union_all([LineString(s) for s in skeletons]).buffer(half_width, quad_segs=32)
    return _outline(stroke.buffer(fillet, quad_segs=32).buffer(-fillet, quad_segs=32))


def _outline(region) -> np.ndarray:
    return np.asarray(region.exterior.coords)[:-1]


def _rounded(region, radius: float = 3.0):
    """Morphological opening: rounds off tips sharper than ``radius`` (mm), e.g. a crescent's horns."""
    return region.buffer(-radius, quad_segs=32).buffer(radius, quad_segs=32)


def _harmonics(r0: float, *terms: tuple[float, float, float]) -> Callable[[np.ndarray], np.ndarray]:
    """Polar radius ``r0 + sum(amplitude * cos(frequency * t + phase))`` (mm) for ``terms`` of
    (amplitude mm, frequency, phase rad)."""
    return lambda t: r0 + sum(a * np.cos(k * t + phase) for a, k, phase in terms)


def _dent(t: np.ndarray, at: float, depth: float, width: float) -> np.ndarray:
    """A smooth dip of ``depth`` mm in a polar radius around angle ``at`` (rad), ``width`` rad wide."""
    return depth * np.exp(-((np.angle(np.exp(1j * (t - at))) / width) ** 2))


_TAU = 2 * np.pi
_SHAPES: dict[str, tuple[bool, Callable[[], np.ndarray]]] = {
    # The FLS pattern-cutting task: a 50 mm circle in the middle of the gauze.
    "fls-circle": (True, lambda: _polar(50, 50, 25)),
    "circle-small": (True, lambda: _polar(36, 60, 15)),
    "circle-large": (True, lambda: _polar(50, 50, 40)),
    "circle-offset": (True, lambda: _polar(62, 38, 18)),
    "ellipse-wide": (True, lambda: _polar(50, 50, 1, sx=36, sy=20)),
    "ellipse-tall": (True, lambda: _polar(50, 50, 1, sx=18, sy=34)),
    "ellipse-tilted": (True, lambda: _polar(50, 50, 1, sx=36, sy=18, turn_deg=30)),
    "blob-round": (True, lambda: _polar(50, 50, _harmonics(26, (4, 2, 1.5), (3, 3, 0.5)))),
    "blob-lumpy": (True, lambda: _polar(50, 50, _harmonics(28, (5, 2, 1), (3, 3, 1.5), (2, 5, 2)))),
    "blob-wavy": (True, lambda: _polar(50, 50, _harmonics(32, (3.5, 10, 0)))),
    "kidney": (True, lambda: _polar(50, 50, lambda t: 30 - _dent(t, np.pi, 11, 0.55), sx=1.15, sy=0.85)),
    "crescent": (True, lambda: _outline(_rounded(Point(46, 50).buffer(32) - Point(60, 50).buffer(27)))),
    "flower-3": (True, lambda: _polar(50, 50, _harmonics(27, (9, 3, 0)))),
    "flower-5": (True, lambda: _polar(50, 50, _harmonics(28, (9, 5, 0)))),
    "c-shape": (True, lambda: _thick([_arc(50, 50, 26, 45, 315)], 7)),
    "c-shape-reversed": (True, lambda: _thick([_arc(50, 50, 26, -135, 135)], 7)),
    "e-shape": (True, lambda: _thick([[(75, 20), (25, 20), (25, 80), (75, 80)], [(25, 50), (75, 50)]], 6)),
    "diagonal": (False, lambda: _curve(lambda t: (t, t + 15), 0, 85)),
    "edge-bite": (False, lambda: _arc(50, 0, 25, 0, 180)),
    "arc-top": (False, lambda: _curve(lambda x: (x, 130 - np.sqrt(50**2 - (x - 50) ** 2)), 10, 90)),
    "arc-left": (False, lambda: _curve(lambda y: (np.sqrt(50**2 - (y - 50) ** 2) - 30, y), 10, 90)),
    "parabola": (False, lambda: _curve(lambda x: (x, 80 - 0.05 * (x - 50) ** 2), 10, 90)),
    "s-curve": (False, lambda: _curve(lambda y: (45 + 20 * np.sin(_TAU * y / 100), y), 0, 100)),
    "wave-1": (False, lambda: _curve(lambda x: (x, 45 + 10 * np.sin(_TAU * x / 100)), 0, 100)),
    "wave-2": (False, lambda: _curve(lambda x: (x, 40 + 6 * np.sin(2 * _TAU * x / 100)), 0, 100)),
    "wave-3": (False, lambda: _curve(lambda x: (x, 62 + 4 * np.sin(3 * _TAU * x / 100)), 0, 100)),
}
