"""Plots: the learning curve and the pinch candidate map (files written, PNGs decode, feasibility agrees)."""

import math

import numpy as np
import pytest
from matplotlib.image import imread

from warpcut.config import SimConfig
from warpcut.contours import load_contour
from warpcut.planning import Plan, pinch_feasible, plan_cut
from warpcut.plots import feasible_grid, plot_learning_curve, plot_pinch_candidates

SIM = SimConfig(resolution=13)


def assert_figure(paths, out, name):
    assert [p.name for p in paths] == [f"{name}.png", f"{name}.svg"]
    for path in paths:
        assert path.parent == out and path.stat().st_size > 1000, path
    image = imread(paths[0])
    assert image.ndim == 3 and image.shape[0] > 100 and image.shape[1] > 100
    assert "<svg" in paths[1].read_text()[:1000]
    assert not list(out.glob(".*.tmp")), "a temporary file was left behind"


def metrics(iterations: int, final_error=lambda i: 0.2 / i) -> list[dict]:
    return [
        {
            "iteration": i,
            "final_error": final_error(i),
            "mean_return": None if final_error(i) is None else -final_error(i),
            "iteration_steps_per_s": 4000.0 + 10 * i,
        }
        for i in range(1, iterations + 1)
    ]


@pytest.mark.parametrize(
    ("history", "validation"),
    [
        (metrics(30), [{"iterations": k, "error": 20.0 - k / 3 + (k == 20) * 5} for k in range(0, 31, 10)]),
        (metrics(5), []),  # no validation yet
        (metrics(8, lambda i: None), [{"iterations": 0, "error": 12.0}]),  # no episode ended yet
        (metrics(6, lambda i: None if i % 2 else 0.1), []),  # some iterations without an ended episode
        ([], []),  # nothing at all
    ],
    ids=["typical", "no-validation", "no-final-error", "gaps", "empty"],
)
def test_learning_curve_is_written(tmp_path, history, validation):
    paths = plot_learning_curve(history, validation, tmp_path, title="fls-circle, seed 0")
    assert_figure(paths, tmp_path, "learning_curve")


def test_learning_curve_custom_name(tmp_path):
    paths = plot_learning_curve(metrics(3), [], tmp_path / "sub", name="curve")
    assert_figure(paths, tmp_path / "sub", "curve")


@pytest.fixture(scope="module")
def small_plan() -> Plan:
    """circle-offset on a 13 x 13 sheet, 2 random candidates (its centroid lies under the arm)."""
    return plan_cut(load_contour("circle-offset"), SIM, num_candidates=2, seed=1, device="cpu")


def test_pinch_candidate_map_is_written(tmp_path, small_plan):
    assert small_plan.rejected, "the fixture should show a rejected centroid"
    paths = plot_pinch_candidates(small_plan, SIM, tmp_path)
    assert_figure(paths, tmp_path, "pinch_candidates")


def test_pinch_candidate_map_with_a_short_arm(tmp_path):
    plan = plan_cut(
        load_contour("fls-circle"), SIM, num_candidates=2, seed=0, device="cpu", arm_length_mm=15.0
    )
    assert not math.isinf(plan.arm_length_mm)
    assert_figure(plot_pinch_candidates(plan, SIM, tmp_path, name="short"), tmp_path, "short")


def test_feasible_grid_agrees_with_planning(small_plan):
    xs, ys, feasible = feasible_grid(small_plan, SIM, step_mm=2.5)
    assert feasible.shape == (len(ys), len(xs)) and xs[-1] == SIM.width_mm and ys[-1] == SIM.height_mm
    assert feasible.any() and not feasible.all()
    rng = np.random.default_rng(0)
    for j, i in zip(rng.integers(0, len(ys), 25), rng.integers(0, len(xs), 25), strict=True):
        expected = pinch_feasible(
            np.array([xs[i], ys[j]]),
            small_plan.contour,
            SIM,
            small_plan.segments,
            small_plan.arm_radius_mm,
            small_plan.arm_length_mm,
        )[0]
        assert feasible[j, i] == expected, (xs[i], ys[j])
    # Orientation: row j is y, column i is x. Corners are infeasible; every candidate was feasible.
    assert not feasible[0, 0] and not feasible[-1, -1]
    for candidate in small_plan.candidates:
        i, j = np.argmin(np.abs(xs - candidate["point"][0])), np.argmin(np.abs(ys - candidate["point"][1]))
        near = feasible[max(j - 1, 0) : j + 2, max(i - 1, 0) : i + 2]
        assert near.any(), candidate["point"]
    centroid = small_plan.rejected[0]["point"]
    i, j = np.argmin(np.abs(xs - centroid[0])), np.argmin(np.abs(ys - centroid[1]))
    assert not feasible[j, i]
    with pytest.raises(ValueError, match="step_mm"):
        feasible_grid(small_plan, SIM, step_mm=0.0)
