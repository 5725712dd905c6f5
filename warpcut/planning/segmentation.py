"""Cut planning, the paper's Problem 1: split a contour into segments the cutting arm can cut, and order them.

The cutting arm approaches from +x and its wrist turns at most 90 degrees off the -x direction, so along its
cutting direction a segment must never move toward +x. A contour is therefore split at its *notch points*
(local maxima of x, where the scissors enter) and *termination points* (local minima of x); each arc between
consecutive extremes is monotone in x and is cut from its notch to its termination. A circle gives two
segments, both running from its rightmost point to its leftmost one. The ends of an open contour are extremes
too: they lie on the sheet's edges, where the scissors can enter or leave.

The paper's ``gen_segments`` takes the extremes where a finite-difference derivative changes sign and assumes
there are no vertical stretches. Here, so that tiny wiggles and near-vertical stretches do not add spurious
segments:

* Extremes are found with hysteresis (a zigzag filter): x counts as reversing only once it has moved back by
  more than ``tolerance_mm`` from the extreme reached so far. Every segment is then *monotone within
  tolerance* (see :func:`is_monotone`): it never rises more than ``tolerance_mm`` above the lowest x reached
  before along its cutting direction. A wiggle at an open contour's end that reverses by no more than the
  tolerance is absorbed into the end, so the scissors enter or leave at the sheet's edge rather than at a
  new notch next to it.
* An extreme on a plateau (a flat or near-vertical stretch: the points next to it whose x lies within half
  the tolerance of the extreme's) is moved along the plateau to the point that keeps its two segments most
  nearly monotone there; among equally good points the one nearest the plateau's middle (by arc length)
  wins. An exactly vertical side thus gets its notch or termination in its middle, a slanted one at its
  outermost end. Half the tolerance keeps the plateaus of neighbouring extremes, which differ in x by more
  than the tolerance, apart, so the segments' order along the contour is unchanged.
* A segment shorter than ``min_length_mm`` is merged into a neighbour where the merged segment is still
  monotone within tolerance. Between the filter's extremes x reverses by more than the tolerance, so this
  only happens where moving an extreme along a noisy plateau left a short segment whose ends reverse by
  less.

Each segment is cut in the direction in which its x rises least: from its notch, normally its largest x, to
its termination. :func:`segment_orders` lists the orders in which to try cutting the segments.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from warpcut.contours import Contour, arc_lengths, polyline_length
from warpcut.sim.config import SEGMENT_TOLERANCE_MM

ORDER_LIMIT = 6
"""Up to this many segments every cutting order is listed (K! of them); beyond it a heuristic list."""

PLATEAU_FRACTION = 0.5
"""An extreme's plateau holds the neighbouring points whose x is within this fraction of ``tolerance_mm``
of the extreme's."""

# Violations closer than this are equal (mm): round-off along exactly vertical sides, far below anything the
# scissors can resolve.
_TIE_MM = 1e-9


@dataclass(frozen=True, eq=False)
class Segment:
    """One stretch of a contour cut in a single pass, from where the scissors enter to where they stop."""

    points: np.ndarray
    """(M, 2) material coordinates (mm), M >= 2, in cutting order: notch first, termination last."""

    @property
    def notch(self) -> np.ndarray:
        """(2,) where the scissors enter (mm)."""
        return self.points[0]

    @property
    def termination(self) -> np.ndarray:
        """(2,) where the segment ends (mm)."""
        return self.points[-1]

    @property
    def length(self) -> float:
        """Length of the polyline (mm)."""
        return polyline_length(self.points)


def is_monotone(points: np.ndarray, tolerance_mm: float) -> bool:
    """Whether a polyline, followed in order, can be cut by the arm: x never rises by more than
    ``tolerance_mm`` above the lowest x reached before it.

    Args:
        points: (M, 2) points (mm) in cutting order.
        tolerance_mm: Largest allowed rise (mm), >= 0; 0 demands x non-increasing.

    Raises:
        ValueError: for a negative or non-finite tolerance or points that are not (M, 2).
    """
    tol = _number("tolerance_mm", tolerance_mm, allow_zero=True)
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) == 0:
        raise ValueError(f"points: expected an (M, 2) array of x, y (mm) with M >= 1, got shape {pts.shape}")
    return _rise(pts[:, 0]) <= tol


def segment_contour(
    contour: Contour, tolerance_mm: float = SEGMENT_TOLERANCE_MM, min_length_mm: float = 2.0
) -> list[Segment]:
    """Split a contour into segments the arm can cut, each monotone within ``tolerance_mm``, from a notch
    (local maximum of x) to a termination (local minimum of x).

    The segments cover the contour exactly: each contour point lies on exactly one segment, except that
    neighbouring segments share the extreme between them. They are listed by position along the contour: a
    closed contour's counter-clockwise, starting at its extreme with the largest x; an open contour's from
    its first point.

    Args:
        contour: The contour to split.
        tolerance_mm: Hysteresis of the extreme detection and the rise allowed within a segment (mm), > 0.
        min_length_mm: Segments shorter than this (mm), >= 0, are merged into a neighbour where the merged
            segment is still monotone within ``tolerance_mm``.

    Returns:
        The segments. A contour whose x varies by no more than ``tolerance_mm`` is one segment; a closed one
        then runs from its rightmost point all the way round back to it.

    Raises:
        ValueError: for a non-positive ``tolerance_mm`` or a negative ``min_length_mm``.
    """
    tol = _number("tolerance_mm", tolerance_mm, allow_zero=False)
    min_length = _number("min_length_mm", min_length_mm, allow_zero=True)
    xy = np.asarray(contour.points, dtype=np.float64)
    closed = contour.closed
    if closed:
        # Starting at the rightmost point, a maximum the filter cannot miss, the loop needs no special case.
        xy = np.roll(xy, -int(np.argmax(xy[:, 0])), axis=0)
        pivots = _zigzag(np.append(xy[:, 0], xy[0, 0]), tol)[0][:-1]  # the last is the first again
        first_is_max = True
    else:
        pivots, first_is_max = _zigzag(xy[:, 0], tol)
    count = len(pivots)
    # Every extreme may move along its plateau, except an open contour's ends: the cut starts or stops there.
    movable = range(count) if closed and count > 1 else range(1, count - 1)
    refined = list(pivots)
    for k in movable:
        is_max = (k % 2 == 0) == first_is_max
        before, after = pivots[k - 1], pivots[(k + 1) % count]
        refined[k] = _refine(xy, pivots[k], before, after, is_max, PLATEAU_FRACTION * tol, closed)
    breaks = _merge_short(xy, refined, closed, tol, min_length)
    if closed:
        top = int(np.argmax(xy[breaks, 0]))
        breaks = breaks[top:] + breaks[:top]
    return [Segment(_frozen(_cutting_order(arc))) for arc in _arcs(xy, breaks, closed)]


def segment_orders(
    num_segments: int, limit: int = ORDER_LIMIT, notches: np.ndarray | None = None
) -> tuple[list[tuple[int, ...]], bool]:
    """Orders in which to cut ``num_segments`` segments, for the paper's search over cutting orders.

    Up to ``limit`` segments every order is listed (K! of them). Beyond that the search would explode
    (8! = 40320 simulations), so a short heuristic list is returned instead, in this order, without
    repeats:

    * the order along the contour (as :func:`segment_contour` lists them) and its reverse;
    * with ``notches``: rightmost notch first, so that the scissors, which reach each notch from +x, never
      travel over material that has already been cut; then leftmost notch first;
    * with ``notches``: top notch first, then bottom notch first.

    Ties keep the order along the contour.

    Args:
        num_segments: K >= 1.
        limit: Largest K, >= 1, whose orders are all listed.
        notches: Optional (K, 2) notch points (mm), e.g. ``[s.notch for s in segments]``, for the
            notch-based heuristic orders.

    Returns:
        ``(orders, heuristic)``: orders as tuples of segment indices, each a permutation of ``range(K)``, and
        whether they are the heuristic list rather than all K! orders (callers should warn that the search
        is then not exhaustive).

    Raises:
        ValueError: for K or ``limit`` below 1, or ``notches`` that are not (K, 2).
    """
    for name, value in (("num_segments", num_segments), ("limit", limit)):
        if not isinstance(value, int | np.integer) or isinstance(value, bool) or value < 1:
            raise ValueError(f"{name}: must be a positive integer (got {value!r})")
    xy = None if notches is None else np.asarray(notches, dtype=np.float64)
    if xy is not None and xy.shape != (num_segments, 2):
        raise ValueError(f"notches: expected shape ({num_segments}, 2), got {xy.shape}")
    if num_segments <= limit:
        return list(itertools.permutations(range(num_segments))), False
    along = tuple(range(num_segments))
    orders = [along, along[::-1]]
    if xy is not None:
        for key in (-xy[:, 0], xy[:, 0], -xy[:, 1], xy[:, 1]):
            orders.append(tuple(int(k) for k in np.argsort(key, kind="stable")))
    return list(dict.fromkeys(orders)), True


def _zigzag(x: np.ndarray, tol: float) -> tuple[list[int], bool]:
    """Indices where ``x`` reverses by more than ``tol`` (its first and last included), and whether the
    first is a maximum.

    A reversal of at most ``tol`` next to either end is absorbed into that end.
    """
    pivots = [0]
    trend = 0  # +1: rising toward a maximum, -1: falling toward a minimum, 0: not yet known
    first_is_max = bool(x[0] >= x[-1])  # kept only if x never moves by more than tol
    candidate = low = high = 0
    for i in range(1, len(x)):
        if trend == 0:
            low = i if x[i] < x[low] else low
            high = i if x[i] > x[high] else high
            if x[i] - x[low] > tol or x[high] - x[i] > tol:
                # The first move beyond tol sets the trend; the start is the first extreme.
                trend = 1 if x[i] - x[low] > tol else -1
                first_is_max = trend < 0
                candidate = i
        elif trend * (x[i] - x[candidate]) > 0:
            candidate = i
        elif trend * (x[candidate] - x[i]) > tol:
            pivots.append(candidate)
            trend = -trend
            candidate = i
    # The last point ends the last arc; a candidate after the last pivot that x left by no more than tol
    # is absorbed into it.
    pivots.append(len(x) - 1)
    return pivots, first_is_max


def _refine(
    xy: np.ndarray, pivot: int, before: int, after: int, is_max: bool, band: float, closed: bool
) -> int:
    """The point of ``pivot``'s plateau that keeps both its segments most nearly monotone there; among equally
    good points the one nearest the plateau's middle by arc length.

    The plateau is the run of points next to ``pivot`` whose x is within ``band`` of its x, up to but
    excluding the neighbouring pivots ``before`` and ``after``.
    """
    n = len(xy)
    sign = 1.0 if is_max else -1.0
    # Seen with this sign every extreme is a maximum and both segments start at it.
    x = sign * xy[:, 0]
    sides = []
    for step, stop in ((-1, before), (1, after)):
        side = []
        i = pivot + step
        while (i % n if closed else i) != stop and x[pivot] - x[i % n] <= band:
            side.append(i % n)
            i += step
        sides.append(side)
    run = np.array([*sides[0][::-1], pivot, *sides[1]])
    if len(run) == 1:
        return pivot
    xr = x[run]
    # rise(x[a:b]) == rise(-x[b:a:-1]): a segment ending at a minimum, read backwards and negated, starts
    # at a maximum, so one measure serves both.
    worst = np.array([max(_rise(xr[t::-1]), _rise(xr[t:])) for t in range(len(run))])
    arc = arc_lengths(xy[run])
    best = np.flatnonzero(worst <= worst.min() + _TIE_MM)
    return int(run[best[np.argmin(np.abs(arc[best] - 0.5 * arc[-1]))]])


def _arcs(xy: np.ndarray, breaks: list[int], closed: bool) -> list[np.ndarray]:
    """The stretches of the polyline ``xy`` between consecutive ``breaks``, in contour order, each including
    both its ends; a closed contour's wrap round, and a lone break's goes all the way round back to it."""
    if not closed:
        return [xy[a : b + 1] for a, b in itertools.pairwise(breaks)]
    n = len(xy)
    ends = [*breaks[1:], breaks[0]]
    return [xy[(a + np.arange(((b - a) % n or n) + 1)) % n] for a, b in zip(breaks, ends, strict=True)]


def _merge_short(xy: np.ndarray, breaks: list[int], closed: bool, tol: float, min_length: float) -> list[int]:
    """``breaks`` less those removed to merge segments shorter than ``min_length`` into a neighbour, where
    the merged segment stays monotone within ``tol``: shortest segment first, on the side where the merged
    segment rises least, until no such merge is left."""
    breaks = list(breaks)
    while True:
        arcs = _arcs(xy, breaks, closed)
        lengths = [polyline_length(arc) for arc in arcs]
        merges = []
        for k in sorted(range(len(arcs)), key=lambda k: (lengths[k], k)):
            if lengths[k] >= min_length:
                break
            # Merging arc k with the arc before removes break k; with the arc after, break k + 1.
            for shared in (k, k + 1):
                if (closed and len(breaks) > 2) or (not closed and 0 < shared < len(breaks) - 1):
                    i = shared % len(breaks)
                    merged = np.vstack([arcs[i - 1], arcs[i % len(arcs)][1:]])
                    rise = min(_rise(merged[:, 0]), _rise(merged[::-1, 0]))
                    if rise <= tol:
                        merges.append((rise, i))
            if merges:
                break
        if not merges:
            return breaks
        del breaks[min(merges)[1]]


def _cutting_order(arc: np.ndarray) -> np.ndarray:
    """``arc`` in the direction in which x rises least (notch first), from its larger-x end on a tie."""
    forward, backward = _rise(arc[:, 0]), _rise(arc[::-1, 0])
    if forward < backward or (forward == backward and arc[0, 0] >= arc[-1, 0]):
        return arc
    return arc[::-1]


def _rise(x: np.ndarray) -> float:
    """Largest rise of ``x`` above its running minimum (0 for a non-increasing sequence)."""
    return float(np.max(x - np.minimum.accumulate(x)))


def _frozen(points: np.ndarray) -> np.ndarray:
    points = np.ascontiguousarray(points)
    points.setflags(write=False)
    return points


def _number(name: str, value: float, allow_zero: bool) -> float:
    ok = isinstance(value, int | float | np.number) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or value < 0 or (value == 0 and not allow_zero):
        need = "a non-negative" if allow_zero else "a positive"
        raise ValueError(f"{name}: must be {need} number of mm (got {value!r})")
    return float(value)
