"""Cut planning: the arm model and its footprint, pinch feasibility and candidates, the default pinch, the
order search, the plan's JSON."""

import json
import math
import warnings

import numpy as np
import pytest

from warpcut import SimConfig
from warpcut.contours import load_contour
from warpcut.io import read_json, write_json
from warpcut.planning import (
    ArmModel,
    Plan,
    default_pinch,
    nearest_feasible,
    pinch_candidates,
    pinch_feasible,
    pinch_rules,
    plan_cut,
    search_orders,
    under_arm,
)
from warpcut.planning.segmentation import segment_contour
from warpcut.task import CuttingTask

GEOMETRY = SimConfig()  # feasibility only: no simulation, so the paper's 25 x 25 sheet costs nothing
SIM = SimConfig(resolution=13)


@pytest.fixture(scope="module")
def small_plan() -> Plan:
    """circle-offset: 2 segments, 2 random candidates (its centroid lies under the arm)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # K = 2: every order, no heuristic warning
        return plan_cut(load_contour("circle-offset"), SIM, num_candidates=2, seed=1, device="cpu")


def test_under_arm_is_the_swept_ray_toward_plus_x():
    path = np.array([[60.0, 50.0], [40.0, 50.0]])  # cut toward -x
    points = np.array([[90.0, 50.0], [70.0, 53.9], [70.0, 54.1], [37.0, 50.0], [35.0, 50.0], [50.0, 20.0]])
    assert under_arm(points, path, ArmModel(radius_mm=4.0)).tolist() == [
        True,
        True,
        False,
        True,
        False,
        False,
    ]
    short = under_arm(np.array([[90.0, 50.0], [44.0, 50.0]]), path, ArmModel(radius_mm=4.0, length_mm=5.0))
    assert short.tolist() == [False, True]
    with pytest.raises(ValueError, match="arm: expected an ArmModel"):
        under_arm(points, path, 4.0)


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"radius_mm": -1}, r"arm\.radius_mm: must be finite and >= 0 mm \(got -1\)"),
        ({"radius_mm": float("inf")}, r"arm\.radius_mm: must be finite"),
        ({"radius_mm": float("nan")}, r"arm\.radius_mm"),
        ({"radius_mm": "4"}, r"arm\.radius_mm"),
        ({"length_mm": -0.5}, r"arm\.length_mm: must be >= 0 mm \(inf: all the way\) \(got -0\.5\)"),
        ({"length_mm": float("nan")}, r"arm\.length_mm"),
        ({"length_mm": True}, r"arm\.length_mm"),
    ],
)
def test_arm_model_rejects_bad_fields(fields, message):
    with pytest.raises(ValueError, match=message):
        ArmModel(**fields)


def test_arm_model_defaults_and_values():
    from warpcut.sim.config import ARM_LENGTH_MM, ARM_RADIUS_MM

    assert ArmModel() == ArmModel(ARM_RADIUS_MM, ARM_LENGTH_MM)
    arm = ArmModel(radius_mm=3, length_mm=np.float32(15.0))
    assert (arm.radius_mm, arm.length_mm) == (3.0, 15.0) and type(arm.length_mm) is float
    assert ArmModel(0, 0) == ArmModel(0.0, 0.0) and math.isinf(ArmModel(length_mm=math.inf).length_mm)


def test_infeasible_points_are_never_candidates():
    contour = load_contour("fls-circle")  # centre (50, 50), radius 25
    segments = segment_contour(contour)
    corners = [[3.0, 3.0], [97.0, 97.0]]
    on_contour = [[25.5, 50.0]]  # just right of the leftmost point: on the cut, under the arm
    under = [[50.0, 50.0], [90.0, 50.0]]  # the centroid; right of the circle, clear of everything but the arm
    clear = [[10.0, 50.0], [50.0, 90.0]]  # left of the circle; above the swept band
    points = np.array(corners + on_contour + under + clear)
    with_arm = pinch_feasible(points, contour, GEOMETRY, segments)
    assert with_arm.tolist() == [False] * 5 + [True] * 2
    # Without segments the arm sweeps the whole contour: the same region however the cut is split.
    assert pinch_feasible(points, contour, GEOMETRY).tolist() == with_arm.tolist()
    short_arm = pinch_feasible(points, contour, GEOMETRY, arm=ArmModel(length_mm=15.0))
    # A short footprint lets the grasp hold the disc; (90, 50) is still under it (15 mm from x = 75).
    assert short_arm.tolist() == [False] * 3 + [True, False] + [True] * 2
    rules = pinch_rules(points, contour, GEOMETRY, segments)
    assert not rules["arm"][2:5].any() and rules["arm"][5:].all()
    assert rules["contour"][3:].all()  # the under-arm points fail only because of the arm

    candidates = pinch_candidates(contour, GEOMETRY, segments, num=40, rng=np.random.default_rng(0))
    assert len(candidates) == 40  # the centroid is infeasible, so not added
    assert pinch_feasible(candidates, contour, GEOMETRY, segments).all()
    assert not under_arm(candidates, segments).any()
    # The same draws without segments: the arm sweeps the whole contour however it is split.
    whole = pinch_candidates(contour, GEOMETRY, num=40, rng=np.random.default_rng(0))
    np.testing.assert_array_equal(whole, candidates)


def test_empty_feasible_region_names_the_contour():
    contour = load_contour("circle-large")
    with pytest.raises(ValueError, match="circle-large.*arm"):
        pinch_candidates(contour, GEOMETRY, segment_contour(contour), arm=ArmModel(radius_mm=60.0))
    with pytest.raises(ValueError, match="circle-large"):
        default_pinch(contour, GEOMETRY, ArmModel(radius_mm=60.0))


def test_plan_cut_rejects_bad_arguments():
    contour = load_contour("circle-offset")
    for kwargs, name in (
        ({"num_candidates": 0}, "num_candidates"),
        ({"arm": (4.0, 15.0)}, "arm: expected an ArmModel"),
        ({"tolerance_mm": 0.0}, "tolerance_mm"),
    ):
        with pytest.raises(ValueError, match=name):
            plan_cut(contour, SIM, **kwargs)


def test_order_search_picks_the_brute_force_best(small_plan):
    contour = small_plan.contour
    points = np.array([c["point"] for c in small_plan.candidates])
    assert len(small_plan.segments) == 2 and len(small_plan.orders) == 2 and len(points) == 2
    brute = np.zeros((len(points), len(small_plan.orders)))
    for c, point in enumerate(points):
        for o, order in enumerate(small_plan.orders):
            task = CuttingTask(
                SIM.replace(noise_std=0.0),
                contour,
                pinch_points=point,
                segments=[small_plan.ordered_segments(order)],
                device="cpu",
            )
            brute[c, o] = task.run(None).error_vertices[0]
    np.testing.assert_array_equal(small_plan.errors, brute)  # the batch simulates each pair faithfully
    chosen = small_plan.chosen
    c = int(np.flatnonzero((points == chosen["pinch"]).all(axis=1))[0])
    o = small_plan.orders.index(tuple(chosen["order"]))
    assert brute[c, o] == brute.min() == chosen["error_vertices"]
    assert tuple(small_plan.order) == tuple(chosen["order"])
    for c, candidate in enumerate(small_plan.candidates):
        assert candidate["error_vertices"] == brute[c].min()
        assert brute[c, small_plan.orders.index(tuple(candidate["best_order"]))] == brute[c].min()


def test_plan_json_shape(small_plan):
    data = json.loads(json.dumps(small_plan.to_json()))
    assert {"segments", "order", "pinch_candidates", "chosen"} <= data.keys()
    assert len(data["segments"]) == len(small_plan.segments)
    for segment in data["segments"]:
        assert {"points", "notch", "termination"} <= segment.keys()
        assert segment["notch"] == segment["points"][0]
        assert segment["termination"] == segment["points"][-1]
        assert all(len(p) == 2 for p in segment["points"])
    assert sorted(data["order"]) == list(range(len(data["segments"])))
    feasible = [c for c in data["pinch_candidates"] if c["feasible"]]
    assert len(feasible) == 2
    for candidate in data["pinch_candidates"]:
        assert {"point", "feasible", "error_vertices"} <= candidate.keys() and len(candidate["point"]) == 2
        assert isinstance(candidate["error_vertices"], float) == candidate["feasible"]
    infeasible = [c for c in data["pinch_candidates"] if not c["feasible"]]
    assert len(infeasible) == 1 and "arm" in infeasible[0]["violates"]  # the centroid, under the arm
    chosen = data["chosen"]
    assert {"pinch", "order", "error_vertices"} <= chosen.keys()
    assert chosen["order"] == data["order"]
    assert chosen["error_vertices"] == min(c["error_vertices"] for c in feasible)
    assert chosen["pinch"] in [c["point"] for c in feasible]
    polylines = small_plan.ordered_segments()
    assert [p.tolist() for p in polylines] == [data["segments"][k]["points"] for k in data["order"]]


def test_plan_json_reads_back_bit_for_bit(small_plan, tmp_path):
    write_json(tmp_path / "plan.json", small_plan.to_json())
    data = read_json(tmp_path / "plan.json")
    again = Plan.from_json(data, small_plan.contour, small_plan.config)
    assert again.to_json() == small_plan.to_json()
    np.testing.assert_array_equal(again.errors, small_plan.errors)
    assert again.errors.shape == small_plan.errors.shape
    assert again.order == small_plan.order and again.orders == small_plan.orders
    assert again.arm == small_plan.arm and again.rejected[0]["violates"] == small_plan.rejected[0]["violates"]
    for a, b in zip(again.segments, small_plan.segments, strict=True):
        np.testing.assert_array_equal(a.points, b.points)
    for a, b in zip(again.candidates, small_plan.candidates, strict=True):
        np.testing.assert_array_equal(a["point"], b["point"])
        assert a["best_order"] == tuple(b["best_order"]) and a["error_vertices"] == b["error_vertices"]
    np.testing.assert_array_equal(again.chosen["pinch"], small_plan.chosen["pinch"])
    np.testing.assert_array_equal(again.analytic_pinch, small_plan.analytic_pinch)
    with pytest.raises(ValueError, match="it is 'circle-offset''s plan, not 'wave-1''s"):
        Plan.from_json(data, load_contour("wave-1"), small_plan.config)
    del data["errors_vertices"]  # a plan written before the errors were
    with pytest.raises(ValueError, match="missing 'errors_vertices'"):
        Plan.from_json(data, small_plan.contour, small_plan.config)


def test_many_segments_use_the_heuristic_orders_with_a_warning():
    contour = load_contour("flower-5")
    segments = segment_contour(contour)
    assert len(segments) > 6
    config = SIM.replace(resolution=16)  # the coarsest sheet that leaves the gripper a feasible point
    candidate = default_pinch(contour, config)[None]
    with pytest.warns(UserWarning, match="heuristic"):
        orders, errors = search_orders(contour, config, segments, candidate, device="cpu")
    assert 1 < len(orders) < math.factorial(len(segments))
    assert errors.shape == (1, len(orders)) and np.isfinite(errors).all()


def test_analytic_pinch_is_the_centroid_only_where_the_gripper_can_be(small_plan):
    """The analytic policy pinches the centroid (the paper's choice) unless it is infeasible: under the
    cutting arm (circle-offset's, with the plan's arm footprint) or on the cut line (crescent's)."""
    contour = small_plan.contour
    segments = small_plan.segments
    assert small_plan.arm == ArmModel()
    assert not pinch_feasible(contour.centroid, contour, SIM, segments, small_plan.arm)[0]
    point = small_plan.analytic_pinch
    assert pinch_feasible(point, contour, SIM, segments, small_plan.arm)[0]
    assert np.linalg.norm(point - contour.centroid) > 0
    assert point.tolist() == default_pinch(contour, SIM, segments=segments).tolist()


def test_default_pinch_is_the_centroid_or_the_nearest_feasible_point():
    circle = load_contour("fls-circle")
    short = ArmModel(length_mm=15.0)
    assert default_pinch(circle, GEOMETRY, short).tolist() == list(circle.centroid)
    outside = default_pinch(circle, GEOMETRY)  # the paper's arm covers the disc: the grasp goes outside
    assert np.linalg.norm(outside - circle.centroid) > 25.0 and pinch_feasible(outside, circle, GEOMETRY)[0]
    assert outside.tolist() == nearest_feasible(circle.centroid, circle, GEOMETRY).tolist()
    # Nearest on the 0.5 mm grid: no feasible grid point is closer to the centroid.
    xs = np.arange(0.0, 100.0 + 1e-9, 0.5)
    grid = np.stack(np.meshgrid(xs, xs), axis=-1).reshape(-1, 2)
    closer = grid[np.linalg.norm(grid - circle.centroid, axis=1) < np.linalg.norm(outside - circle.centroid)]
    assert not pinch_feasible(closer, circle, GEOMETRY).any()
    # The arm sweeps the same footprint however the contour is split.
    segments = segment_contour(circle)
    assert default_pinch(circle, GEOMETRY, segments=segments).tolist() == outside.tolist()
    crescent = load_contour("crescent")
    assert pinch_rules(crescent.centroid, crescent, GEOMETRY)["contour"].tolist() == [False]
    moved = default_pinch(crescent, GEOMETRY, short)  # on the cut line even for a short arm
    assert pinch_feasible(moved, crescent, GEOMETRY, arm=short)[0]
    assert np.linalg.norm(moved - crescent.centroid) > 0
