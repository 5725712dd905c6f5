"""Plots: the learning curve, the pinch candidate map and the cut regions (files written, PNGs decode,
feasibility agrees, the regions show the first trial of each contour)."""

import math

import numpy as np
import pytest
from matplotlib.image import imread

from warpcut.contours import load_contour
from warpcut.planning import ArmModel, Plan, pinch_feasible, plan_cut
from warpcut.sim.config import SimConfig
from warpcut.task import CuttingTask
from warpcut.viz.plots import (
    FinalCuts,
    feasible_grid,
    plot_learning_curve,
    plot_pinch_candidates,
    plot_regions,
)

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
        load_contour("fls-circle"), SIM, num_candidates=2, seed=0, device="cpu", arm=ArmModel(length_mm=15.0)
    )
    assert not math.isinf(plan.arm.length_mm)
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
            small_plan.arm,
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


def test_regions_of_a_two_contour_batch(tmp_path):
    """Envs contour by contour, trials within (as agents.evaluation.run_method lays them out): one figure
    per contour, each method's cut the first trial of that contour, scored once, at the end."""
    contours = [load_contour("fls-circle"), load_contour("s-curve")]
    trials = 2
    envs = [c for c in contours for _ in range(trials)]
    config = SIM.replace(noise_std=0.05)
    cuts = FinalCuts()
    captured, capture = [], cuts.capture
    cuts.capture = lambda task, method: (captured.append(method), capture(task, method))
    scores = {}
    for method, pinches in (("none", None), ("fixed", np.array([c.centroid for c in envs]))):
        task = CuttingTask(config, envs, pinch_points=pinches, device="cpu", seed=3)
        scores[method] = task.run(None, on_step=cuts.step_callback(method))
    assert captured == ["none", "fixed"]  # once per batch, at the end
    assert list(cuts.cuts) == ["fls-circle", "s-curve"]
    for k, contour in enumerate(contours):
        by_method = cuts.of(contour.name, ["fixed", "none", "rl"])
        assert list(by_method) == ["fixed", "none"]
        for method, cut in by_method.items():
            assert cut.contour is contour and cut.trials == trials
            assert cut.score.error_vertices[0] == scores[method].error_vertices[k * trials]
            assert np.array_equal(cut.score.achieved[0], scores[method].achieved[k * trials])
        assert by_method["none"].pinch is None
        assert by_method["fixed"].pinch == pytest.approx(contour.centroid)
    paths = cuts.plot(tmp_path / "regions", ["none", "fixed"])
    assert [p.name for p in paths] == ["fls-circle.png", "fls-circle.svg", "s-curve.png", "s-curve.svg"]
    for name in ("fls-circle", "s-curve"):
        assert_figure([p for p in paths if p.stem == name], tmp_path / "regions", name)
    assert "first of 2 trials" in (tmp_path / "regions" / "s-curve.svg").read_text()
    with pytest.raises(ValueError, match="one contour"):
        plot_regions({"a": cuts.of("fls-circle")["none"], "b": cuts.of("s-curve")["none"]}, tmp_path)
    with pytest.raises(ValueError, match="no cuts"):
        plot_regions(cuts.of("missing"), tmp_path)
