"""Plots: the Table I figure, the learning curve, the pinch candidate map and the cut regions (files
written, PNGs decode, feasibility agrees, the regions show the first trial of each contour, confidence
intervals stay at or below 100%, legends sit outside the axes and match what is drawn)."""

import math
import re

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import PathCollection
from matplotlib.image import imread
from matplotlib.lines import Line2D
from scipy import stats

from agents.plots import (
    aggregate_improvements,
    improvement_figure,
    learning_curve_figure,
    plot_improvements,
    plot_learning_curve,
)
from warpcut.contours import load_contour
from warpcut.planning import ArmModel, Plan, pinch_feasible, plan_cut
from warpcut.sim.config import SimConfig
from warpcut.task import CuttingTask
from warpcut.viz.plots import (
    FinalCuts,
    candidate_counts,
    candidate_summary,
    feasible_grid,
    pinch_candidates_figure,
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
        task = CuttingTask(  # the centroids, under the arm: the grasp holds the piece
            config, envs, pinch_points=pinches, device="cpu", seed=3, allow_infeasible_pinch=True
        )
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


# ------------------------------------------------------------------------------------------ Table I figure


def suite_report(contours: int, trials: int, seed: int = 0, with_trials: bool = True) -> dict:
    """An evaluate_suite-like report: none, fixed (about 80% better) and analytic (near 100%) per trial,
    with the table's Student t half-widths."""
    rng = np.random.default_rng(seed)
    rows = []
    for c in range(contours):
        none = rng.uniform(8.0, 14.0, trials)
        row = {"contour": f"shape-{c}", "none_error_vertices": float(none.mean())}
        if with_trials:
            row["none_trials_error_vertices"] = none.tolist()
        for method, spread in (("fixed", 0.4), ("analytic", 0.06)):
            errors = none * rng.uniform(0.0, spread, trials)
            improvement = 100 * (none - errors) / none
            half = (
                stats.t.ppf(0.975, trials - 1) * improvement.std(ddof=1) / np.sqrt(trials)
                if trials > 1
                else 0
            )
            row[f"{method}_improvement_pct"] = float(improvement.mean())
            row[f"{method}_ci95"] = float(half)
            if with_trials:
                row[f"{method}_trials_error_vertices"] = errors.tolist()
        rows.append(row)
    return {"rows": rows, "mean": {}, "trials": trials, "score": "path"}


def drawn(fig):
    FigureCanvasAgg(fig).draw()
    return fig


def whisker_tops(ax) -> list[float]:
    return [float(s[:, 1].max()) for c in ax.collections for s in c.get_segments() if len(s)]


def assert_legend_outside_the_axes(fig):
    renderer = fig.canvas.get_renderer()
    (legend,) = fig.legends
    box = legend.get_window_extent(renderer)
    for ax in fig.axes:
        assert not box.overlaps(ax.get_window_extent(renderer)), ax.get_title()


def test_improvement_intervals_never_pass_100_percent_and_say_how_they_were_made(tmp_path):
    report = suite_report(contours=4, trials=2)
    # The table's t interval with 1 degree of freedom reaches far beyond 100% here.
    assert any(r["analytic_improvement_pct"] + r["analytic_ci95"] > 100 for r in report["rows"])
    fig = drawn(improvement_figure(report, ["none", "fixed", "analytic"]))
    bars, aggregate = fig.subfigs
    (ax,) = bars.axes
    tops = whisker_tops(ax)
    assert len(tops) == 4 * 2 and max(tops) <= 100.0
    assert "percentile bootstrap over trials (10,000 resamples)" in ax.get_title()
    assert [t.get_text() for t in ax.get_xticklabels()] == [f"shape-{c}" for c in range(4)]  # no mean group
    assert [a.get_title() for a in aggregate.axes] == ["mean", "IQM"]
    assert "bootstrap over\ncontours and their trials" in aggregate._suptitle.get_text()
    for bar_axes in aggregate.axes:  # every interval's right end
        assert max(p.get_x() + p.get_width() for p in bar_axes.patches) <= 100.0
    assert_legend_outside_the_axes(fig)
    paths = plot_improvements(report, ["none", "fixed", "analytic"], tmp_path)
    assert_figure(paths, tmp_path, "improvement")


def test_improvement_of_one_contour_has_no_mean_group_and_old_reports_get_clipped_t_intervals():
    report = suite_report(contours=1, trials=3, with_trials=False)
    row = report["rows"][0]
    row["analytic_ci95"] = 50.0  # a wide table interval: clipped at 100%
    fig = drawn(improvement_figure(report, ["none", "fixed", "analytic"]))
    assert not fig.subfigs and len(fig.axes) == 1
    (ax,) = fig.axes
    assert [t.get_text() for t in ax.get_xticklabels()] == ["shape-0"]
    assert "Student t interval, clipped at 100%" in ax.get_title()
    assert max(whisker_tops(ax)) == 100.0
    assert_legend_outside_the_axes(fig)
    # One trial: no interval at all, and the figure says so.
    fig = drawn(improvement_figure(suite_report(contours=2, trials=1), ["fixed"]))
    assert not whisker_tops(fig.subfigs[0].axes[0])
    assert "no whisker where a contour has one trial" in fig.subfigs[0].axes[0].get_title()


def test_aggregate_improvements_mean_and_iqm():
    report = suite_report(contours=6, trials=3, seed=2)
    result = aggregate_improvements(report, ["fixed", "analytic"])
    for method in ("fixed", "analytic"):
        per_trial = [
            100
            * (np.array(r["none_trials_error_vertices"]) - r[f"{method}_trials_error_vertices"])
            / np.array(r["none_trials_error_vertices"])
            for r in report["rows"]
        ]
        mean, iqm = result[method]["mean"], result[method]["iqm"]
        assert mean[0] == pytest.approx(np.mean([r[f"{method}_improvement_pct"] for r in report["rows"]]))
        assert iqm[0] == pytest.approx(stats.trim_mean(np.concatenate(per_trial), 0.25))
        for point, low, high in (mean, iqm):
            assert low <= point <= high <= 100.0
        assert (result[method]["contours"], result[method]["scores"]) == (6, 18)
    assert result["analytic"]["mean"][1] > result["fixed"]["mean"][2]  # clearly apart here
    nothing = aggregate_improvements({"rows": [{"fixed_improvement_pct": float("nan")}]}, ["fixed"])
    assert nothing["fixed"]["contours"] == 0 and math.isnan(nothing["fixed"]["mean"][0])


# ------------------------------------------------------------------------------------------ learning curve


@pytest.mark.parametrize("iterations", [1, 3, 30])
def test_learning_curve_has_one_unit_per_panel_and_whole_iterations(iterations):
    validation = [{"iterations": k, "error": 20.0 - k / 3} for k in range(0, iterations + 1, 10)]
    fig = drawn(learning_curve_figure(metrics(iterations), validation))
    assert len(fig.axes) == 3  # three panels, no second y axis
    # Each label names its series and its unit: every learner's final_error is the error area over the
    # intended area, validation errors are in vertices.
    assert [ax.get_ylabel() for ax in fig.axes] == [
        "final error: error / intended area (mm²/mm²)",
        "validation error (vertices)",
        "throughput (env steps/s)",
    ]
    (best,) = [t.get_text() for t in fig.axes[1].get_legend().get_texts() if t.get_text().startswith("best")]
    assert re.fullmatch(r"best: [\d.]+ vertices at iteration \d+ \(best\.pt\)", best), best
    ticks = fig.axes[-1].get_xticks()
    low, high = fig.axes[-1].get_xlim()
    shown = ticks[(ticks >= low) & (ticks <= high)]
    assert len(shown) >= 2 and np.all(shown == np.round(shown)), shown


# ------------------------------------------------------------------------------------------ pinch candidates


def assert_legend_matches_the_map(fig):
    """Every marker in the legend is drawn on the map as it is shown (marker, fill, edge)."""
    (ax,) = [a for a in fig.axes if a.get_label() != "<colorbar>"]
    (legend,) = fig.legends

    def look(line):
        return (line.get_marker(), str(line.get_markerfacecolor()), str(line.get_markeredgecolor()))

    on_map = {look(line) for line in ax.lines if line.get_marker() not in ("None", None, "")}
    for handle, text in zip(legend.legend_handles, legend.get_texts(), strict=True):
        if isinstance(handle, Line2D) and handle.get_marker() not in ("None", None, ""):
            assert look(handle) in on_map, text.get_text()
    scatters = [h for h in legend.legend_handles if isinstance(h, PathCollection)]
    assert len(scatters) == len([c for c in ax.collections if isinstance(c, PathCollection)])


def test_pinch_candidate_map_counts_and_legend(small_plan):
    assert candidate_counts(small_plan) == (2, False)
    assert candidate_summary(small_plan) == "2 sampled pinch candidates; the centroid is infeasible"
    fig = drawn(pinch_candidates_figure(small_plan, SIM))
    assert fig.axes[0].get_title().startswith("circle-offset: 2 sampled pinch candidates; the centroid is")
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert any(label.startswith("centroid, infeasible (") for label in labels)
    assert "sampled candidate (fill: its error)" in labels
    assert_legend_matches_the_map(fig)
    assert_legend_outside_the_axes(fig)
    # A short arm leaves the centroid feasible: a candidate besides the sampled ones (N + 1 in all).
    plan = plan_cut(
        load_contour("fls-circle"), SIM, num_candidates=2, seed=0, device="cpu", arm=ArmModel(length_mm=15.0)
    )
    assert len(plan.candidates) == 3 and candidate_counts(plan) == (2, True) and not plan.rejected
    assert candidate_summary(plan) == "3 pinch candidates: 2 sampled + the centroid"
    fig = drawn(pinch_candidates_figure(plan, SIM))
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "the centroid, a candidate (fill: its error)" in labels
    assert_legend_matches_the_map(fig)
