"""Tests for warpcut.contours: the built-in suite, loaders, resampling, every validation error, and which
simulation grids resolve a contour (and leave a pinch point)."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from shapely.geometry import LinearRing, LineString, Point, Polygon

from warpcut.contours import (
    Contour,
    ContourError,
    builtin_contours,
    builtin_names,
    check_resolution,
    load_contour,
    validate,
)
from warpcut.contours.polyline import arc_lengths, polyline_length, resample_polyline
from warpcut.planning import default_pinch, pinch_candidates
from warpcut.sim.config import SimConfig

BUILTINS = builtin_contours()
SQUARE = [[20.0, 20.0], [40.0, 20.0], [40.0, 40.0], [20.0, 40.0]]


def count_x_maxima(points: np.ndarray, tolerance_mm: float = 0.5) -> int:
    """Local maxima of x around a closed contour, ignoring wiggles smaller than ``tolerance_mm``.

    Each maximum is where a scissors that can only cut toward -x must start a new segment.
    """
    x = points[:, 0]
    start = int(np.argmin(x))
    # Starting at the global minimum, the cyclic sequence opens and closes in a valley.
    x = np.concatenate([np.roll(x, -start), x[start : start + 1]])
    count, rising, extreme = 0, True, x[0]
    for value in x:
        if rising and value > extreme or not rising and value < extreme:
            extreme = value
        elif abs(value - extreme) > tolerance_mm:
            count += rising
            rising, extreme = not rising, value
    return count


def write(tmp_path, filename: str, text: str):
    path = tmp_path / filename
    path.write_text(text)
    return path


# ---------------------------------------------------------------------------------------------- built-ins


def test_builtin_suite_composition():
    names = builtin_names()
    assert names[0] == "fls-circle"
    assert names == list(BUILTINS)
    assert len(names) >= 18
    assert all(re.fullmatch(r"[a-z0-9]+(-[a-z0-9]+)*", name) for name in names)
    closed = [c for c in BUILTINS.values() if c.closed]
    assert len(closed) >= 11
    assert len(BUILTINS) - len(closed) >= 7
    assert max(count_x_maxima(c.points) for c in closed) >= 3


@pytest.mark.parametrize("name", builtin_names())
def test_builtin_is_valid(name):
    contour = BUILTINS[name]
    again = validate(contour.name, contour.closed, contour.points, contour.sheet_size)
    np.testing.assert_array_equal(again.points, contour.points)
    assert math.isfinite(contour.length) and contour.length > 0
    assert math.isfinite(contour.area_mm2) and contour.area_mm2 > 0
    steps = np.linalg.norm(np.diff(contour.points, axis=0), axis=1)
    assert steps.max() <= 1.0
    x, y = contour.points.T
    if contour.closed:
        assert LinearRing(contour.points).is_ccw
        assert min(x.min(), y.min(), 100 - x.max(), 100 - y.max()) >= 8.0
        region = contour.intended_region()
        # An opening of radius 1.5 mm removes anything thinner than 3 mm.
        opened = region.buffer(-1.5).buffer(1.5)
        assert opened.geom_type == "Polygon"
        assert region.area - opened.area < 0.01 * region.area
    else:
        for end in (contour.points[0], contour.points[-1]):
            assert min(end[0], 100 - end[0], end[1], 100 - end[1]) == 0.0
        assert contour.area_mm2 <= 5000.0


def test_fls_circle():
    circle = load_contour("fls-circle")
    assert circle is BUILTINS["fls-circle"]
    assert circle.closed
    assert circle.length == pytest.approx(50 * math.pi, abs=0.05)
    assert circle.area_mm2 == pytest.approx(25**2 * math.pi, abs=0.5)
    np.testing.assert_allclose(circle.centroid, [50.0, 50.0], atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(circle.points - 50.0, axis=1), 25.0, atol=1e-3)


def test_x_maxima_counter():
    assert count_x_maxima(BUILTINS["fls-circle"].points) == 1
    assert count_x_maxima(BUILTINS["c-shape"].points) == 2
    assert count_x_maxima(BUILTINS["e-shape"].points) == 3


def test_builtins_scale_with_the_sheet():
    wide = builtin_contours((200.0, 100.0))
    assert wide["fls-circle"].area_mm2 == pytest.approx(2 * BUILTINS["fls-circle"].area_mm2, rel=1e-9)
    np.testing.assert_allclose(wide["fls-circle"].centroid, [100.0, 50.0], atol=1e-6)
    assert wide["wave-1"].points[-1].tolist() == [200.0, 45.0]
    assert load_contour("fls-circle", (200.0, 100.0)).sheet_size == (200.0, 100.0)


# --------------------------------------------------------------------------------------- normalisation


def test_closed_contour_is_made_counter_clockwise_keeping_its_start():
    clockwise = SQUARE[::-1]
    contour = validate("square", True, clockwise)
    assert LinearRing(contour.points).is_ccw
    assert contour.points[0].tolist() == clockwise[0]
    assert contour.area_mm2 == pytest.approx(400.0)
    np.testing.assert_allclose(contour.centroid, [30.0, 30.0])
    assert contour.length == pytest.approx(80.0)


def test_tiny_contour_far_from_the_origin_is_made_counter_clockwise():
    # Found by fuzzing: the shoelace formula on raw coordinates got this 1e-8 mm triangle's sign wrong.
    clockwise = [[9.99999990100075, 4.0000000141120005], [9.999999906354331, 3.999999964921677]]
    clockwise.append([9.999999950226726, 3.999999913266954])
    assert LinearRing(validate("speck", True, clockwise).points).is_ccw


def test_repeated_points_are_removed():
    contour = validate("square", True, [SQUARE[0], SQUARE[0], *SQUARE[1:], SQUARE[0]])
    np.testing.assert_array_equal(contour.points, SQUARE)


def test_points_are_read_only_and_the_input_untouched():
    given = np.array(SQUARE[::-1])
    contour = validate("square", True, given)
    np.testing.assert_array_equal(given, SQUARE[::-1])
    with pytest.raises(ValueError):
        contour.points[0, 0] = 1.0


def test_open_contour_end_near_an_edge_is_extended():
    contour = validate("cut", False, [[3.0, 30.0], [50.0, 60.0], [97.5, 30.0]])
    np.testing.assert_array_equal(contour.points[[0, 1, -2, -1]], [[0, 30], [3, 30], [97.5, 30], [100, 30]])


def test_open_contour_end_too_far_from_an_edge():
    with pytest.raises(ContourError, match=r"end \(90, 50\) is 10 mm from the nearest edge; move it"):
        validate("cut", False, [[0.0, 30.0], [50.0, 60.0], [90.0, 50.0]])


def test_open_contour_region_is_the_smaller_piece():
    contour = validate("strip", False, [[30.0, 0.0], [30.0, 50.0], [30.0, 100.0]])
    assert contour.area_mm2 == pytest.approx(3000.0)
    np.testing.assert_allclose(contour.centroid, [15.0, 50.0])
    assert contour.length == pytest.approx(100.0)


# -------------------------------------------------------------------------------------------- resample


@pytest.mark.parametrize("closed", [True, False])
def test_resample_is_uniform_in_arc_length(closed):
    points = [[0.0, 10.0], [40.0, 10.0], [60.0, 50.0], [100.0, 70.0]] if not closed else SQUARE
    contour = validate("poly", closed, points)
    samples = contour.resample(1.3)
    line = LineString(np.vstack([contour.points, contour.points[:1]]) if closed else contour.points)
    arc = np.array([line.project(Point(p)) for p in samples])
    np.testing.assert_array_equal(samples[0], contour.points[0])
    steps = np.diff(arc)
    np.testing.assert_allclose(steps[:-1], 1.3, atol=1e-9)
    assert 0 < steps[-1] <= 1.3 + 1e-9
    if closed:
        assert contour.length - arc[-1] <= 1.3
        assert not np.allclose(samples[-1], samples[0])
    else:
        np.testing.assert_array_equal(samples[-1], contour.points[-1])


def test_resample_circle_chords():
    samples = BUILTINS["fls-circle"].resample(2.0)
    chords = np.linalg.norm(np.diff(samples, axis=0), axis=1)
    np.testing.assert_allclose(chords, 2.0, atol=0.01)


def test_resample_rejects_a_bad_spacing():
    with pytest.raises(ContourError, match="spacing_mm must be a positive number"):
        BUILTINS["fls-circle"].resample(0.0)


def test_arc_lengths_open_and_closed_in_any_dimension():
    square = np.array(SQUARE)
    np.testing.assert_array_equal(arc_lengths(square), [0.0, 20.0, 40.0, 60.0])
    np.testing.assert_array_equal(arc_lengths(square, closed=True), [0.0, 20.0, 40.0, 60.0, 80.0])
    assert polyline_length(square) == 60.0
    world = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0], [3.0, 4.0, 12.0]])
    np.testing.assert_array_equal(arc_lengths(world), [0.0, 5.0, 17.0])
    assert polyline_length(world) == 17.0


def test_resample_polyline_open_closed_and_along_another_arc():
    line = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 2.5]])
    np.testing.assert_array_equal(resample_polyline(line, 1.0)[:, 2], [0.0, 1.0, 2.0, 2.5])
    # Exactly divisible, up to round-off: no extra sample a hair before the end or the start.
    assert 2.1 / 0.3 > 7
    np.testing.assert_allclose(resample_polyline(np.array([[0.0], [2.1]]), 0.3)[:, 0], np.linspace(0, 2.1, 8))
    ring = resample_polyline(np.array(SQUARE), 20.0, closed=True)
    np.testing.assert_array_equal(ring, SQUARE)
    # Sample a parallel polyline where the measured one is evenly spaced.
    world = np.array([[0.0, 0.0], [1.0, 0.0], [4.0, 0.0]])
    material = np.array([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]])
    along = resample_polyline(material, 2.0, arc=arc_lengths(world))
    np.testing.assert_allclose(along[:, 0], [0.0, 8 / 3, 4.0])
    with pytest.raises(ValueError, match="arc: expected shape"):
        resample_polyline(material, 2.0, closed=True, arc=arc_lengths(world))
    with pytest.raises(ValueError, match="spacing"):
        resample_polyline(material, 0.0)


# --------------------------------------------------------------------------------------------- loaders


def test_json_round_trip(tmp_path):
    for name in ("kidney", "s-curve"):
        original = BUILTINS[name]
        path = write(tmp_path, f"{name}.json", json.dumps(original.to_json()))
        loaded = load_contour(path)
        assert isinstance(loaded, Contour)
        assert (loaded.name, loaded.closed) == (original.name, original.closed)
        np.testing.assert_array_equal(loaded.points, original.points)


def test_json_name_defaults_to_file_stem(tmp_path):
    path = write(tmp_path, "my-square.json", json.dumps({"closed": True, "points": SQUARE}))
    assert load_contour(str(path)).name == "my-square"


SVG_CLOSED = """<svg xmlns="http://www.w3.org/2000/svg" width="100mm" height="100mm" viewBox="0 0 100 100">
  <g><path d="M 30 40 L 60 40 C 70 40 70 70 60 70 L 30 70 Z" style="fill:none"/></g>
</svg>"""


def test_svg_closed_with_curve(tmp_path):
    contour = load_contour(write(tmp_path, "shape.svg", SVG_CLOSED))
    assert contour.closed and contour.name == "shape"
    # y is flipped: SVG y = 40 is 60 mm above the sheet's lower edge.
    assert contour.points[0].tolist() == [30.0, 60.0]
    np.testing.assert_allclose(contour.points.min(axis=0), [30.0, 30.0])
    np.testing.assert_allclose(contour.points.max(axis=0), [67.5, 60.0])
    steps = np.linalg.norm(np.diff(contour.points, axis=0), axis=1)
    assert steps[steps < 29].max() <= 0.5  # the curve is flattened; the straight sides stay whole
    # The 30 x 30 rectangle plus the cubic's bulge beyond x = 60: 900 * 6 * integral(t^2 (1 - t)^2) = 180.
    assert contour.area_mm2 == pytest.approx(900.0 + 180.0, rel=1e-4)


def test_svg_open_and_relative_commands(tmp_path):
    contour = load_contour(write(tmp_path, "cut.svg", '<svg><path d="m 0,70 h 40 v 20 l 60,0"/></svg>'))
    assert not contour.closed
    np.testing.assert_array_equal(contour.points, [[0, 30], [40, 30], [40, 10], [100, 10]])


def test_svg_viewbox_origin_and_smooth_curves(tmp_path):
    text = '<svg viewBox="-5 20 100 100"><path d="M 10 40 Q 30 20 50 40 T 90 40 L 90 90 L 10 90 z"/></svg>'
    contour = load_contour(write(tmp_path, "wave.svg", text))
    np.testing.assert_allclose(contour.points.min(axis=0), [15.0, 30.0])
    np.testing.assert_allclose(contour.points.max(axis=0), [95.0, 90.0], atol=1e-9)
    # T reflects the previous control point, so the second bump dips below the first's baseline.
    assert contour.points[:, 1].max() == pytest.approx(90.0)
    assert np.sum(contour.points[:, 1] < 80.0 - 1e-9) > 0


# ------------------------------------------------------------------------------------------- errors


def test_fewer_than_three_distinct_points():
    with pytest.raises(ContourError, match="fewer than 3 distinct points"):
        validate("tiny", True, [[10.0, 10.0], [10.0, 10.0], [20.0, 20.0], [10.0, 10.0]])


def test_nan_point():
    with pytest.raises(ContourError, match=r"point 2 is \[nan, 30.0\], which is not finite"):
        validate("bad", True, [[10.0, 10.0], [20.0, 10.0], [np.nan, 30.0]])


def test_infinite_point():
    with pytest.raises(ContourError, match=r"point 0 is \[inf, 10.0\], which is not finite"):
        validate("bad", True, [[np.inf, 10.0], [20.0, 10.0], [20.0, 30.0]])


def test_self_intersection_bow_tie():
    bow_tie = [[20.0, 20.0], [40.0, 40.0], [40.0, 20.0], [20.0, 40.0]]
    with pytest.raises(ContourError, match=r"'bow-tie': self-intersection near \(30, 30\)"):
        validate("bow-tie", True, bow_tie)


def test_self_intersection_open():
    loop = [[0.0, 20.0], [60.0, 20.0], [40.0, 40.0], [40.0, 0.0]]
    with pytest.raises(ContourError, match=r"self-intersection near \(40, 20\)"):
        validate("loop", False, loop)


def test_closed_contour_leaving_the_sheet():
    with pytest.raises(ContourError, match=r"must lie inside the sheet, but it leaves it by 5 mm at point 1"):
        validate("big", True, [[50.0, 50.0], [105.0, 50.0], [50.0, 90.0]])


def test_open_contour_touching_an_edge_in_between():
    with pytest.raises(ContourError, match="exactly two pieces, but it splits it into 3"):
        validate("zigzag", False, [[0.0, 10.0], [50.0, 0.0], [100.0, 10.0]])


def test_round_off_from_an_edge_is_on_it():
    # Found by fuzzing: a point 1e-300 mm from an edge touches it (and would upset shapely's geometry).
    with pytest.raises(ContourError, match="exactly two pieces, but it splits it into 3"):
        validate("zigzag", False, [[0.0, 10.0], [50.0, 1e-300], [100.0, 10.0]])
    near = validate("cut", False, [[1e-7, 10.0], [50.0, 50.0], [100.0 - 1e-9, 10.0]])
    np.testing.assert_array_equal(near.points, [[0.0, 10.0], [50.0, 50.0], [100.0, 10.0]])


def test_closed_must_be_boolean():
    with pytest.raises(ContourError, match="'closed' must be true or false"):
        validate("square", "yes", SQUARE)


@pytest.mark.parametrize("points", [[[1.0, 2.0, 3.0]] * 3, [["1", "2"]] * 3, [[1.0, 2.0], [3.0]]])
def test_points_must_be_an_n_by_2_array_of_numbers(points):
    with pytest.raises(ContourError, match=r"points must be an \(N, 2\) array of numbers"):
        validate("bad", True, points)


def test_unknown_name_lists_the_built_ins():
    with pytest.raises(ContourError, match=r"unknown contour 'xyz': not a built-in name \(known: fls-circle"):
        load_contour("xyz")


def test_unsupported_file_type(tmp_path):
    with pytest.raises(ContourError, match=r"'.txt' is not a supported file type; give a built-in name"):
        load_contour(write(tmp_path, "shape.txt", "M 0 0"))
    (tmp_path / "folder.json").mkdir()
    with pytest.raises(ContourError, match=r"and a directory, not a contour file; give a built-in name"):
        load_contour(tmp_path / "folder.json")


def test_svg_with_several_subpaths(tmp_path):
    path = write(tmp_path, "two.svg", '<svg><path d="M 20 20 h 10 v 10 z M 50 50 h 10 v 10 z"/></svg>')
    with pytest.raises(ContourError, match="several subpaths; give one contour per file"):
        load_contour(path)


def centre(contour) -> np.ndarray:
    return np.asarray(Polygon(contour.points).centroid.coords[0])


def test_svg_arcs_are_flattened(tmp_path):
    # A half disc of radius 20 above y_svg = 50 (sweep flag 1: clockwise on the page, through y_svg = 30).
    path = write(tmp_path, "arc.svg", '<svg><path d="M 30 50 A 20 20 0 0 1 70 50 Z"/></svg>')
    contour = load_contour(path)
    assert contour.closed and contour.area_mm2 == pytest.approx(math.pi * 400 / 2, rel=1e-3)
    np.testing.assert_allclose(contour.points.max(axis=0), [70.0, 70.0], atol=1e-9)
    np.testing.assert_allclose(contour.points.min(axis=0), [30.0, 50.0], atol=1e-9)
    steps = np.linalg.norm(np.diff(contour.points, axis=0), axis=1)
    assert steps[steps < 39].max() <= 0.5  # the arc is flattened; the straight side stays whole


@pytest.mark.parametrize(
    ("element", "closed", "area", "centroid"),
    [
        ('<circle cx="50" cy="40" r="20"/>', True, math.pi * 400, (50, 60)),
        ('<ellipse cx="50" cy="50" rx="30" ry="10"/>', True, math.pi * 300, (50, 50)),
        ('<rect x="20" y="30" width="40" height="20"/>', True, 800, (40, 60)),
        ('<rect x="20" y="30" width="40" height="20" rx="5"/>', True, 800 - (4 - math.pi) * 25, (40, 60)),
        ('<polygon points="20,20 80,20 50,70"/>', True, 1500, (50, 100 - 110 / 3)),
        ('<polyline points="0,50 50,40 100,50"/>', False, None, None),
    ],
    ids=["circle", "ellipse", "rect", "rounded-rect", "polygon", "polyline"],
)
def test_svg_shapes(tmp_path, element, closed, area, centroid):
    contour = load_contour(
        write(tmp_path, "shape.svg", f'<svg xmlns="http://www.w3.org/2000/svg">{element}</svg>')
    )
    assert contour.closed is closed
    if closed:
        assert contour.area_mm2 == pytest.approx(area, rel=1e-3)
        np.testing.assert_allclose(centre(contour), centroid, atol=1e-6)
    else:
        np.testing.assert_allclose(contour.points, [[0, 50], [50, 60], [100, 50]])


def test_svg_transforms_apply(tmp_path):
    text = '<svg><g transform="translate(5)"><path d="M 20 20 h 9 v 9 z"/></g></svg>'
    contour = load_contour(write(tmp_path, "moved.svg", text))
    np.testing.assert_allclose(contour.points.min(axis=0), [25.0, 71.0])
    # Nested: scale by 2 about the origin, then rotate 90 degrees about (50, 50) (page coordinates).
    text = (
        '<svg><g transform="rotate(90 50 50)"><g transform="scale(2)">'
        '<rect x="10" y="10" width="10" height="5"/></g></g></svg>'
    )
    contour = load_contour(write(tmp_path, "turned.svg", text))
    # The rect spans page x 20..40, y 20..30; turned: x 70..80, y 20..40; on the sheet y 60..80.
    np.testing.assert_allclose(contour.points.min(axis=0), [70.0, 60.0], atol=1e-9)
    np.testing.assert_allclose(contour.points.max(axis=0), [80.0, 80.0], atol=1e-9)


def test_svg_use_nested_svg_and_hidden_shapes(tmp_path):
    text = (
        '<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink">'
        '<defs><circle id="c" cx="20" cy="20" r="10"/></defs>'
        '<rect x="1" y="1" width="5" height="5" style="display:none"/>'
        '<use xlink:href="#c" x="30" y="10"/></svg>'
    )
    contour = load_contour(write(tmp_path, "use.svg", text))
    np.testing.assert_allclose(centre(contour), [50.0, 70.0], atol=1e-6)
    text = (
        '<svg><svg x="10" y="10" width="40" height="40" viewBox="0 0 10 10">'
        '<rect x="2" y="2" width="5" height="5"/></svg></svg>'
    )
    contour = load_contour(write(tmp_path, "nested.svg", text))
    np.testing.assert_allclose(contour.points.min(axis=0), [18.0, 62.0], atol=1e-9)
    assert contour.area_mm2 == pytest.approx(400.0)


def test_a_contour_too_dense_to_plan_is_refused_in_seconds(tmp_path):
    """A contour of 200,000 points (8 MB, under the file cap) would take many minutes to plan: it is refused
    as it is loaded, in seconds, with the spacing to resample it at; 10,000 points still load."""
    import time

    from warpcut.contours.contour import MAX_POINTS

    def circle(n):
        t = np.linspace(0, 2 * np.pi, n, endpoint=False)
        return np.stack([50 + 20 * np.cos(t), 50 + 20 * np.sin(t)], axis=1)

    path = tmp_path / "dense.json"
    path.write_text(json.dumps({"name": "dense", "closed": True, "points": circle(200_000).tolist()}))
    start = time.perf_counter()
    with pytest.raises(ContourError, match=r"200,000 points, more than the 10,000 .* a point every 0.5 mm"):
        load_contour(path)
    assert time.perf_counter() - start < 10
    assert len(validate("ok", True, circle(MAX_POINTS)).points) == MAX_POINTS
    lines = " ".join(f"L{x:.3f},{y:.3f}" for x, y in circle(100_000)[1:])  # 2.6 MB: seconds of parsing
    svg = write(tmp_path, "dense.svg", f'<svg><path d="M70,50 {lines} Z"/></svg>')
    start = time.perf_counter()
    with pytest.raises(ContourError, match=r"a <path> holds 200,000 numbers, more than 10,000 points' worth"):
        load_contour(svg)
    assert time.perf_counter() - start < 2


def test_svg_sizes_it_cannot_read_are_named_not_misread(tmp_path):
    """A root size in a unit SVG does not have (``0.1m``) is refused, not read as user units; a viewBox too
    small to compute with (1e-300: its lengths' squares underflow) is named as such, not reported as a
    self-intersection."""
    circle = '<circle cx="50" cy="50" r="20"/>'
    for root, message in [
        (
            'width="0.1m" height="0.1m" viewBox="0 0 100 100"',
            r"the svg's width '0.1m' has a unit SVG does not",
        ),
        ('viewBox="0 0 1e-300 1e-300" width="100mm" height="100mm"', r"too small to compute with"),
    ]:
        with pytest.raises(ContourError, match=message):
            load_contour(write(tmp_path, "sized.svg", f"<svg {root}>{circle}</svg>"))
    for unit in ("px", "em"):  # not physical: a user unit is a mm, as before
        contour = load_contour(
            write(tmp_path, "screen.svg", f'<svg width="100{unit}" height="100{unit}">{circle}</svg>')
        )
        assert contour.area_mm2 == pytest.approx(np.pi * 400, rel=1e-3)


def test_svg_use_bombs_are_refused_before_they_expand(tmp_path):
    """Nested ``<use>`` (7 levels of 10 in 1.4 kB: ten million circles) are refused in one line, in well
    under a second, before the parser instantiates them (a ``<use>`` inside what it refers to: above)."""
    import time

    levels = ['<circle id="u0" cx="50" cy="50" r="10"/>'] + [
        f'<g id="u{k}">' + f'<use href="#u{k - 1}"/>' * 10 + "</g>" for k in range(1, 8)
    ]
    bomb = f'<svg xmlns="http://www.w3.org/2000/svg"><defs>{"".join(levels)}</defs><use href="#u7"/></svg>'
    start = time.perf_counter()
    with pytest.raises(ContourError, match="<use> references expand to more than 20,000 elements"):
        load_contour(write(tmp_path, "bomb.svg", bomb))
    assert time.perf_counter() - start < 1


@pytest.mark.parametrize(
    ("root", "lower_left", "side"),
    [
        # A physical width and height: the viewBox maps onto them (here 2 user units per mm).
        ('width="50mm" height="50mm" viewBox="0 0 100 100"', (10.0, 80.0), 5.0),
        ('width="5cm" height="5cm" viewBox="0 0 100 100"', (10.0, 80.0), 5.0),
        # preserveAspectRatio (default xMidYMid meet): 0.5 mm per unit, centred across the 100 mm width.
        ('width="100mm" height="50mm" viewBox="0 0 100 100"', (35.0, 80.0), 5.0),
        (
            'width="100mm" height="50mm" viewBox="0 0 100 100" preserveAspectRatio="none"',
            (20.0, 80.0),
            (10, 5),
        ),
        (
            'width="100mm" height="50mm" viewBox="0 0 100 100" preserveAspectRatio="xMinYMin"',
            (10.0, 80.0),
            5.0,
        ),
        # Not physical (px, plain numbers, no viewBox): a user unit is a mm, the viewBox's origin the corner.
        ('width="50px" height="50px" viewBox="0 0 100 100"', (20.0, 60.0), 10.0),
        ('width="50" height="50" viewBox="-10 0 100 100"', (30.0, 60.0), 10.0),
        ('width="50mm" height="50mm"', (20.0, 60.0), 10.0),
    ],
)
def test_svg_units(tmp_path, root, lower_left, side):
    text = (
        f'<svg xmlns="http://www.w3.org/2000/svg" {root}><rect x="20" y="30" width="10" height="10"/></svg>'
    )
    contour = load_contour(write(tmp_path, "units.svg", text))
    np.testing.assert_allclose(contour.points.min(axis=0), lower_left, atol=1e-9)
    np.testing.assert_allclose(np.ptp(contour.points, axis=0), np.broadcast_to(side, 2), atol=1e-9)


def test_svg_lengths_with_units_inside(tmp_path):
    # Without a physical size, a length in mm is that many mm; with one, CSS's 96 px per inch applies.
    contour = load_contour(write(tmp_path, "r.svg", '<svg><circle cx="50" cy="50" r="5mm"/></svg>'))
    assert contour.area_mm2 == pytest.approx(math.pi * 25, rel=2e-3)  # flattened: a polygon inside
    text = '<svg width="100mm" height="100mm" viewBox="0 0 100 100"><circle cx="50" cy="50" r="0.1in"/></svg>'
    contour = load_contour(write(tmp_path, "in.svg", text))
    assert contour.area_mm2 == pytest.approx(math.pi * 9.6**2, rel=1e-3)


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (
            '<path d="M 10 10 L 20"/>',
            r"cannot read the path data at character \d+ .*: a command is cut short",
        ),
        ('<path d="M 10 10 X 20 20"/>', r"cannot read the path data at character 8 \(near 'X 20 20'\)"),
        ('<path d="M 10 10 L 20 20 30 10 Z 40 40"/>', "cannot read the path data"),
        (
            '<path d="L 10 10 20 20 30 10 Z"/>',
            r"path data must start with a moveto \(M or m\), not 'L 10 10 20 2'",
        ),
        ('<text x="5" y="5">a</text>', r"no shape to read \(<path>, <circle>"),
        ('<defs><circle cx="50" cy="50" r="10"/></defs>', "no shape to read"),
        (
            '<g id="a"><use xmlns:xlink="http://www.w3.org/1999/xlink" xlink:href="#a"/></g>',
            "a <use> refers to an element that holds it; draw it out",
        ),
        ('<circle cx="50" cy="50" r="1e100"/>', r"a curve of the path leaves the sheet by 1e\+100 mm"),
        (
            '<circle cx="50" cy="50" r="1e300"/>',
            "the path reaches a coordinate too large to be a number of mm",
        ),
        (
            '<ellipse cx="50" cy="50" rx="1e999" ry="5"/>',
            "the path reaches a coordinate too large to be a number of mm",
        ),
        (
            '<g transform="scale(1e100)"><circle cx="50" cy="50" r="10"/></g>',
            "a curve of the path leaves the sheet by 6e\\+101 mm",
        ),
        ('<circle cx="50" cy="50" r="-20"/>', r"<circle> r='-20' is negative; a circle's r must be >= 0"),
        ('<rect x="5" y="5" width="abc" height="5"/>', r"<rect> width='abc' is not a length"),
        (
            '<g transform="rotate(abc)"><circle cx="50" cy="50" r="10"/></g>',
            r"<g> transform='rotate\(abc\)' cannot be read; give matrix\(\), translate\(\)",
        ),
        (
            '<g transform="translate(5-3) scale(0)"><circle cx="50" cy="50" r="10"/></g>',
            r"<g> transform='translate\(5-3\) scale\(0\)' collapses the drawing to a line or a point",
        ),
    ],
    ids=[
        "cut-short",
        "unknown-command",
        "after-close",
        "no-moveto",
        "text",
        "defs",
        "recursive-use",
        "huge-circle",
        "overflowing-circle",
        "infinite-ellipse",
        "huge-transform",
        "negative-radius",
        "unreadable-width",
        "unreadable-transform",
        "zero-scale",
    ],
)
def test_svg_errors_name_the_file_on_one_line(tmp_path, body, message):
    path = write(tmp_path, "bad.svg", f"<svg>{body}</svg>")
    with pytest.raises(ContourError, match=rf"^contour file '{re.escape(str(path))}': {message}") as caught:
        load_contour(path)
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize(
    ("root", "message"),
    [
        ('width="0mm" height="50mm" viewBox="0 0 10 10"', r"the svg's width '0mm' must be a positive length"),
        ('width="50mm" height="50mm" viewBox="0 0 0 10"', r"viewBox '0 0 0 10' has a width or height <= 0"),
    ],
)
def test_svg_bad_physical_size(tmp_path, root, message):
    path = write(tmp_path, "size.svg", f'<svg {root}><path d="M 1 1 h 5 v 5 z"/></svg>')
    with pytest.raises(ContourError, match=message):
        load_contour(path)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"points": SQUARE}, "field 'closed' is required and must be true or false"),
        ({"closed": "yes", "points": SQUARE}, "field 'closed' is required"),
        ({"closed": True}, "field 'points' is required"),
        ({"closed": True, "points": [[1, 2], [3, "4"], [5, 6]]}, "field 'points' is required"),
        ({"name": 7, "closed": True, "points": SQUARE}, "field 'name' must be a non-empty string"),
        ([1, 2], "expected a JSON object"),
    ],
)
def test_bad_json_field(tmp_path, data, message):
    path = write(tmp_path, "bad.json", json.dumps(data))
    with pytest.raises(ContourError, match=message):
        load_contour(path)


def test_closed_contour_on_the_sheet_boundary_is_refused(tmp_path):
    sheet = [[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0]]
    with pytest.raises(
        ContourError, match=r"material all round it to clip and hold, but point 0 \(0, 0\) is on"
    ):
        validate("sheet", True, sheet)
    # One side along an edge is refused too: there is nothing to cut there.
    with pytest.raises(ContourError, match=r"point 1 \(100, 20\) is on the sheet's edge \(2 such point"):
        validate("bite", True, [[60.0, 20.0], [100.0, 20.0], [100.0, 40.0], [60.0, 40.0]])
    path = write(tmp_path, "sheet.json", json.dumps({"closed": True, "points": sheet}))
    with pytest.raises(
        ContourError, match=rf"^contour file '{re.escape(str(path))}': contour 'sheet': a closed"
    ):
        load_contour(path)


def test_json_empty_points_names_the_file_and_field(tmp_path):
    path = write(tmp_path, "empty.json", json.dumps({"closed": True, "points": []}))
    with pytest.raises(ContourError) as caught:
        load_contour(path)
    assert str(caught.value) == (
        f"contour file {str(path)!r}: field 'points' has 0 point(s); give at least 3 [x_mm, y_mm] pairs"
    )
    with pytest.raises(ContourError, match="fewer than 3 distinct points"):
        validate("empty", False, np.zeros((0, 2)))


def test_json_number_out_of_range(tmp_path):
    path = write(
        tmp_path, "huge.json", '{"closed": true, "points": [[1' + "0" * 400 + ", 1], [2, 3], [4, 5]]}"
    )
    with pytest.raises(ContourError, match="field 'points' has a number too large"):
        load_contour(path)
    path = write(tmp_path, "inf.json", '{"closed": true, "points": [[1e999, 1], [2, 3], [4, 5]]}')
    with pytest.raises(
        ContourError, match=r"inf.json': contour 'inf': point 0 is \[inf, 1.0\], which is not fin"
    ):
        load_contour(path)


def test_deeply_nested_json_is_a_read_error(tmp_path):
    path = write(tmp_path, "deep.json", "[" * 100_000 + "]" * 100_000)
    with pytest.raises(ContourError, match="deep.json': cannot read it as JSON"):
        load_contour(path)


@pytest.mark.parametrize(
    ("d", "message"),
    [
        (
            "M 10 10 C 1e300 0 0 1e300 10 20 Z",
            r"a curve of the path leaves the sheet by 4.44e\+299 mm, reaching",
        ),
        ("M 50 50 Q 1e308 -1e308 60 60 L 50 60 Z", r"a curve of the path leaves the sheet by 5e\+307 mm"),
        ("M 10 10 C 1e999 0 0 10 10 20 Z", "the path reaches a coordinate too large to be a number of mm"),
        ("M 1e308 10 l 1e308 0 L 10 20 Z", "the path reaches a coordinate too large to be a number of mm"),
    ],
)
def test_svg_huge_coordinates_are_refused_before_flattening(tmp_path, d, message):
    path = write(tmp_path, "huge.svg", f'<svg><path d="{d}"/></svg>')
    with pytest.raises(ContourError, match=rf"^contour file '{re.escape(str(path))}': {message}"):
        load_contour(path)


def test_svg_curve_with_control_points_off_the_sheet(tmp_path):
    # The control points lie 6 mm below the sheet (SVG y = 106), the curve dips to 0.5 mm above its edge.
    text = '<svg><path d="M 20 80 C 20 106 80 106 80 80 Z"/></svg>'
    contour = load_contour(write(tmp_path, "dip.svg", text))
    assert contour.points[:, 1].min() == pytest.approx(0.5, abs=1e-3)
    # A curve leaving the sheet by less than a chord is flattened, and validate() judges its points.
    path = write(tmp_path, "over.svg", '<svg><path d="M 20 80 C 20 107.2 80 107.2 80 80 Z"/></svg>')
    with pytest.raises(
        ContourError, match=r"over.svg': contour 'over': a closed contour must lie inside the sheet"
    ):
        load_contour(path)


@pytest.mark.parametrize("view_box", ["5", "0 0 nan 100", "a b c d", "0 0 100"])
def test_svg_bad_viewbox(tmp_path, view_box):
    path = write(tmp_path, "box.svg", f'<svg viewBox="{view_box}"><path d="M 10 10 h 20 v 20 z"/></svg>')
    with pytest.raises(ContourError, match="cannot read viewBox .*; give four numbers"):
        load_contour(path)


def test_svg_unknown_encoding_is_a_read_error(tmp_path):
    path = write(tmp_path, "enc.svg", '<?xml version="1.0" encoding="no-such"?><svg/>')
    with pytest.raises(ContourError, match="enc.svg': cannot read it as SVG/XML"):
        load_contour(path)


# ------------------------------------------------------------------------------------------- resolution

DEFAULT_SPACING = SimConfig().spacing_mm


def test_builtin_suite_is_resolved_at_the_default_resolution():
    for contour in BUILTINS.values():
        check_resolution(contour, DEFAULT_SPACING)


def test_sliver_is_too_small_for_the_grid():
    sliver = validate("sliver", True, [[10.0, 10.0], [90.0, 10.0], [50.0, 10.5]])
    with pytest.raises(ContourError) as caught:
        check_resolution(sliver, DEFAULT_SPACING)
    message = str(caught.value)
    assert message.startswith(
        "contour 'sliver': too small for the simulation grid: the region it cuts out is "
    )
    assert "at resolution 25 x 25, 4.17 x 4.17 mm between vertices," in message
    assert message.endswith("no resolution up to 100 resolves it: enlarge the contour")
    sliver = validate("sliver", True, [[10.0, 10.0], [90.0, 10.0], [50.0, 13.0]])
    message = str(pytest.raises(ContourError, check_resolution, sliver, DEFAULT_SPACING).value)
    finer = int(re.search(r"use resolution (\d+) or finer, or enlarge the contour$", message).group(1))
    check_resolution(sliver, 100.0 / (finer - 1))  # the resolution it names resolves it...
    with pytest.raises(ContourError):
        check_resolution(sliver, 100.0 / (finer - 2))  # ...and is the coarsest that does


def test_small_square_needs_a_finer_grid():
    square = validate("dot", True, [[50.0, 50.0], [53.0, 50.0], [53.0, 53.0], [50.0, 53.0]])
    with pytest.raises(
        ContourError, match=r"at most 3 mm wide with an area of 9 mm\^2.*use resolution 35 or finer"
    ):
        check_resolution(square, DEFAULT_SPACING)
    check_resolution(square, 100.0 / 34)
    # A non-square grid: the coarser axis decides.
    with pytest.raises(ContourError, match=r"at resolution 40 x 20, 2.56 x 5.26 mm between vertices"):
        check_resolution(square, (100.0 / 39, 100.0 / 19))


def test_too_little_material_left_round_the_contour():
    frame = validate("frame", True, [[2.0, 2.0], [98.0, 2.0], [98.0, 98.0], [2.0, 98.0]])
    with pytest.raises(
        ContourError, match="the rest of the sheet is at most .* move it away from the sheet's edges"
    ):
        check_resolution(frame, DEFAULT_SPACING)
    check_resolution(frame, 1.0)


@pytest.mark.parametrize("spacing", [0.0, -1.0, math.inf, math.nan, (1.0, 2.0, 3.0), "4"])
def test_check_resolution_rejects_a_bad_spacing(spacing):
    with pytest.raises(ContourError, match="spacing_mm: "):
        check_resolution(BUILTINS["fls-circle"], spacing)


def test_coarse_grid_blames_the_resolution_for_no_pinch_point():
    circle = BUILTINS["fls-circle"]
    coarse = SimConfig(resolution=5)
    expected = (
        r"^resolution: 5 is too coarse to pinch the sheet for contour 'fls-circle': .* use resolution 12 or"
    )
    with pytest.raises(ValueError, match=expected):
        pinch_candidates(circle, coarse, num=4)
    with pytest.raises(ValueError, match=expected):
        default_pinch(circle, coarse)
    assert len(pinch_candidates(circle, SimConfig(resolution=12), num=4))
