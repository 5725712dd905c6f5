"""Figures of agents' reports, drawn with :func:`warpcut.viz.plots.save_figure`: Table I (a table's
per-contour improvements with rliable-style aggregates over contours, :func:`plot_improvements`), a training
run's learning curve (:func:`plot_learning_curve`) and the sensitivity studies (the paper's Fig. 5,
:func:`plot_robustness`). Each ``plot_*`` saves what its ``*_figure`` draws.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from matplotlib.ticker import MaxNLocator

from warpcut.stats import BOOTSTRAP_RESAMPLES, bootstrap_ci, paired_improvement
from warpcut.viz.plots import save_figure


def plot_improvements(
    report: dict, methods: Sequence[str], out_dir: str | os.PathLike, resamples: int = BOOTSTRAP_RESAMPLES
) -> list[Path]:
    """Table I as a figure: per contour, each method's mean improvement over no tension (bars) with a 95%
    confidence interval; with two contours or more, beside it the aggregate over the contours (rliable
    style, :func:`aggregate_improvements`): the mean (the table's mean row) and the interquartile mean.

    Improvements are paired per trial (``100 (e_none - e) / e_none``), so they never exceed 100%, and
    neither do the intervals: percentile bootstrap intervals of the mean over a contour's trials (none for
    one trial). A report without per-trial errors gets the table's Student t interval, clipped at 100%.
    The figure states which.

    Args:
        report: :func:`agents.evaluation.evaluate_suite`'s report.
        methods: The methods to show; ``none`` (the reference, 0 by definition) is left out.
        out_dir: Where ``improvement.png`` and ``improvement.svg`` go.
        resamples: Bootstrap resamples.

    Returns:
        The paths written.
    """
    return save_figure(improvement_figure(report, methods, resamples), out_dir, "improvement")


def improvement_figure(report: dict, methods: Sequence[str], resamples: int = BOOTSTRAP_RESAMPLES) -> Figure:
    """:func:`plot_improvements`' figure, unsaved."""
    shown = [m for m in methods if m != "none"]
    rows = report["rows"]
    colours = {m: f"C{k % 10}" for k, m in enumerate(shown)}
    aggregate = len(rows) >= 2 and bool(shown)
    fig = Figure(
        figsize=(max(6.0, 0.9 * len(rows) * max(1, len(shown)) ** 0.5 + 2) + 3.6 * aggregate, 4.8),
        layout="constrained",
    )
    left, right = fig.subfigures(1, 2, width_ratios=[3, 1.5]) if aggregate else (fig, None)
    ax = left.add_subplot()
    x = np.arange(len(rows))
    width = 0.8 / max(1, len(shown))
    how = set()
    for k, method in enumerate(shown):
        values = np.array([r[f"{method}_improvement_pct"] for r in rows], dtype=np.float64)
        cis = [_contour_ci(r, method, resamples) for r in rows]
        how.update(c[2] for c in cis)
        low, high = np.array([c[0] for c in cis]), np.array([c[1] for c in cis])
        at = x + (k - (len(shown) - 1) / 2) * width
        ax.bar(at, values, width, color=colours[method], label=method)
        ok = np.isfinite(low) & np.isfinite(high) & np.isfinite(values)
        ax.errorbar(
            at[ok], values[ok], yerr=[values[ok] - low[ok], high[ok] - values[ok]], fmt="none",
            ecolor="black", elinewidth=1.0, capsize=3,
        )  # fmt: skip
    ax.axhline(0.0, color="black", linewidth=0.8)
    ax.set_xticks(x, [r["contour"] for r in rows], rotation=45 if len(rows) > 4 else 0, ha="right")
    ax.set_ylabel("improvement over no tension (%)")
    trials = f"{report['trials']} trial{'' if report['trials'] == 1 else 's'}"
    ax.set_title(f"per contour, {trials} each\n{_ci_note(how, resamples)}", fontsize="small")
    if aggregate:
        _plot_aggregate(right, aggregate_improvements(report, shown, resamples), colours, resamples)
    if shown:
        handles = [Patch(color=colours[m], label=m) for m in shown]
        fig.legend(handles=handles, loc="outside lower center", ncol=min(len(shown), 6), frameon=False)
    fig.suptitle("Cut error reduction over no tension (100% = no error left)")
    return fig


def _trial_improvements(row: dict, method: str) -> np.ndarray | None:
    """A contour's finite per-trial paired improvements (%) of ``method``; None where the row lacks the
    trials' errors (of ``none`` or of the method)."""
    none, errors = row.get("none_trials_error_vertices"), row.get(f"{method}_trials_error_vertices")
    if none is None or errors is None or len(none) != len(errors):
        return None
    values = paired_improvement(np.asarray(none, dtype=np.float64), np.asarray(errors, dtype=np.float64))
    return values[np.isfinite(values)]


def _contour_ci(row: dict, method: str, resamples: int) -> tuple[float, float, str]:
    """``(low, high, how)``: the 95% interval of a contour's mean improvement (NaN where none), and how it
    was made: ``"bootstrap"``, ``"single"`` (one trial) or ``"t-clipped"`` (no per-trial errors)."""
    trials = _trial_improvements(row, method)
    if trials is None:
        mean, half = row[f"{method}_improvement_pct"], row[f"{method}_ci95"]
        return mean - half, min(mean + half, 100.0), "t-clipped"
    interval = bootstrap_ci(trials, "mean", resamples)
    return (np.nan, np.nan, "single") if interval is None else (*interval, "bootstrap")


def _ci_note(how: set[str], resamples: int) -> str:
    """The figure's statement of how its per-contour whiskers were made."""
    notes = []
    if "bootstrap" in how:
        notes.append(
            f"whiskers: 95% CI of the mean, percentile bootstrap over trials ({resamples:,} resamples)"
        )
    if "t-clipped" in how:
        notes.append("whiskers: the table's 95% Student t interval, clipped at 100%")
    if "single" in how:
        notes.append("no whisker where a contour has one trial")
    return "; ".join(notes)


def aggregate_improvements(
    report: dict, methods: Sequence[str], resamples: int = BOOTSTRAP_RESAMPLES, seed: int = 0
) -> dict[str, dict]:
    """Each method's improvement over the report's contours, as rliable aggregates it (Agarwal et al.,
    NeurIPS 2021): the mean of the contours' mean improvements (the table's mean row) and the
    interquartile mean (IQM) of every trial's improvement, each with a 95% percentile-bootstrap interval
    from a two-level bootstrap: contours drawn with replacement, then each drawn contour's trials.

    Without per-trial errors in the report, a contour's mean improvement stands for its trials.

    Returns:
        ``{method: {"mean": (point, low, high), "iqm": (point, low, high), "contours": int,
        "scores": int}}`` (%); NaN where no contour has a defined improvement.
    """
    rng = np.random.default_rng(seed)
    result = {}
    for method in methods:
        scores = []
        for row in report["rows"]:
            trials = _trial_improvements(row, method)
            if trials is None:
                trials = np.array([row[f"{method}_improvement_pct"]], dtype=np.float64)
            if np.isfinite(trials).any():
                scores.append(trials[np.isfinite(trials)])
        if not scores:
            nothing = (np.nan, np.nan, np.nan)
            result[method] = {"mean": nothing, "iqm": nothing, "contours": 0, "scores": 0}
            continue
        counts = np.array([len(s) for s in scores])
        table = np.full((len(scores), counts.max()), np.nan)
        for c, s in enumerate(scores):
            table[c, : len(s)] = s
        chosen = rng.integers(0, len(scores), size=(resamples, len(scores)))  # contours
        n = counts[chosen][..., None]
        picks = (rng.random((*chosen.shape, table.shape[1])) * n).astype(np.intp)  # trials of each
        sample = np.where(np.arange(table.shape[1]) < n, table[chosen[..., None], picks], np.nan)
        means = np.nanmean(sample, axis=2).mean(axis=1)
        iqms = _iqm(sample.reshape(resamples, -1))
        point_mean = float(np.nanmean(table, axis=1).mean())
        point_iqm = float(_iqm(table.reshape(1, -1))[0])
        result[method] = {
            "mean": (point_mean, *(float(v) for v in np.percentile(means, [2.5, 97.5]))),
            "iqm": (point_iqm, *(float(v) for v in np.percentile(iqms, [2.5, 97.5]))),
            "contours": len(scores),
            "scores": int(counts.sum()),
        }
    return result


def _iqm(rows: np.ndarray) -> np.ndarray:
    """Per row, the interquartile mean of its finite values (NaN elsewhere): the mean after dropping the
    lowest and highest quarter (``floor(n / 4)`` each, as ``scipy.stats.trim_mean(x, 0.25)``)."""
    ordered = np.sort(rows, axis=1)  # NaN last
    n = np.isfinite(ordered).sum(axis=1, keepdims=True)
    cut = n // 4
    position = np.arange(ordered.shape[1])
    keep = (position >= cut) & (position < n - cut)
    return np.where(keep, ordered, 0.0).sum(axis=1) / np.maximum(keep.sum(axis=1), 1)


def _plot_aggregate(subfig, aggregates: dict[str, dict], colours: dict[str, str], resamples: int) -> None:
    """rliable's interval estimates: per statistic, each method's 95% interval as a bar and its point
    estimate as a black tick."""
    methods = list(aggregates)
    axes = subfig.subplots(1, 2, sharex=True, sharey=True)
    y = np.arange(len(methods))[::-1]
    for ax, (key, title) in zip(axes, (("mean", "mean"), ("iqm", "IQM")), strict=True):
        for yi, method in zip(y, methods, strict=True):
            point, low, high = aggregates[method][key]
            ax.barh(yi, high - low, left=low, height=0.6, color=colours[method], alpha=0.75)
            ax.plot([point, point], [yi - 0.3, yi + 0.3], color="black", linewidth=2)
        ax.set_title(title, fontsize="medium")
        ax.set_xlabel("improvement (%)")
        ax.grid(axis="x", alpha=0.3)
    axes[0].set_yticks(y, methods)
    contours = max((a["contours"] for a in aggregates.values()), default=0)
    subfig.suptitle(
        f"over {contours} contours: 95% CI, bootstrap over\n"
        f"contours and their trials ({resamples:,} resamples)",
        fontsize="small",
    )


FINAL_ERROR_LABEL = "final error: error / intended area (mm²/mm²)"
"""The learning curve's unit of the training episodes' ``final_error`` (every learner's: the cut's error area,
by the path score unless ``sim.score`` says otherwise, over the intended area)."""


VALIDATION_ERROR_LABEL = "validation error (vertices)"
"""The learning curve's unit of the validation errors."""


THROUGHPUT_LABEL = "throughput (env steps/s)"
"""The learning curve's unit of each iteration's throughput."""


def plot_learning_curve(
    metrics: Sequence[dict],
    validation: Sequence[dict],
    out_dir: str | os.PathLike,
    name: str = "learning_curve",
    title: str | None = None,
) -> list[Path]:
    """A training run over its learning iterations, three panels on one iteration axis (whole numbers),
    each in one unit, which its label names: the training episodes' final error, the validation error, the
    throughput.

    Top: the mean final error of the training episodes that ended in each iteration (``final_error``, as
    every learner logs it: the cut's error area over the intended area, mm²/mm²; iterations where none
    ended are skipped). Middle: the deterministic policy's validation error (vertices), its minimum marked
    (the policy kept as ``best.pt``). Bottom: env steps per second of each iteration.

    Args:
        metrics: One dict per iteration: ``iteration`` (iterations done, from 1), ``final_error`` (error
            mm² / intended area mm², or None), ``mean_return`` (float or None, not drawn) and
            ``iteration_steps_per_s``.
        validation: ``{"iterations": int, "error": float}`` per validation (0 = the initial policy), the
            error in vertices; may be empty.
        out_dir: Where ``NAME.png`` and ``NAME.svg`` go.
        name: File name stem.
        title: Figure title; default "Learning curve".

    Returns:
        The paths written.
    """
    return save_figure(learning_curve_figure(metrics, validation, title), out_dir, name)


def learning_curve_figure(
    metrics: Sequence[dict], validation: Sequence[dict], title: str | None = None
) -> Figure:
    """:func:`plot_learning_curve`'s figure, unsaved."""
    fig = Figure(figsize=(7.5, 7.5), layout="constrained")
    top, middle, bottom = fig.subplots(3, 1, sharex=True, height_ratios=[2, 2, 1.2])
    ended = [(m["iteration"], m["final_error"]) for m in metrics if m.get("final_error") is not None]
    if ended:
        x, y = zip(*ended, strict=True)
        top.plot(x, y, color="C0", linewidth=1.2, marker="o" if len(x) == 1 else None)  # a line needs two
    else:
        top.text(0.5, 0.5, "no training episode has ended", transform=top.transAxes, ha="center", color="C0")
    top.set_title("training episodes: mean final error of those ending in the iteration", fontsize="medium")
    top.set_ylabel(FINAL_ERROR_LABEL)
    if validation:
        x = [v["iterations"] for v in validation]
        y = [v["error"] for v in validation]
        middle.plot(x, y, "o-", color="C1", markersize=4, label="validation error")
        best = int(np.argmin(y))
        middle.scatter(
            x[best], y[best], marker="*", s=220, color="C3", zorder=5,
            label=f"best: {y[best]:.1f} vertices at iteration {x[best]} (best.pt)",
        )  # fmt: skip
        middle.legend(loc="best", fontsize="small")
    else:
        middle.text(0.5, 0.5, "no validation yet", transform=middle.transAxes, ha="center", color="C1")
    middle.set_title("deterministic policy on the validation envs", fontsize="medium")
    middle.set_ylabel(VALIDATION_ERROR_LABEL)
    rates = [(m["iteration"], m["iteration_steps_per_s"]) for m in metrics if m.get("iteration_steps_per_s")]
    if rates:
        x, y = zip(*rates, strict=True)
        bottom.plot(x, y, color="C2", linewidth=1.2, marker="o" if len(x) == 1 else None)
        bottom.set_ylim(bottom=0.0)
    bottom.set_title("throughput", fontsize="medium")
    bottom.set_ylabel(THROUGHPUT_LABEL)
    bottom.set_xlabel("learning iteration")
    iterations = [m["iteration"] for m in metrics] + [v["iterations"] for v in validation]
    if iterations:  # at least one whole number either side, or the locator falls back to fractions
        low, high = min(iterations), max(iterations)
        pad = max(1.0, 0.03 * (high - low))
        bottom.set_xlim(low - pad, high + pad)
    bottom.xaxis.set_major_locator(MaxNLocator(integer=True))
    for ax in (top, middle, bottom):
        ax.grid(alpha=0.3)
    fig.suptitle(title or "Learning curve")
    return fig


ROBUSTNESS_FLOOR_PCT = -100.0
"""Improvements below this are drawn at it, with their value written (:func:`robustness_figure`)."""


def plot_robustness(
    reports: Sequence[dict], out_dir: str | os.PathLike, name: str = "robustness"
) -> list[Path]:
    """The paper's Fig. 5 for ``reports`` of :func:`agents.pipelines.robustness.robustness_study`: one panel
    per report,
    each method's median over trials at every value of the sweep with its interquartile band, the nominal
    value dashed; improvement studies mark 0 (no tension). Writes ``NAME.png`` and ``NAME.svg``."""
    return save_figure(robustness_figure(reports), out_dir, name)


def robustness_figure(reports: Sequence[dict], floor_pct: float = ROBUSTNESS_FLOOR_PCT) -> Figure:
    """What :func:`plot_robustness` saves. A method keeps its colour in every panel; improvements below
    ``floor_pct`` (e.g. a policy dragging a sheet that hangs flat, where no tension is nearly exact) are
    drawn at the floor with their value written beside them, so they do not squash the rest."""
    if not reports:
        raise ValueError("reports: give at least one robustness report")
    names = list(dict.fromkeys(m for report in reports for m in report["methods"]))
    colours = {m: f"C{k % 10}" for k, m in enumerate(names)}
    fig = Figure(figsize=(4.6 * len(reports), 3.6), layout="constrained")
    axes = fig.subplots(1, len(reports), squeeze=False)[0]
    for ax, report in zip(axes, reports, strict=True):
        values = np.asarray(report["values"], dtype=np.float64)
        floor = floor_pct if report["metric"] == "improvement_pct" else -np.inf
        below: dict[float, int] = {}  # off-scale labels already written at each value: stacked
        for method in report["methods"]:
            stats = {
                q: np.array([np.nan if v is None else v for v in report[method][q]], dtype=np.float64)
                for q in ("median", "q25", "q75")
            }
            shown = np.maximum(stats["median"], floor)
            colour = colours[method]
            ax.plot(values, shown, "o-", color=colour, label=method, markersize=3.5)
            band = [np.maximum(stats[q], floor) for q in ("q25", "q75")]
            ax.fill_between(values, *band, color=colour, alpha=0.15, linewidth=0)
            for x, med in zip(values, stats["median"], strict=True):
                if med < floor:
                    k = below[x] = below.get(x, -1) + 1
                    ax.annotate(f"{med:.0f}%", (x, floor), xytext=(4, 3 + 8 * k), textcoords="offset points",
                                fontsize=6, color=colour)  # fmt: skip
        ax.axvline(report["nominal"], color="0.3", linestyle="--", linewidth=1, label="nominal")
        if report["metric"] == "improvement_pct":
            ax.axhline(0.0, color="0.5", linewidth=0.8)
            ax.set_ylabel("improvement over no tension (%)")
        else:
            ax.set_ylabel("error (% of the sheet)")
        ax.set_xlabel(report["unit"])
        ax.set_title(f"{report['contour']}: {report['study']} ({report['trials']} trials)", fontsize=10)
        ax.legend(fontsize=7, loc="best", framealpha=0.8)
    fig.text(
        0.01,
        -0.02,
        f"lines: median over trials; bands: 25th to 75th percentile; floor {floor_pct:g}%",
        fontsize=7,
    )
    return fig
