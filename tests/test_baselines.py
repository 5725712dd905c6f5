"""The baseline tensioners."""

import numpy as np
import pytest

from agents.baselines import AnalyticTension, FixedTension, NoTension, search_fixed_pinch
from agents.evaluation import compare_policies
from warpcut import SimConfig
from warpcut.contours import load_contour
from warpcut.planning import ArmModel, pinch_feasible
from warpcut.stats import ci95
from warpcut.task import CuttingTask

CONFIG = SimConfig(resolution=13)


def test_no_tension_has_no_grasp():
    contour = load_contour("fls-circle")
    assert NoTension().pinch_point(contour, CONFIG) is None


def test_fixed_search_picks_the_best_feasible_candidate():
    contour = load_contour("fls-circle")
    best, points, errors = search_fixed_pinch(contour, CONFIG, candidates=6, seed=3)
    assert len(points) == 6  # 6 random; the centroid lies under the cutting arm
    assert np.all(pinch_feasible(points, contour, CONFIG))
    assert errors[np.flatnonzero((points == best).all(axis=1))[0]] == errors.min()
    assert np.array_equal(FixedTension(pinch=(30.0, 40.0)).pinch_point(contour, CONFIG), [30.0, 40.0])


def test_feasibility_excludes_corners_contour_and_edges():
    contour = load_contour("fls-circle")
    points = np.array([[5.0, 5.0], [50.0, 75.0], [98.0, 50.0], [50.0, 50.0], [90.0, 90.0], [50.0, 90.0]])
    # The centroid lies under the cutting arm (the paper's cylinder); a short footprint frees it.
    config = SimConfig()  # 25 x 25: grasp radius 6.7 mm, cut radius 4.2 mm
    assert pinch_feasible(points, contour, config).tolist() == [False] * 5 + [True]
    short = pinch_feasible(points, contour, config, arm=ArmModel(length_mm=15.0))
    assert short.tolist() == [False, False, False, True, False, True]


def test_analytic_moves_against_the_tracking_error():
    contour = load_contour("fls-circle")
    task = CuttingTask(CONFIG, contour, pinch_points=contour.centroid, allow_infeasible_pinch=True)
    task.reset()
    for _ in range(10):
        task.step(None)
    policy = AnalyticTension(gain=0.5)
    error = task.target_world() - task.tip_positions()[:, :3]
    move = policy(task)
    np.testing.assert_allclose(move[:, :2], -0.5 * error[:, :2], rtol=1e-6)
    assert move[0, 2] == 0.0


def test_tensioning_changes_the_result():
    report = compare_policies(
        load_contour("fls-circle"), ("none", "fixed", "analytic"), config=CONFIG, pinch=(83.0, 83.0)
    )
    errors = {k: v["error_vertices"] for k, v in report["results"].items()}
    assert errors["none"] > 0
    assert errors["fixed"] != errors["none"] or errors["analytic"] != errors["none"]
    assert report["results"]["none"]["improvement_pct"] == 0.0


def test_ci95():
    assert ci95(np.array([1.0])) == 0.0
    # sample std of (1, 2, 3) is 1; t(0.975, 2 dof) = 4.3027
    assert ci95(np.array([1.0, 2.0, 3.0])) == pytest.approx(4.302652729749464 / np.sqrt(3))


def test_table_one_protocol_rows_and_mean():
    from agents.evaluation import evaluate_suite

    contours = [load_contour("fls-circle"), load_contour("s-curve")]
    config = SimConfig(resolution=13, noise_std=0.02)
    report = evaluate_suite(contours, ("none", "fixed", "analytic"), trials=2, config=config, seed=1)
    assert [r["contour"] for r in report["rows"]] == ["fls-circle", "s-curve"]
    for row in report["rows"]:
        assert row["none_error_vertices"] > 0
        for method in ("fixed", "analytic"):
            assert np.isfinite(row[f"{method}_improvement_pct"]) and row[f"{method}_ci95"] >= 0
            assert len(row[f"{method}_trials_error_vertices"]) == 2
    for method in ("none", "fixed", "analytic"):
        values = [r[f"{method}_improvement_pct"] for r in report["rows"]]
        assert report["mean"][f"{method}_improvement_pct"] == pytest.approx(np.mean(values))
    assert report["mean"]["none_improvement_pct"] == 0.0


def test_analytic_pinches_the_centroid_unless_it_is_infeasible():
    circle, crescent = load_contour("fls-circle"), load_contour("crescent")  # crescent's: on the cut line
    outside = AnalyticTension().pinch_point(circle, CONFIG)  # the disc lies under the cutting arm
    assert (
        pinch_feasible(outside, circle, CONFIG)[0] and not pinch_feasible(circle.centroid, circle, CONFIG)[0]
    )
    assert AnalyticTension(feasible=False).pinch_point(circle, CONFIG).tolist() == list(circle.centroid)
    moved = AnalyticTension().pinch_point(crescent, CONFIG)
    assert (
        pinch_feasible(moved, crescent, CONFIG)[0]
        and not pinch_feasible(crescent.centroid, crescent, CONFIG)[0]
    )
    literal = AnalyticTension(feasible=False).pinch_point(crescent, CONFIG)
    assert literal.tolist() == list(crescent.centroid)
    assert AnalyticTension(pinch=(30.0, 40.0)).pinch_point(crescent, CONFIG).tolist() == [30.0, 40.0]
