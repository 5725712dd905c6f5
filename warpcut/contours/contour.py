"""The contour type and its validation.

Units are millimetres. Contours are given in material (rest) coordinates on the sheet, which lies in the
x-y plane with its origin at the lower-left corner, x to the right and y up (default 100 x 100 mm). The
scissors approach from +x.

A contour is either *closed* (a simple loop inside the sheet, off its edges; the cut separates its inside)
or *open* (a simple polyline that enters and leaves the sheet through its edges; the cut separates the
smaller of the two pieces it splits the sheet into). Every contour, built-in or loaded, goes through
:func:`validate`, which checks what holds on any grid; :func:`check_resolution` checks that a given
simulation grid resolves it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import shapely
import shapely.ops
from shapely.geometry import LinearRing, LineString, Point, Polygon, box

from warpcut.contours.polyline import arc_lengths, resample_polyline, ring
from warpcut.sim.config import RESOLUTION_RANGE
from warpcut.validation import check_flag, check_text, fail, is_number

DEFAULT_SHEET_MM = (100.0, 100.0)
EDGE_REACH_MM = 5.0
"""An open contour's end within this distance of a sheet edge is extended straight onto that edge (mm)."""

OPEN_TIE = 1e-6
"""The share of the sheet's area within which an open contour's two pieces count as equal (0.01 mm^2 on the
default sheet; the built-in and generated open contours' pieces differ by 200 mm^2 and more)."""

MAX_POINTS = 10_000
"""The most points a contour may have (after repeated points are removed): planning one takes seconds
(segmenting it grows faster than its points: 10^6 would take hours); the built-in contours have a point
every 0.5 mm, a few hundred."""

# Coordinates closer than this to an edge count as on it (mm): absorbs round-off such as
# 100 + 35 * cos(pi / 2), far below anything that matters on a 4 mm simulation grid.
_EDGE_TOL_MM = 1e-6


class ContourError(ValueError):
    """A contour is invalid or cannot be loaded; the message names the problem and how to fix it."""


@dataclass(frozen=True, eq=False)
class Contour:
    """A validated cutting contour in material coordinates (mm).

    Build it with :func:`validate`, :func:`~warpcut.contours.loaders.load_contour` or
    :func:`~warpcut.contours.suite.builtin_contours`, which check and normalise the points; the
    constructor itself checks only the fields' types (a :class:`~warpcut.validation.ConfigError` naming
    ``Contour.field``), not the geometry. Instances compare by identity (``points`` is an array).
    """

    name: str
    closed: bool
    points: np.ndarray
    """(N, 2) float64, read-only (mm). Closed: the first point is not repeated at the end and the order is
    counter-clockwise. Open: in the given order, both ends on sheet edges."""
    sheet_size: tuple[float, float] = DEFAULT_SHEET_MM
    """Sheet width (x) and height (y) in mm."""

    def __post_init__(self) -> None:
        check_text("Contour.name", self.name)
        object.__setattr__(self, "closed", check_flag("Contour.closed", self.closed))
        points = self.points
        if not (
            isinstance(points, np.ndarray)
            and points.dtype.kind in "iuf"
            and points.ndim == 2
            and points.shape[0] >= 2
            and points.shape[1] == 2
            and np.isfinite(points).all()
        ):
            fail(
                "Contour.points", "an (N, 2) array of finite x, y (mm), N >= 2 (validate() makes one)", points
            )
        size = self.sheet_size
        pair = isinstance(size, list | tuple) and len(size) == 2 and all(is_number(v) for v in size)
        if not (pair and all(0 < v < math.inf for v in size)):
            fail("Contour.sheet_size", "(width_mm, height_mm), two finite numbers > 0", size)
        object.__setattr__(self, "sheet_size", (float(size[0]), float(size[1])))

    @property
    def length(self) -> float:
        """Length of the polyline (mm), including the closing edge when closed."""
        return float(arc_lengths(self.points, self.closed)[-1])

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
        return resample_polyline(self.points, float(spacing_mm), self.closed)

    def intended_region(self) -> Polygon:
        """The material the cut should separate: the inside of a closed contour, or for an open one the
        smaller (by area) of the two pieces it splits the sheet rectangle into; where they are equal within
        :data:`OPEN_TIE` of the sheet's area (a contour that halves it), the piece on its left (as it runs
        from its first point), so that a shift by round-off never flips the side."""
        return self._region

    @cached_property
    def _region(self) -> Polygon:
        if self.closed:
            return Polygon(self.points)
        pieces = sorted(_split_sheet(self.points, self.sheet_size), key=lambda piece: piece.area)
        width, height = self.sheet_size
        if len(pieces) == 2 and pieces[1].area - pieces[0].area <= OPEN_TIE * width * height:
            start, step = self.points[0], self.points[1] - self.points[0]
            left = Point(start + step / 2 + 1e-3 * np.array([-step[1], step[0]]) / np.hypot(*step))
            return min(pieces, key=lambda piece: piece.distance(left))
        return pieces[0]

    @property
    def centroid(self) -> np.ndarray:
        """(2,) centroid of :meth:`intended_region` (mm)."""
        return np.array(self._region.centroid.coords[0], dtype=np.float64)

    @property
    def area_mm2(self) -> float:
        """Area of :meth:`intended_region` (mm^2)."""
        return float(self._region.area)

    def to_json(self) -> dict:
        """The contour as the JSON object :func:`~warpcut.contours.loaders.load_contour` reads: ``name``,
        ``closed`` and ``points``."""
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

    The points must be finite and on the sheet, the polyline simple; a closed contour must not touch the
    sheet's edges (the fixture holds the material around it), an open one must split the sheet in two.
    Whether a simulation grid resolves the contour is for :func:`check_resolution`, which needs the grid.

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
    width, height = check_sheet_size(sheet_size)
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
    pts = _drop_duplicates(_onto_sheet(name, pts, closed, width, height), closed) if len(pts) else pts
    if len(pts) > MAX_POINTS:
        length = float(np.hypot(*np.diff(pts, axis=0).T).sum())
        raise ContourError(
            f"contour {name!r}: {len(pts):,} points, more than the {MAX_POINTS:,} warpcut plans (not "
            f"resampled); resample it, e.g. a point every {max(0.5, length / MAX_POINTS):.2g} mm "
            "(warpcut.contours.polyline.resample_polyline)"
        )
    if len(pts) < 3:
        raise ContourError(
            f"contour {name!r}: fewer than 3 distinct points ({len(pts)} after removing repeated points); "
            "give at least 3 (sample curves densely, about every 1 mm)"
        )
    if closed:
        _check_off_edges(name, pts, width, height)
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


def check_sheet_size(sheet_size: tuple[float, float]) -> tuple[float, float]:
    """``(width, height)`` as floats (mm).

    Raises:
        ContourError: unless both are finite and positive.
    """
    try:
        width, height = (float(v) if is_number(v) else math.nan for v in sheet_size)
    except (TypeError, ValueError):
        raise ContourError(f"sheet_size: give (width_mm, height_mm) (got {sheet_size!r})") from None
    if not (math.isfinite(width) and math.isfinite(height) and width > 0 and height > 0):
        raise ContourError(f"sheet_size: width and height must be positive (mm) (got {sheet_size!r})")
    return width, height


def check_resolution(contour: Contour, spacing_mm: float | tuple[float, float]) -> None:
    """Check that a simulation grid with vertices ``spacing_mm`` apart resolves ``contour``.

    Both the material the cut should separate (:meth:`Contour.intended_region`) and the rest of the sheet,
    which the fixture holds, must be at least one grid spacing wide somewhere (the diameter of the largest
    disc inside them) and cover at least one vertex's cell (``hx * hy``): anything smaller can fall
    between the vertices, and its error is meaningless (a sliver can score 0 vertices either way).

    Args:
        contour: A validated contour.
        spacing_mm: Grid spacing along x and y, ``(hx, hy)``, or one for both (mm); e.g.
            ``SheetGrid.spacing_mm`` or ``SimConfig.spacing_mm``.

    Raises:
        ContourError: naming the contour, the grid's resolution and the coarsest resolution that resolves it.
    """
    if not isinstance(contour, Contour):
        raise ContourError(f"contour: expected a Contour (validate(...)), got {type(contour).__name__}")
    try:
        spacing = np.asarray(spacing_mm)
    except ValueError:  # ragged
        spacing = np.asarray(None)
    if spacing.dtype.kind not in "iuf" or spacing.shape not in ((), (2,)):
        raise ContourError(f"spacing_mm: give (hx_mm, hy_mm) or one number (got {spacing_mm!r})")
    hx, hy = (float(h) for h in np.broadcast_to(spacing, (2,)))
    if not (0 < hx < math.inf and 0 < hy < math.inf):
        raise ContourError(f"spacing_mm: must be positive and finite (mm) (got {spacing_mm!r})")
    width, height = contour.sheet_size
    region = contour.intended_region()
    rest = box(0.0, 0.0, width, height) - region
    parts = [
        ("the region it cuts out", region, "enlarge the contour"),
        ("the rest of the sheet", rest, "shrink the contour or move it away from the sheet's edges"),
    ]
    sizes = [(_widest(part, width, height), part.area) for _, part, _ in parts]
    # Slack for round-off, so that the resolution suggested below passes.
    failing = [
        i
        for i, (across, area) in enumerate(sizes)
        if across < max(hx, hy) * (1 - 1e-9) or area < hx * hy * (1 - 1e-9)
    ]
    if not failing:
        return
    label, _, change = parts[failing[0]]
    across, area = sizes[failing[0]]
    # The coarsest square grid that resolves both: spacing at most each one's width, cell at most its area.
    need = max(max(width / w, height / w, math.sqrt(width * height / a)) if w else math.inf for w, a in sizes)
    finest = RESOLUTION_RANGE[1]
    fix = (
        f"use resolution {math.ceil(need) + 1} or finer, or {change}"
        if need + 1 <= finest
        else f"no resolution up to {finest} resolves it: {change}"
    )
    grid = f"{_resolution(width, hx)} x {_resolution(height, hy)}, {hx:.3g} x {hy:.3g} mm between vertices"
    raise ContourError(
        f"contour {contour.name!r}: too small for the simulation grid: {label} is at most {across:.3g} mm "
        f"wide with an area of {area:.3g} mm^2, but at resolution {grid}, it must be at least one spacing "
        f"wide and one vertex cell ({hx * hy:.3g} mm^2) in area; {fix}"
    )


def _widest(part, width: float, height: float) -> float:
    """Diameter of the largest disc inside ``part`` (mm; 0 if it is empty), to 1e-4 of the sheet's size."""
    if not part.area > 0:
        return 0.0
    return 2.0 * shapely.maximum_inscribed_circle(part, 1e-4 * max(width, height)).length


def _resolution(length: float, spacing: float) -> str:
    """Vertices along a side ``length`` mm long at ``spacing`` mm, as text (a whole number if it is one)."""
    n = length / spacing + 1
    return f"{round(n)}" if abs(n - round(n)) < 1e-6 else f"{n:.3g}"


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
    """Clip round-off onto the sheet and snap it onto the edges; a real excursion is an error."""
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
    pts = np.clip(pts, lo, hi)
    # Within round-off of an edge is on it (also spares geometry code coordinates like 1e-300).
    pts = np.where(pts - lo <= _EDGE_TOL_MM, lo, pts)
    return np.where(hi - pts <= _EDGE_TOL_MM, hi, pts)


def _check_off_edges(name: str, pts: np.ndarray, width: float, height: float) -> None:
    """A closed contour must leave material all round it: the fixture holds the sheet outside the cut."""
    gaps = np.minimum(np.minimum(pts[:, 0], width - pts[:, 0]), np.minimum(pts[:, 1], height - pts[:, 1]))
    on_edge = np.flatnonzero(gaps <= _EDGE_TOL_MM)
    if on_edge.size:
        x, y = pts[on_edge[0]]
        raise ContourError(
            f"contour {name!r}: a closed contour must lie inside the sheet with material all round it to "
            f"clip and hold, but point {on_edge[0]} ({x:.6g}, {y:.6g}) is on the sheet's edge "
            f"({on_edge.size} such point(s)); move it into (0, {width:g}) x (0, {height:g}) mm, or give a "
            "cut from edge to edge as an open contour"
        )


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
    # Measured from the first point: far from the origin the products would cancel out a small shape's area.
    x, y = (pts - pts[0]).T
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
    line = ring(pts, closed)
    segments = shapely.linestrings(np.stack([line[:-1], line[1:]], axis=1))
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
