"""Tests for warpcut.planning.segmentation: splitting contours into wrist-feasible segments, cut orders."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from warpcut.contours import builtin_contours, load_contour, validate
from warpcut.planning.segmentation import Segment, is_monotone, segment_contour, segment_orders

BUILTINS = builtin_contours()


def contour_indices(contour, segments: list[Segment]) -> list[np.ndarray]:
    """Each segment as indices into ``contour.points``, turned to run along the contour; checks that every
    segment is a contiguous stretch of the contour and that consecutive segments meet."""
    n = len(contour.points)
    where = {tuple(p): i for i, p in enumerate(contour.points)}
    chains = []
    for segment in segments:
        idx = np.array([where[tuple(p)] for p in segment.points])
        step = (lambda i: np.diff(i) % n) if contour.closed else np.diff
        if step(idx)[0] != 1:
            idx = idx[::-1]
        assert np.all(step(idx) == 1), f"{contour.name}: a segment is not a contiguous stretch of the contour"
        chains.append(idx)
    pairs = itertools.pairwise(chains + chains[:1] if contour.closed else chains)
    assert all(a[-1] == b[0] for a, b in pairs), f"{contour.name}: consecutive segments do not meet"
    return chains


def rise(points: np.ndarray) -> float:
    x = np.asarray(points)[:, 0]
    return float(np.max(x - np.minimum.accumulate(x)))


def polar_x_maxima(radius, tolerance_mm: float) -> int:
    """Local maxima of x = r(t) cos(t) around a polar curve, from a dense analytic sample (not the module)."""
    t = np.linspace(0.0, 2 * np.pi, 100_000, endpoint=False)
    x = radius(t) * np.cos(t)
    rising = np.diff(np.append(x, x[0])) > 0
    maxima = np.flatnonzero(np.roll(rising, 1) & ~rising)
    minima = np.flatnonzero(~np.roll(rising, 1) & rising)
    # Every reversal exceeds the tolerance, so hysteresis sees the same extremes.
    assert len(maxima) == len(minima)
    assert np.abs(x[maxima][:, None] - x[minima][None]).min() > tolerance_mm
    return len(maxima)


def test_circle_gives_two_segments_from_rightmost_to_leftmost_point():
    segments = segment_contour(load_contour("fls-circle"))  # 50 mm circle centred on (50, 50)
    assert len(segments) == 2
    for segment in segments:
        np.testing.assert_allclose(segment.notch, [75.0, 50.0], atol=0.3)
        np.testing.assert_allclose(segment.termination, [25.0, 50.0], atol=0.3)
        assert is_monotone(segment.points, 1e-9)  # exactly non-increasing, not merely within tolerance
        assert segment.length == pytest.approx(25 * math.pi, rel=0.01)
    # One goes over the top, the other under the bottom.
    assert sorted(np.sign(s.points[len(s.points) // 2, 1] - 50) for s in segments) == [-1, 1]


def test_s_curve_is_split_at_its_hand_computed_extremes():
    # x = 45 + 20 sin(2 pi y / 100) from y = 0 to 100: x is 45 at both ends (on the bottom and top edges),
    # peaks at y = 25 (x = 65) and bottoms out at y = 75 (x = 25). Cutting toward -x: from the peak down
    # to the start, from the peak up to the trough, and from the top end down to the trough.
    segments = segment_contour(load_contour("s-curve"))
    expected = [((65, 25), (45, 0)), ((65, 25), (25, 75)), ((45, 100), (25, 75))]
    assert len(segments) == len(expected)
    for segment, (notch, termination) in zip(segments, expected, strict=True):
        np.testing.assert_allclose(segment.notch, notch, atol=0.3)
        np.testing.assert_allclose(segment.termination, termination, atol=0.3)
        assert is_monotone(segment.points, 1e-9)
        y = segment.points[:, 1]
        assert (
            min(notch[1], termination[1]) - 0.3 <= y.min() and y.max() <= max(notch[1], termination[1]) + 0.3
        )


@pytest.mark.parametrize(
    ("name", "maxima"),
    [
        # The polar ones' radii as in warpcut.contours.
        ("flower-5", lambda t: 28 + 9 * np.cos(5 * t)),
        ("blob-wavy", lambda t: 32 + 3.5 * np.cos(10 * t)),
        ("flower-3", lambda t: 27 + 9 * np.cos(3 * t)),
        ("e-shape", 3),  # the tips of its three bars
        ("c-shape", 2),  # the tips of the C
        ("crescent", 2),  # its two horns
        ("kidney", 2),  # the right side and the bottom of the dent on the left
    ],
)
def test_closed_contour_gets_two_segments_per_x_maximum(name, maxima):
    if callable(maxima):
        maxima = polar_x_maxima(maxima, 1.0)
    assert maxima >= 2  # i.e. >= 4 segments, more than the single rightmost notch of a convex shape
    segments = segment_contour(BUILTINS[name])
    assert len(segments) == 2 * maxima
    assert all(is_monotone(s.points, 1.0) for s in segments)
    # Each notch is shared by the two segments that leave it.
    notches = {tuple(s.notch) for s in segments}
    assert len(notches) == maxima
    assert all(sum(np.array_equal(s.notch, n) for s in segments) == 2 for n in notches)


def test_flower_5_notches_are_its_x_maxima():
    segments = segment_contour(BUILTINS["flower-5"])
    notch_x = sorted({round(float(s.notch[0]), 1) for s in segments})
    # r = 28 + 9 cos 5t: the right petal's tip (87), the right flanks of the upper and lower petals
    # (66.5, by the analytic sample) and the valley between the two left petals (50 - 19 = 31).
    assert notch_x == pytest.approx([31.0, 66.5, 87.0], abs=0.2)


def test_ripple_on_a_circle_does_not_add_segments():
    t = np.linspace(0.0, 2 * np.pi, 720, endpoint=False)
    r = 25 + 0.2 * np.sin(60 * t)  # 0.2 mm ripple, 2.6 mm wavelength
    contour = validate("rippled", True, np.stack([50 + r * np.cos(t), 50 + r * np.sin(t)], axis=1))
    segments = segment_contour(contour)
    assert len(segments) == 2
    for segment in segments:
        assert is_monotone(segment.points, 1.0)
        assert not is_monotone(segment.points, 0.0)  # the ripple is really there
        np.testing.assert_allclose(segment.notch, [75.0, 50.0], atol=1.0)
        np.testing.assert_allclose(segment.termination, [25.0, 50.0], atol=1.0)


def test_square_with_vertical_sides_gives_two_segments_split_mid_side():
    side = np.linspace(25.0, 75.0, 101)[:-1]  # 0.5 mm apart
    const_lo, const_hi = np.full_like(side, 25.0), np.full_like(side, 75.0)
    points = np.concatenate(
        [
            np.stack([side, const_lo], axis=1),
            np.stack([const_hi, side], axis=1),
            np.stack([side[::-1] + 0.5, const_hi], axis=1),
            np.stack([const_lo, side[::-1] + 0.5], axis=1),
        ]
    )
    segments = segment_contour(validate("square", True, points))
    assert len(segments) == 2
    for segment in segments:
        # The extreme on a vertical side is the side's middle; both halves are exactly monotone.
        np.testing.assert_allclose(segment.notch, [75.0, 50.0])
        np.testing.assert_allclose(segment.termination, [25.0, 50.0])
        assert is_monotone(segment.points, 0.0)
    corners = validate("square-4", True, [[25, 25], [75, 25], [75, 75], [25, 75]])
    assert len(segment_contour(corners)) == 2


def test_slanted_side_keeps_its_outermost_end():
    # A quadrilateral whose right side leans by 0.4 mm (within the plateau band): the notch is the
    # lower-right corner, the side's true maximum, so both segments stay exactly monotone.
    ys = np.linspace(25.0, 75.0, 101)
    right = np.stack([75.0 - 0.4 * (ys - 25) / 50, ys], axis=1)
    top = np.stack([np.linspace(74.6, 25.0, 100)[1:], np.full(99, 75.0)], axis=1)
    left = np.stack([np.full(99, 25.0), np.linspace(75.0, 25.0, 100)[1:]], axis=1)
    bottom = np.stack([np.linspace(25.0, 75.0, 100)[1:-1], np.full(98, 25.0)], axis=1)
    segments = segment_contour(validate("leaning", True, np.concatenate([right, top, left, bottom])))
    assert len(segments) == 2
    for segment in segments:
        np.testing.assert_allclose(segment.notch, [75.0, 25.0])
        assert is_monotone(segment.points, 0.0)


def test_wiggle_at_an_open_end_is_absorbed_into_the_end():
    # From the bottom edge x first drifts 0.6 mm right (less than the tolerance), then the contour heads
    # left to the left edge: one segment, entered at the sheet's edge rather than at a notch 5 mm in.
    y = np.arange(0.0, 60.5, 0.5)
    x = np.where(y <= 5, 50 + 0.12 * y, 50.6 - (y - 5) * 50.6 / 55)
    contour = validate("drift", False, np.stack([x, y], axis=1))
    (segment,) = segment_contour(contour)
    np.testing.assert_allclose(segment.notch, [50.0, 0.0])
    np.testing.assert_allclose(segment.termination, [0.0, 60.0])
    assert rise(segment.points) == pytest.approx(0.6)
    # With a tolerance below the drift it is a reversal: the drift's top becomes a notch.
    assert len(segment_contour(contour, tolerance_mm=0.5)) == 2


def test_short_segment_is_merged_only_where_the_result_stays_monotone():
    # In from the right edge, a dip whose flat, slightly noisy bottom (60.0 - 60.45) is followed by a
    # 1.1 mm tooth, then out to the left edge; y rises 0.5 mm a point. The tooth reverses x by 1.1 mm
    # from the dip's lowest point, more than the tolerance, so the filter splits there; but the dip's
    # termination moves to the flat's middle (x = 60.2), from where the tooth rises only 0.9 mm.
    x = np.concatenate(
        [np.linspace(100, 61, 40), [60.2, 60.45, 60.0], np.full(6, 60.2), [61.1], np.linspace(60, 0, 40)]
    )
    contour = validate("tooth", False, np.stack([x, 20 + 0.5 * np.arange(len(x))], axis=1))
    split = segment_contour(contour, tolerance_mm=1.0, min_length_mm=0.0)
    assert [round(s.length, 1) for s in split] == [46.8, 3.0, 64.3]
    np.testing.assert_allclose(split[1].notch, [61.1, 44.5])  # the tooth's tip
    merged = segment_contour(contour, tolerance_mm=1.0, min_length_mm=5.0)
    assert len(merged) == 2
    np.testing.assert_allclose(merged[1].notch, split[1].termination)  # cut from the flat over the tooth
    assert rise(merged[1].points) == pytest.approx(0.9)
    assert all(is_monotone(s.points, 1.0) for s in merged)
    # Where merging would break the tolerance it is refused, however short the segment.
    assert len(segment_contour(contour, tolerance_mm=0.8, min_length_mm=50.0)) == 3


@pytest.mark.parametrize("name", list(BUILTINS))
def test_segments_cover_the_contour_exactly_once(name):
    contour = BUILTINS[name]
    segments = segment_contour(contour)
    chains = contour_indices(contour, segments)
    covered = np.concatenate([c[:-1] for c in chains] + ([] if contour.closed else [chains[-1][-1:]]))
    if contour.closed:
        # A rotation of the contour: every point once, the shared extremes counted once.
        assert sorted(covered.tolist()) == list(range(len(contour.points)))
        assert np.all(np.diff(covered) % len(contour.points) == 1)
    else:
        assert covered.tolist() == list(range(len(contour.points)))
    assert sum(s.length for s in segments) == pytest.approx(contour.length)
    for segment in segments:
        assert is_monotone(segment.points, 1.0)
        assert not segment.points.flags.writeable


@pytest.mark.parametrize(
    ("name", "count"),
    [("diagonal", 1), ("edge-bite", 1), ("arc-top", 1), ("arc-left", 2), ("parabola", 1), ("wave-1", 1)],
)
def test_open_contours(name, count):
    segments = segment_contour(BUILTINS[name])
    assert len(segments) == count
    # Notches are the larger-x ends.
    assert all(s.notch[0] > s.termination[0] for s in segments)


def test_closed_segments_start_at_the_rightmost_notch():
    for name in ("blob-wavy", "kidney", "crescent", "flower-5"):
        segments = segment_contour(BUILTINS[name])
        assert segments[0].notch[0] == max(s.notch[0] for s in segments)


def test_narrow_contour_is_one_segment():
    # Within tolerance in x everywhere: one pass all the way round, from the rightmost point back to it.
    t = np.linspace(0.0, 2 * np.pi, 400, endpoint=False)
    contour = validate("sliver", True, np.stack([50 + 0.4 * np.cos(t), 50 + 30 * np.sin(t)], axis=1))
    (segment,) = segment_contour(contour)
    assert len(segment.points) == len(contour.points) + 1
    np.testing.assert_array_equal(segment.notch, segment.termination)
    assert segment.notch[0] == contour.points[:, 0].max()


def test_is_monotone():
    assert is_monotone(np.array([[5.0, 0.0], [4.0, 1.0], [4.0, 2.0], [1.0, 3.0]]), 0.0)
    # A rise of 0.5 above the running minimum (3.0), though x never gets back to its start.
    wiggle = np.array([[5.0, 0.0], [3.0, 1.0], [3.5, 2.0], [1.0, 3.0]])
    assert not is_monotone(wiggle, 0.4)
    assert is_monotone(wiggle, 0.5)
    assert is_monotone(np.array([[1.0, 1.0]]), 0.0)


def test_segment_orders_exhaustive_up_to_limit():
    orders, heuristic = segment_orders(3)
    assert not heuristic
    assert len(orders) == 6 == len(set(orders))
    assert set(orders) == set(itertools.permutations(range(3)))
    assert segment_orders(1) == ([(0,)], False)
    assert len(segment_orders(6)[0]) == 720


def test_segment_orders_heuristic_beyond_limit():
    orders, heuristic = segment_orders(8)
    assert heuristic
    assert orders == [tuple(range(8)), tuple(range(7, -1, -1))]
    segments = segment_contour(BUILTINS["flower-5"])  # 8 segments
    notches = np.array([s.notch for s in segments])
    orders, heuristic = segment_orders(len(segments), notches=notches)
    assert heuristic
    assert 2 < len(orders) <= 6
    assert len(set(orders)) == len(orders)
    assert all(sorted(order) == list(range(8)) for order in orders)
    # One cuts the rightmost notches first.
    assert any(np.all(np.diff(notches[list(order), 0]) <= 0) for order in orders)


@pytest.mark.parametrize("bad", [0, 0.0, -1.0, math.nan, math.inf, True, "1"])
def test_tolerance_must_be_positive(bad):
    with pytest.raises(ValueError, match="tolerance_mm"):
        segment_contour(BUILTINS["fls-circle"], tolerance_mm=bad)


def test_argument_errors_name_the_argument():
    with pytest.raises(ValueError, match="min_length_mm"):
        segment_contour(BUILTINS["fls-circle"], min_length_mm=-1.0)
    with pytest.raises(ValueError, match="tolerance_mm"):
        is_monotone(np.zeros((2, 2)), -0.1)
    with pytest.raises(ValueError, match="points"):
        is_monotone(np.zeros(4), 1.0)
    with pytest.raises(ValueError, match="num_segments"):
        segment_orders(0)
    with pytest.raises(ValueError, match="limit"):
        segment_orders(3, limit=0)
    with pytest.raises(ValueError, match="notches"):
        segment_orders(8, notches=np.zeros((7, 2)))
