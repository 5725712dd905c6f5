"""Cutting contours: loading, validation and the built-in suite.

Units are millimetres. Contours are given in material (rest) coordinates on the sheet, which lies in the
x-y plane with its origin at the lower-left corner, x to the right and y up (default 100 x 100 mm). The
scissors approach from +x.

A contour is either *closed* (a simple loop on the sheet; the cut separates its inside) or *open* (a simple
polyline that enters and leaves the sheet through its edges; the cut separates the smaller of the two
pieces it splits the sheet into). Every contour, built-in or loaded, goes through :func:`validate`.

Contour files:

* ``.json``: ``{"name": "my-shape", "closed": true, "points": [[x_mm, y_mm], ...]}``; ``name`` is optional
  (default: the file stem).
* ``.svg``: the ``d`` attribute of the first ``<path>`` element. User units are millimetres and y is
  flipped (``y_mm = sheet_height - y_svg``) because SVG's y axis points down. A path ending with ``Z`` is
  closed. Curves are flattened into segments of at most 0.5 mm; arcs (``A``) are not supported.
"""

from __future__ import annotations

import json
import math
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path

import numpy as np
import shapely
import shapely.ops
from shapely.geometry import LinearRing, LineString, Point, Polygon, box

DEFAULT_SHEET_MM = (100.0, 100.0)
EDGE_REACH_MM = 5.0
"""An open contour's end within this distance of a sheet edge is extended straight onto that edge (mm)."""
SVG_CHORD_MM = 0.5
"""Longest segment an SVG curve is flattened into (mm)."""
BUILTIN_SPACING_MM = 0.5
"""Largest distance between consecutive points of a built-in contour (mm)."""

# Coordinates closer than this to an edge count as on it (mm): absorbs round-off such as
# 100 + 35 * cos(pi / 2), far below anything that matters on a 4 mm simulation grid.
_EDGE_TOL_MM = 1e-6


class ContourError(ValueError):
    """A contour is invalid or cannot be loaded; the message names the problem and how to fix it."""


@dataclass(frozen=True, eq=False)
class Contour:
    """A validated cutting contour in material coordinates (mm).

    Build it with :func:`validate`, :func:`load_contour` or :func:`builtin_contours`, which check and
    normalise the points; the constructor itself checks nothing. Instances compare by identity
    (``points`` is an array).
    """

    name: str
    closed: bool
    points: np.ndarray
    """(N, 2) float64, read-only (mm). Closed: the first point is not repeated at the end and the order is
    counter-clockwise. Open: in the given order, both ends on sheet edges."""
    sheet_size: tuple[float, float] = DEFAULT_SHEET_MM
    """Sheet width (x) and height (y) in mm."""

    @property
    def length(self) -> float:
        """Length of the polyline (mm), including the closing edge when closed."""
        return float(_cumulative_length(self.points, self.closed)[-1])

    def resample(self, spacing_mm: float) -> np.ndarray:
        """Points every ``spacing_mm`` of arc length along the polyline, starting at ``points[0]``.

        Args:
            spacing_mm: Arc length between consecutive points (mm), positive.

        Returns:
            (M, 2) float64 points (mm). Open: the last point is the end point, so the last step may be
            shorter. Closed: the start is not repeated, so the step back to it may be shorter.
        """
        if not isinstance(spacing_mm, int | float | np.number) or not 0 < spacing_mm < math.inf:
            raise ContourError(f"resample: spacing_mm must be a positive number of mm (got {spacing_mm!r})")
        return _resample(self.points, self.closed, float(spacing_mm))

    def intended_region(self) -> Polygon:
        """The material the cut should separate: the inside of a closed contour, or for an open one the
        smaller (by area) of the two pieces it splits the sheet rectangle into."""
        return self._region

    @cached_property
    def _region(self) -> Polygon:
        if self.closed:
            return Polygon(self.points)
        return min(_split_sheet(self.points, self.sheet_size), key=lambda piece: piece.area)

    @property
    def centroid(self) -> np.ndarray:
        """(2,) centroid of :meth:`intended_region` (mm)."""
        return np.array(self._region.centroid.coords[0], dtype=np.float64)

    @property
    def area_mm2(self) -> float:
        """Area of :meth:`intended_region` (mm^2)."""
        return float(self._region.area)

    def to_json(self) -> dict:
        """The contour as the JSON object :func:`load_contour` reads (``name``, ``closed``, ``points``)."""
        return {"name": self.name, "closed": self.closed, "points": self.points.tolist()}


def validate(
    name: str,
    closed: bool,
    points: np.ndarray | Sequence[Sequence[float]],
    sheet_size: tuple[float, float] = DEFAULT_SHEET_MM,
) -> Contour:
    """Check and normalise a contour; every loader goes through here.

    Consecutive duplicate points are removed (and a closed contour's repeated start); a closed contour is
    oriented counter-clockwise, keeping its start point; each end of an open contour lying within
    :data:`EDGE_REACH_MM` of a sheet edge is extended straight onto the nearest edge.

    Args:
        name: Contour name, used in messages.
        closed: True for a loop, False for a cut from edge to edge.
        points: (N, 2) x, y coordinates (mm) in material coordinates.
        sheet_size: Sheet width and height (mm).

    Returns:
        The validated :class:`Contour`.

    Raises:
        ContourError: naming the contour, the problem and the fix.
    """
    if not isinstance(name, str) or not name:
        raise ContourError(f"contour name must be a non-empty string (got {name!r})")
    width, height = _check_sheet_size(sheet_size)
    if not isinstance(closed, bool | np.bool_):
        raise ContourError(f"contour {name!r}: 'closed' must be true or false (got {closed!r})")
    closed = bool(closed)
    pts = _as_points(name, points)

    bad = np.flatnonzero(~np.isfinite(pts).all(axis=1))
    if bad.size:
        raise ContourError(
            f"contour {name!r}: point {bad[0]} is {pts[bad[0]].tolist()}, which is not finite "
            f"({bad.size} such point(s)); give finite x, y in mm"
        )
    pts = _drop_duplicates(_onto_sheet(name, pts, closed, width, height), closed)
    if len(pts) < 3:
        raise ContourError(
            f"contour {name!r}: fewer than 3 distinct points ({len(pts)} after removing repeated points); "
            "give at least 3 (sample curves densely, about every 1 mm)"
        )
    if closed:
        if _signed_area(pts) < 0:
            pts = np.concatenate([pts[:1], pts[:0:-1]])
    else:
        pts = _extend_to_edges(name, pts, width, height)
    _check_simple(name, pts, closed)
    if not closed:
        pieces = _split_sheet(pts, (width, height))
        if len(pieces) != 2:
            raise ContourError(
                f"contour {name!r}: an open contour must split the sheet into exactly two pieces, but it "
                f"splits it into {len(pieces)}; let it touch the sheet's edges only at its two ends"
            )
    pts.setflags(write=False)
    return Contour(name=name, closed=closed, points=pts, sheet_size=(width, height))


def load_contour(
    name_or_path: str | os.PathLike, sheet_size: tuple[float, float] = DEFAULT_SHEET_MM
) -> Contour:
    """A built-in contour by name, or one read from a ``.json`` or ``.svg`` file.

    Args:
        name_or_path: A name from :func:`builtin_names` (checked first) or a path to a contour file.
        sheet_size: Sheet width and height (mm).

    Raises:
        ContourError: for an unknown name, a missing or unsupported file, or an invalid contour.
    """
    key = os.fspath(name_or_path)
    if key in _SHAPES:
        return builtin_contours(sheet_size)[key]
    path = Path(key)
    suffix = path.suffix.lower()
    if path.is_file() and suffix == ".json":
        return _load_json(path, sheet_size)
    if path.is_file() and suffix == ".svg":
        return _load_svg(path, sheet_size)
    why = "no such file" if not path.is_file() else f"'{path.suffix}' is not a supported file type"
    raise ContourError(
        f"unknown contour {key!r}: not a built-in name (known: {', '.join(builtin_names())}) and {why}; "
        "give a built-in name or a path to a .json or .svg contour"
    )


def builtin_names() -> list[str]:
    """Names of the built-in contours: ``fls-circle`` first, then the other closed ones, then open ones."""
    return list(_SHAPES)


def builtin_contours(sheet_size: tuple[float, float] = DEFAULT_SHEET_MM) -> dict[str, Contour]:
    """The built-in suite, validated, keyed by name in :func:`builtin_names` order.

    The shapes are designed for the 100 x 100 mm FLS gauze. On another sheet size they are scaled per axis
    so that they keep their place on the sheet and open contours still end on the edges; on a non-square
    sheet circles therefore become ellipses.
    """
    width, height = _check_sheet_size(sheet_size)
    return dict(_builtin_contours(width, height))


# --------------------------------------------------------------------------------------------------
# Geometry helpers shared by validation and the Contour methods.


def _check_sheet_size(sheet_size: tuple[float, float]) -> tuple[float, float]:
    try:
        width, height = (float(v) for v in sheet_size)
    except (TypeError, ValueError):
        raise ContourError(f"sheet_size: give (width_mm, height_mm) (got {sheet_size!r})") from None
    if not (math.isfinite(width) and math.isfinite(height) and width > 0 and height > 0):
        raise ContourError(f"sheet_size: width and height must be positive (mm) (got {sheet_size!r})")
    return width, height


def _as_points(name: str, points) -> np.ndarray:
    try:
        raw = np.asarray(points)
    except (TypeError, ValueError):  # ragged nested lists
        raw = None
    # The dtype check rejects strings and None, which float() would partly accept.
    if raw is None or raw.dtype.kind not in "iuf" or raw.ndim != 2 or raw.shape[1] != 2:
        shape = "ragged" if raw is None else f"shape {raw.shape}, dtype {raw.dtype}"
        raise ContourError(
            f"contour {name!r}: points must be an (N, 2) array of numbers [[x_mm, y_mm], ...] (got {shape})"
        )
    return raw.astype(np.float64)  # a copy: callers' arrays are never modified


def _drop_duplicates(pts: np.ndarray, closed: bool) -> np.ndarray:
    keep = np.ones(len(pts), dtype=bool)
    keep[1:] = np.any(pts[1:] != pts[:-1], axis=1)
    pts = pts[keep]
    if closed:
        while len(pts) > 1 and np.array_equal(pts[0], pts[-1]):
            pts = pts[:-1]
    return pts


def _onto_sheet(name: str, pts: np.ndarray, closed: bool, width: float, height: float) -> np.ndarray:
    """Clip round-off onto the sheet; a real excursion is an error."""
    lo = np.zeros(2)
    hi = np.array([width, height])
    outside = np.maximum(lo - pts, pts - hi).max(axis=1)
    worst = int(np.argmax(outside))
    if outside[worst] > _EDGE_TOL_MM:
        kind = "a closed contour must lie inside" if closed else "an open contour must stay on"
        raise ContourError(
            f"contour {name!r}: {kind} the sheet, but it leaves it by {outside[worst]:.3g} mm at point "
            f"{worst} ({pts[worst, 0]:.6g}, {pts[worst, 1]:.6g}); "
            f"move it into [0, {width:g}] x [0, {height:g}] mm"
        )
    return np.clip(pts, lo, hi)


def _extend_to_edges(name: str, pts: np.ndarray, width: float, height: float) -> np.ndarray:
    ends = []
    for label, end in (("start", pts[0]), ("end", pts[-1])):
        x, y = end
        gaps = np.array([x, width - x, y, height - y])
        edge = int(np.argmin(gaps))
        on_edge = end.copy()
        on_edge[edge // 2] = (0.0, width, 0.0, height)[edge]
        if gaps[edge] > EDGE_REACH_MM:
            raise ContourError(
                f"contour {name!r}: an open contour must enter and leave the sheet through its edges, "
                f"but its {label} ({x:.6g}, {y:.6g}) is {gaps[edge]:.3g} mm from the nearest edge; "
                f"move it to within {EDGE_REACH_MM:g} mm of an edge, or close the contour"
            )
        ends.append((on_edge, gaps[edge] <= _EDGE_TOL_MM))
    (start, start_on), (stop, stop_on) = ends
    # An end already on the edge (up to round-off) is snapped there rather than doubled.
    if start_on:
        pts[0] = start
    if stop_on:
        pts[-1] = stop
    head = [] if start_on else [start[None]]
    tail = [] if stop_on else [stop[None]]
    return np.concatenate([*head, pts, *tail])


def _signed_area(pts: np.ndarray) -> float:
    x, y = pts.T
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _check_simple(name: str, pts: np.ndarray, closed: bool) -> None:
    line = LinearRing(pts) if closed else LineString(pts)
    if line.is_simple:
        return
    where = _first_crossing(pts, closed)
    at = f" near ({where[0]:.4g}, {where[1]:.4g})" if where is not None else ""
    raise ContourError(
        f"contour {name!r}: self-intersection{at}: the contour crosses or touches itself; "
        "give a simple curve (no loops, figure-eights or doubled-back segments)"
    )


def _first_crossing(pts: np.ndarray, closed: bool) -> np.ndarray | None:
    """A point where two segments meet other than at their shared vertex."""
    ring = np.concatenate([pts, pts[:1]]) if closed else pts
    segments = shapely.linestrings(np.stack([ring[:-1], ring[1:]], axis=1))
    n = len(segments)
    first, second = shapely.STRtree(segments).query(segments, predicate="intersects")
    for i, j in zip(first, second, strict=True):
        if i >= j:
            continue
        meeting = segments[i].intersection(segments[j])
        neighbours = j == i + 1 or (closed and i == 0 and j == n - 1)
        # Neighbours always share a vertex; only an overlap (doubling back) is a crossing.
        if not neighbours or meeting.length > 0:
            return np.array(meeting.representative_point().coords[0])
    return None


def _split_sheet(pts: np.ndarray, sheet_size: tuple[float, float]) -> list[Polygon]:
    pieces = shapely.ops.split(box(0.0, 0.0, *sheet_size), LineString(pts))
    return [piece for piece in pieces.geoms if piece.area > 0]


def _cumulative_length(pts: np.ndarray, closed: bool) -> np.ndarray:
    ring = np.concatenate([pts, pts[:1]]) if closed else pts
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ring, axis=0), axis=1))])


def _resample(pts: np.ndarray, closed: bool, spacing: float) -> np.ndarray:
    ring = np.concatenate([pts, pts[:1]]) if closed else pts
    arc = _cumulative_length(pts, closed)
    total = arc[-1]
    # Round-off must not add a point a hair before the end (open) or the start (closed).
    count = int(math.ceil(total / spacing - 1e-9))
    s = spacing * np.arange(count)
    if not closed:
        s = np.append(s, total)
    return np.stack([np.interp(s, arc, ring[:, 0]), np.interp(s, arc, ring[:, 1])], axis=1)


# --------------------------------------------------------------------------------------------------
# File loaders.


def _load_json(path: Path, sheet_size: tuple[float, float]) -> Contour:
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ContourError(f"contour file {str(path)!r}: cannot read it as JSON ({exc})") from None
    if not isinstance(data, dict):
        raise ContourError(
            f"contour file {str(path)!r}: expected a JSON object "
            '{"name": ..., "closed": true/false, "points": [[x, y], ...]}'
        )
    name = data.get("name", path.stem)
    if not isinstance(name, str) or not name:
        raise ContourError(
            f"contour file {str(path)!r}: field 'name' must be a non-empty string (got {name!r})"
        )
    if not isinstance(data.get("closed"), bool):
        raise ContourError(
            f"contour file {str(path)!r}: field 'closed' is required and must be true or false "
            f"(got {data.get('closed', 'nothing')!r})"
        )
    points = data.get("points")
    if not isinstance(points, list) or not all(
        isinstance(p, list) and len(p) == 2 and all(_is_number(v) for v in p) for p in points
    ):
        raise ContourError(
            f"contour file {str(path)!r}: field 'points' is required and must be a list of [x_mm, y_mm] "
            "number pairs"
        )
    return validate(name, data["closed"], np.array(points, dtype=np.float64).reshape(-1, 2), sheet_size)


def _is_number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _load_svg(path: Path, sheet_size: tuple[float, float]) -> Contour:
    where = f"contour file {str(path)!r}"
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ContourError(f"{where}: cannot read it as SVG/XML ({exc})") from None
    parents = {child: parent for parent in root.iter() for child in parent}
    element = next((e for e in root.iter() if _local_tag(e.tag) == "path"), None)
    if element is None or not element.get("d"):
        raise ContourError(f"{where}: no <path> element with a 'd' attribute; draw the contour as a path")
    node = element
    while node is not None:
        # Coordinates are read as written, so a transform would silently move or distort the contour.
        if node.get("transform"):
            raise ContourError(
                f"{where}: the path or a group around it has a transform ({node.get('transform')!r}), which "
                "is not supported; apply it to the path first (Inkscape: ungroup, then Path > Object to Path)"
            )
        node = parents.get(node)

    origin = np.zeros(2)
    if root.get("viewBox"):
        try:
            origin = np.array([float(v) for v in re.split(r"[\s,]+", root.get("viewBox").strip())[:2]])
        except ValueError:
            raise ContourError(f"{where}: cannot read viewBox {root.get('viewBox')!r}") from None
    points, closed = _parse_path(where, element.get("d"))
    height = _check_sheet_size(sheet_size)[1]
    xy = np.asarray(points, dtype=np.float64) - origin
    xy[:, 1] = height - xy[:, 1]
    return validate(path.stem, closed, xy, sheet_size)


def _local_tag(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


_PATH_TOKEN = re.compile(r"[A-Za-z]|[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_PATH_ARGS = {"M": 2, "L": 2, "H": 1, "V": 1, "C": 6, "S": 4, "Q": 4, "T": 2, "Z": 0}


def _parse_path(where: str, d: str) -> tuple[list[np.ndarray], bool]:
    """Flatten one SVG subpath into points (SVG user units, y down) and whether it ends with Z."""
    tokens = _PATH_TOKEN.findall(d)
    points: list[np.ndarray] = []
    closed = False
    pos = np.zeros(2)
    last_cubic = last_quad = None  # previous curve's last control point, reflected by S and T
    command = ""
    i = 0
    while i < len(tokens):
        if tokens[i].isalpha():
            command = tokens[i]
            i += 1
        elif command in ("", "Z", "z"):
            raise ContourError(f"{where}: path data has a number ({tokens[i]!r}) where a command is expected")
        kind = command.upper()
        if kind == "A":
            raise ContourError(
                f"{where}: SVG arcs (A/a commands) are unsupported; convert them to cubic Bezier curves "
                "first (e.g. Inkscape: Path > Object to Path, or your editor's 'convert to cubic' option)"
            )
        if kind not in _PATH_ARGS:
            raise ContourError(f"{where}: unknown SVG path command {command!r}")
        if (kind == "M" and points) or (kind != "M" and closed):
            raise ContourError(
                f"{where}: the path has several subpaths; give one contour per file (split the path)"
            )
        if kind != "M" and not points:
            raise ContourError(f"{where}: path data must start with a moveto (M or m)")
        if kind == "Z":
            closed = True
            continue
        count = _PATH_ARGS[kind]
        numbers = tokens[i : i + count]
        if len(numbers) != count or any(t.isalpha() for t in numbers):
            raise ContourError(
                f"{where}: command {command!r} needs {count} numbers; the path data is cut short"
            )
        i += count
        values = np.array(numbers, dtype=np.float64)
        offset = pos if command.islower() else np.zeros(2)
        if kind in ("H", "V"):
            axis = int(kind == "V")
            given = pos[None].copy()
            given[0, axis] = values[0] + offset[axis]
        else:
            given = values.reshape(-1, 2) + offset
        if kind == "S":
            given = np.vstack([pos if last_cubic is None else 2 * pos - last_cubic, given])
        elif kind == "T":
            given = np.vstack([pos if last_quad is None else 2 * pos - last_quad, given])
        if kind in ("C", "S", "Q", "T"):
            points.extend(_bezier(np.vstack([pos, given]))[1:])
        else:
            points.append(given[-1])
        if kind == "M":
            # Pairs after a moveto are implicit linetos.
            command = "l" if command.islower() else "L"
        last_cubic = given[-2] if kind in ("C", "S") else None
        last_quad = given[-2] if kind in ("Q", "T") else None
        pos = given[-1]
    if not points:
        raise ContourError(f"{where}: the path has no points")
    return points, closed


def _bezier(control: np.ndarray) -> np.ndarray:
    """Points on a Bezier curve, from its first to its last control point, at most SVG_CHORD_MM apart."""
    degree = len(control) - 1
    # |B'(t)| <= degree * (longest control leg), which bounds each piece's arc length and so its chord.
    longest = float(np.linalg.norm(np.diff(control, axis=0), axis=1).max())
    t = np.linspace(0.0, 1.0, max(1, math.ceil(degree * longest / SVG_CHORD_MM)) + 1)[:, None]
    weights = [math.comb(degree, k) * t**k * (1 - t) ** (degree - k) for k in range(degree + 1)]
    return sum(w * c for w, c in zip(weights, control, strict=True))


# --------------------------------------------------------------------------------------------------
# The built-in suite, drawn on the 100 x 100 mm sheet. Each shape is a dense sample of a parametric curve
# or a shapely outline; _builtin_contours resamples it evenly and validates it. Closed shapes keep >= 8 mm
# from the edges (the corners are clipped) and are several mm wide everywhere, as the simulation grid is
# ~4.2 mm; open ones end exactly on the edges.

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


@lru_cache(maxsize=8)
def _builtin_contours(width: float, height: float) -> dict[str, Contour]:
    scale = np.array([width, height]) / 100.0
    contours = {}
    for name, (closed, shape) in _SHAPES.items():
        dense = shape()
        length = _cumulative_length(dense, closed)[-1]
        points = _resample(dense, closed, length / math.ceil(length / BUILTIN_SPACING_MM))
        if closed:
            # Start where scissors coming from +x meet the shape first.
            points = np.roll(points, -int(np.argmax(points[:, 0])), axis=0)
        contours[name] = validate(name, closed, points * scale, (width, height))
    return contours
