"""Property-based tests of the contour loaders: any file either loads to a valid contour or fails with a
one-line ValueError naming the file, never another exception.

The inputs cover random point lists (NaN, inf, huge and tiny values, integers beyond float range,
duplicates, self-intersections, shapes from sub-micrometre to kilometres), wrong types and missing fields,
arbitrary JSON, and random SVG path data. Last, :func:`check_resolution` refuses a contour on one line
and names a resolution that resolves it. ``HYPOTHESIS_PROFILE=long`` runs 1000 examples per test
(tests/conftest.py).
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from shapely.geometry import LinearRing, LineString

from warpcut.contours import (
    Contour,
    ContourError,
    check_resolution,
    contour_from_json,
    load_contour,
    validate,
)

SHEET = 100.0


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """One folder for the module: hypothesis runs a test many times, but builds function fixtures once."""
    return tmp_path_factory.mktemp("fuzz")


def load(folder, filename: str, text: str | bytes) -> Contour | None:
    """Write a contour file and load it; None for a refused file, whose error must name it on one line."""
    path = folder / filename
    path.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8", "surrogatepass"))
    try:
        contour = load_contour(path)
    except ValueError as exc:
        message = str(exc)
        assert repr(str(path)) in message, message
        assert "\n" not in message and "\r" not in message, message
        return None
    assert_valid(contour)
    return contour


def assert_valid(contour: Contour) -> None:
    """What every loaded contour guarantees."""
    assert isinstance(contour, Contour) and contour.name
    points = contour.points
    assert points.dtype == np.float64 and points.ndim == 2 and points.shape[1] == 2 and len(points) >= 3
    assert np.isfinite(points).all() and not points.flags.writeable
    assert (points >= 0.0).all() and (points <= SHEET).all()
    assert math.isfinite(contour.length) and contour.length > 0
    assert math.isfinite(contour.area_mm2) and contour.area_mm2 > 0
    if contour.closed:
        assert LinearRing(points).is_simple and LinearRing(points).is_ccw
        assert np.minimum(points, SHEET - points).min() > 0.0
    else:
        assert LineString(points).is_simple
        for end in (points[0], points[-1]):
            assert min(end[0], end[1], SHEET - end[0], SHEET - end[1]) == 0.0


# ------------------------------------------------------------------------------------------ strategies

# Plain coordinates on and around the sheet, with the values that break arithmetic mixed in.
coordinates = st.one_of(
    st.floats(-20.0, 120.0),
    st.integers(-20, 120),
    st.sampled_from(
        [0.0, SHEET, -0.0, 1e-300, 5e-324, 1e300, -1e300, 1.8e308, math.inf, -math.inf, math.nan]
    ),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**400), max_value=10**400),
)
points = st.lists(st.lists(coordinates, min_size=2, max_size=2), max_size=12)


@st.composite
def polygons(draw) -> list[list[float]]:
    """A star-shaped polygon of any size anywhere, maybe shuffled (self-intersecting) or with repeats."""
    count = draw(st.integers(3, 12))
    angles = sorted(draw(st.lists(st.floats(0.0, 2 * math.pi), min_size=count, max_size=count)))
    radius = 10.0 ** draw(st.floats(-7.0, 4.0))
    centre = draw(st.tuples(st.floats(-10.0, 110.0), st.floats(-10.0, 110.0)))
    ring = [[centre[0] + radius * math.cos(a), centre[1] + radius * math.sin(a)] for a in angles]
    if draw(st.booleans()):
        ring = draw(st.permutations(ring))
    if draw(st.booleans()):
        ring.insert(draw(st.integers(0, len(ring))), ring[draw(st.integers(0, len(ring) - 1))])
    return ring


@st.composite
def cuts(draw) -> list[list[float]]:
    """An open polyline from near one sheet edge to near another, through random points (maybe on edges)."""

    def near_edge() -> list[float]:
        along, gap = draw(st.floats(0.0, SHEET)), draw(st.sampled_from([0.0, 1e-9, 1e-7, 2.0, 5.0, 6.0]))
        edge = draw(st.integers(0, 3))
        x, y = (gap, along) if edge == 0 else (SHEET - gap, along) if edge == 1 else (along, gap)
        return [x, SHEET - gap] if edge == 3 else [x, y]

    inside = st.lists(st.floats(0.0, SHEET), min_size=2, max_size=2)
    return [near_edge(), *draw(st.lists(inside, min_size=1, max_size=6)), near_edge()]


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=8), children, max_size=4)
    ),
    max_leaves=12,
)


@st.composite
def contour_objects(draw) -> dict:
    """A contour JSON object, each field right, wrong or missing."""
    data = {}
    if draw(st.booleans()):
        data["name"] = draw(st.one_of(st.text(max_size=12), json_values))
    if draw(st.integers(0, 4)):
        data["closed"] = draw(st.booleans()) if draw(st.integers(0, 3)) else draw(json_values)
    choice = draw(st.integers(0, 5))
    if choice:
        shapes = polygons() | cuts() if choice < 3 else points if choice < 5 else json_values
        data["points"] = draw(shapes)
    return data


numbers = st.one_of(
    st.floats(-20.0, 120.0).map(lambda v: f"{v:.6g}"),
    st.integers(-20, 120).map(str),
    st.sampled_from(
        ["1e300", "-1e300", "1e308", "1e999", "-1e999", "1e-999", ".5", "-.5", "+7", "0e0", "1.5.5"]
    ),
)
commands = st.sampled_from(list("MLHVCSQTZAmlhvcsqtzaXe"))


@st.composite
def path_data(draw) -> str:
    """SVG path data: random tokens, or commands with the right number of arguments."""
    if draw(st.booleans()):
        tokens = draw(st.lists(st.one_of(commands, numbers), max_size=30))
    else:
        arity = {"M": 2, "L": 2, "H": 1, "V": 1, "C": 6, "S": 4, "Q": 4, "T": 2}
        tokens = ["M", *draw(st.lists(numbers, min_size=2, max_size=2))]
        for _ in range(draw(st.integers(0, 8))):
            command = draw(st.sampled_from(list(arity)))
            tokens += [command if draw(st.booleans()) else command.lower()]
            tokens += draw(st.lists(numbers, min_size=arity[command], max_size=arity[command]))
        if draw(st.booleans()):
            tokens.append("Z")
    separators = draw(st.lists(st.sampled_from([" ", ",", "", "\n", " , "]), min_size=len(tokens)))
    return "".join(t + s for t, s in zip(tokens, separators, strict=False))


# -------------------------------------------------------------------------------------------------- JSON


@given(data=contour_objects())
def test_json_contour_objects(folder, data):
    load(folder, "shape.json", json.dumps(data))


@given(data=json_values)
def test_any_json(folder, data):
    load(folder, "any.json", json.dumps(data))


@given(text=st.one_of(st.text(max_size=60), st.binary(max_size=60)))
def test_any_text_as_json(folder, text):
    load(folder, "text.json", text)


@given(ring=polygons(), closed=st.booleans())
def test_polygons_of_any_size(folder, ring, closed):
    contour = load(folder, "ring.json", json.dumps({"closed": closed, "points": ring}))
    if contour is not None and closed:
        assert contour.area_mm2 <= SHEET * SHEET


@given(cut=cuts())
def test_open_cuts(folder, cut):
    load(folder, "cut.json", json.dumps({"closed": False, "points": cut}))


@given(data=contour_objects())
def test_contour_from_json_names_where(data):
    try:
        contour = contour_from_json(data, "options: contour")
    except ValueError as exc:
        assert str(exc).startswith("options: contour: ") and "\n" not in str(exc)
    else:
        assert_valid(contour)


# --------------------------------------------------------------------------------------------------- SVG


@given(d=path_data(), view_box=st.one_of(st.none(), st.just("0 0 100 100"), st.text(max_size=12)))
def test_svg_path_data(folder, d, view_box):
    attributes = "" if view_box is None else f' viewBox="{_escape(view_box)}"'
    load(folder, "path.svg", f'<svg{attributes}><path d="{_escape(d)}"/></svg>')


@given(text=st.one_of(st.text(max_size=80), st.binary(max_size=80)))
def test_any_text_as_svg(folder, text):
    load(folder, "text.svg", text)


def _escape(text: str) -> str:
    return text.replace("&", "&amp;").replace('"', "&quot;").replace("<", "&lt;")


# ---------------------------------------------------------------------------------------------- the grid


@given(ring=polygons() | cuts(), closed=st.booleans(), resolution=st.integers(5, 100))
def test_check_resolution_names_a_resolution_that_works(ring, closed, resolution):
    try:
        contour = validate("shape", closed, ring)
    except ContourError:
        return
    try:
        check_resolution(contour, SHEET / (resolution - 1))
    except ContourError as exc:
        assert str(exc).startswith(
            "contour 'shape': too small for the simulation grid: "
        ) and "\n" not in str(exc)
        finer = re.search(r"use resolution (\d+) or finer", str(exc))
        if finer:
            assert int(finer.group(1)) > resolution
            check_resolution(contour, SHEET / (int(finer.group(1)) - 1))
