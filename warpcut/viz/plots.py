"""Figures of a run, as PNG and SVG written atomically: the Table I comparison (with rliable-style
aggregates over contours), the cut regions, a training run's learning curve and a cut plan's pinch
candidates. ``plot_improvements``, ``plot_learning_curve`` and ``plot_pinch_candidates`` save what
``improvement_figure``, ``learning_curve_figure`` and ``pinch_candidates_figure`` draw.

Figures are drawn on ``matplotlib.figure.Figure`` objects (Agg), never through pyplot, so plotting needs
no display and leaves matplotlib's global state alone.
"""

from __future__ import annotations

import io
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import ListedColormap, Normalize
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Rectangle
from matplotlib.ticker import MaxNLocator

from warpcut.contours import Contour, ring
from warpcut.io import WriteFailed, safe_name, write_atomic
from warpcut.planning import Plan, pinch_feasible
from warpcut.scoring import BOOTSTRAP_RESAMPLES, Score, bootstrap_ci, paired_improvement
from warpcut.sim.config import SheetGrid, SimConfig
from warpcut.task import CuttingTask

FORMATS = ("png", "svg")

# Separated-material categories on the sheet: neither, intended and separated, intended only, separated only.
_REGION_LABELS = (
    "sheet",
    "separated as intended",
    "intended, not separated",
    "separated, not intended",
)
_REGION_COLOURS = ("#eeeeee", "#b8e0b5", "#ffd8a8", "#f4a6a6")
_PATH_COLOUR = "#1f4fd1"


def save_figure(fig: Figure, out_dir: str | os.PathLike, name: str) -> list[Path]:
    """Write ``fig`` as ``out_dir/NAME.png`` and ``out_dir/NAME.svg``, each atomically, where NAME is
    :func:`~warpcut.io.safe_name` of ``name`` (``name`` itself when it is a plain file name).

    Raises:
        ValueError: ``out_dir`` (or a parent) is a file, or a figure's path is a directory; or the disk is
            full (the ``OSError`` is its cause): the message names the file, and a figure written before
            stays as it was.
    """
    out_dir = Path(out_dir)
    for where in (out_dir, *out_dir.parents):
        if where.exists() and not where.is_dir():
            raise ValueError(f"{where}: is a file, not a directory for the figures; choose another output")
    paths = []
    for fmt in FORMATS:
        path = out_dir / f"{safe_name(name)}.{fmt}"  # a contour's name may be anything: never a path
        if path.is_dir():
            raise ValueError(f"{path}: is a directory, not a figure file; remove it or choose another output")
        buffer = io.BytesIO()
        fig.savefig(buffer, format=fmt, dpi=150, bbox_inches="tight")
        try:
            paths.append(write_atomic(path, buffer.getvalue()))
        except WriteFailed as exc:
            raise ValueError(
                f"{exc.path}: not written, {exc.reason}; {exc.fix}, then plot again (or skip the plots: "
                "--set plots=false)"
            ) from exc.__cause__
    return paths


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


@dataclass
class FinalCut:
    """One method's cut of one env (the first of its contour in the batch), as it ended."""

    contour: Contour
    grid: SheetGrid
    score: Score
    """That env's score alone (``B = 1``)."""
    pinch: np.ndarray | None
    """Material pinch point (mm), ``None`` without a grasp."""
    trials: int = 1
    """Envs of this contour in the batch (the trials); the cut shown is the first's."""


class FinalCuts:
    """Step callbacks that keep, per contour of a batch, the end of each method's episode in the first env
    of that contour, for :func:`plot_regions`.

    Envs of a contour are found by the contour's name in ``task.contours``, so a batch may hold several
    contours in any order (e.g. :func:`agents.evaluation.evaluate_suite`'s, contour by contour, trials
    within) and several batches of one method may fill different contours (e.g. the rl column, one batch
    per contour). The cut is scored once per batch, when the episode is done.
    """

    def __init__(self) -> None:
        self.cuts: dict[str, dict[str, FinalCut]] = {}
        """Contour name to method name to its final cut, contours and methods in the order first seen."""

    def step_callback(self, method: str):
        """A new step callback, for ``task.run(policy, on_step=cuts.step_callback(method))``, that keeps
        ``method``'s cuts at the end of the episode."""

        def callback(task: CuttingTask, action) -> None:
            if task.done:
                self.capture(task, method)

        return callback

    def capture(self, task: CuttingTask, method: str) -> None:
        """Score the first env of each contour of ``task`` as it stands and keep it as ``method``'s cut."""
        first: dict[str, int] = {}
        trials: dict[str, int] = {}
        for env, contour in enumerate(task.contours):
            first.setdefault(contour.name, env)
            trials[contour.name] = trials.get(contour.name, 0) + 1
        scores = task.score()
        for name, env in first.items():
            contour = task.contours[env]
            score = scores.select([env])
            pinch = task.pinch_points[env].copy() if task.sim.grasped[env] else None
            self.cuts.setdefault(name, {})[method] = FinalCut(contour, task.grid, score, pinch, trials[name])

    def of(self, contour: str, methods: Sequence[str] | None = None) -> dict[str, FinalCut]:
        """``contour``'s cuts by method: those of ``methods`` in that order (default: all, as captured)."""
        cuts = self.cuts.get(contour, {})
        if methods is None:
            return dict(cuts)
        return {m: cuts[m] for m in methods if m in cuts}

    def plot(
        self,
        out_dir: str | os.PathLike,
        methods: Sequence[str] | None = None,
        contours: Sequence[str] | None = None,
    ) -> list[Path]:
        """One :func:`plot_regions` figure per contour, ``out_dir/CONTOUR.png`` and ``.svg``.

        Args:
            out_dir: Where the figures go.
            methods: The methods to show, in order (default: all captured).
            contours: The contours to plot, in order (default: all captured); those without a cut are
                skipped.

        Returns:
            The paths written.
        """
        paths = []
        for name in self.cuts if contours is None else contours:
            cuts = self.of(name, methods)
            if cuts:
                paths += plot_regions(cuts, out_dir, name=name)
        return paths


def plot_regions(cuts: dict[str, FinalCut], out_dir: str | os.PathLike, name: str = "regions") -> list[Path]:
    """One contour, per method on the sheet at rest: the intended contour (black), the region its cut path
    encloses (blue: the path score's Y, with the path's points) and, shaded, the material that came free
    (the separated score). The title gives both errors, the protocol's score first.

    Args:
        cuts: Method name to its final cut of one contour (see :meth:`FinalCuts.of`).
        out_dir: Where ``NAME.png`` and ``NAME.svg`` go.
        name: File name stem.

    Returns:
        The paths written.

    Raises:
        ValueError: ``cuts`` is empty, or its cuts are of different contours.
    """
    if not cuts:
        raise ValueError("plot_regions: no cuts to plot")
    first = next(iter(cuts.values()))
    if len({cut.contour.name for cut in cuts.values()}) > 1:
        raise ValueError("plot_regions: give the cuts of one contour (see FinalCuts.of)")
    fig = Figure(figsize=(3.4 * len(cuts) + 0.6, 4.4), layout="constrained")
    axes = fig.subplots(1, len(cuts), squeeze=False)[0]
    cmap = ListedColormap(_REGION_COLOURS)
    for k, (ax, (method, cut)) in enumerate(zip(axes, cuts.items(), strict=True)):
        grid, score = cut.grid, cut.score
        intended = np.broadcast_to(score.intended, score.achieved.shape)[0]
        achieved = score.achieved[0]
        category = np.select(
            [intended & achieved, intended & ~achieved, achieved & ~intended], [1, 2, 3], default=0
        )
        hx, hy = grid.spacing_mm
        ax.imshow(
            category.reshape(grid.ny, grid.nx),
            origin="lower",
            extent=(-hx / 2, grid.width_mm + hx / 2, -hy / 2, grid.height_mm + hy / 2),
            cmap=cmap,
            vmin=-0.5,
            vmax=len(_REGION_COLOURS) - 0.5,
            interpolation="nearest",
        )
        points = ring(cut.contour.points, cut.contour.closed)
        ax.plot(points[:, 0], points[:, 1], color="black", linewidth=1.0)
        region = score.cut_regions[0]
        if region is not None and not region.is_empty:
            for polygon in getattr(region, "geoms", [region]):
                if hasattr(polygon, "exterior"):
                    line = np.asarray(polygon.exterior.coords)
                    ax.fill(line[:, 0], line[:, 1], facecolor=_PATH_COLOUR, alpha=0.12, edgecolor="none")
                    ax.plot(line[:, 0], line[:, 1], color=_PATH_COLOUR, linewidth=1.0, linestyle="--")
        path = score.cut_paths[0]
        if len(path):
            ax.plot(path[:, 0], path[:, 1], ".", color=_PATH_COLOUR, markersize=1.5)
        if cut.pinch is not None:
            ax.plot(*cut.pinch, marker="x", color="magenta", markersize=8, markeredgewidth=2)
        path_text = f"path {score.path_error_vertices[0]:.1f}"
        separated_text = f"separated {score.separated_error_vertices[0]:.0f}"
        first_text, second_text = (
            (path_text, separated_text) if score.metric == "path" else (separated_text, path_text)
        )
        ax.set_title(f"{method}: {first_text} ({second_text}) vertices", fontsize="small")
        ax.set_xlabel("x (mm)")
        if k == 0:
            ax.set_ylabel("y (mm)")
        ax.set_aspect("equal")
    handles = [Patch(color=c, label=label) for c, label in zip(_REGION_COLOURS, _REGION_LABELS, strict=True)]
    handles += [
        Line2D([], [], color="black", linewidth=1.0, label="intended contour"),
        Line2D([], [], color=_PATH_COLOUR, linestyle="--", label="region the cut path encloses"),
        Line2D([], [], color="magenta", marker="x", linestyle="none", label="pinch point"),
    ]
    fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize="small", frameon=False)
    trial = f", first of {first.trials} trials" if first.trials > 1 else ""
    fig.suptitle(f"{first.contour.name}{trial}: the cut path and the separated material", y=1.04)
    return save_figure(fig, out_dir, name)


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


def feasible_grid(
    plan: Plan, config: SimConfig, step_mm: float = 1.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pinch feasibility sampled on a grid over the sheet, as :func:`~warpcut.planning.plan_cut` judged
    it: :func:`~warpcut.planning.pinch_feasible` with the plan's contour, segments and arm.

    Args:
        plan: The plan (its contour, segments and ``arm``).
        config: The simulation parameters the plan was made with (sheet size, grasp radius, fixture).
        step_mm: Grid spacing (mm), > 0.

    Returns:
        ``(xs, ys, feasible)``: (NX,) and (NY,) sample coordinates (mm), and (NY, NX) bool, ``feasible[j, i]``
        for the point ``(xs[i], ys[j])``.
    """
    if not step_mm > 0:
        raise ValueError(f"step_mm: must be > 0 (got {step_mm!r})")
    xs = np.arange(0.0, config.width_mm + 1e-9, step_mm)
    ys = np.arange(0.0, config.height_mm + 1e-9, step_mm)
    points = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    feasible = pinch_feasible(points, plan.contour, config, plan.segments, plan.arm)
    return xs, ys, feasible.reshape(len(ys), len(xs))


def candidate_counts(plan: Plan) -> tuple[int, bool]:
    """``(sampled, centroid)``: how many of ``plan.candidates`` were sampled from the feasible region, and
    whether the contour's centroid is a candidate too (it is added, first, when feasible; otherwise it is
    in ``plan.rejected``). ``plan_cut(num_candidates=N)`` scores ``N + 1`` candidates where the centroid is
    feasible."""
    centroid = np.asarray(plan.contour.centroid, dtype=np.float64)
    included = any(
        np.array_equal(np.asarray(c["point"], dtype=np.float64), centroid) for c in plan.candidates
    )
    return len(plan.candidates) - included, included


def candidate_summary(plan: Plan) -> str:
    """The candidates counted in words, as the map's title says it: "9 pinch candidates: 8 sampled + the
    centroid", or "8 sampled pinch candidates; the centroid is infeasible"."""
    sampled, centroid = candidate_counts(plan)
    if centroid:
        return f"{sampled + 1} pinch candidates: {sampled} sampled + the centroid"
    text = f"{sampled} sampled pinch candidate{'' if sampled == 1 else 's'}"
    return text + ("; the centroid is infeasible" if plan.rejected else "")


def plot_pinch_candidates(
    plan: Plan, config: SimConfig, out_dir: str | os.PathLike, name: str = "pinch_candidates"
) -> list[Path]:
    """The plan on the rest sheet: where a pinch is feasible, the contour and its segments, every
    candidate coloured by its error with fixed tension, the rejected points and the chosen pinch.

    The feasible region is :func:`feasible_grid` at 1 mm (shaded green); segments are drawn in cutting
    order with their notch (circle, where the scissors enter) and termination (square); candidates are
    coloured by ``error_vertices`` (their best order's, colour bar), the sampled ones as dots and the
    centroid (where feasible) as a diamond; rejected points (``plan.rejected``, the centroid when
    infeasible) are crosses labelled with the rules they break; the chosen pinch is ringed. Every legend
    entry is drawn as on the map. The title counts the candidates as :func:`candidate_counts` does.

    Args:
        plan: From :func:`~warpcut.planning.plan_cut`.
        config: The simulation parameters the plan was made with.
        out_dir: Where ``NAME.png`` and ``NAME.svg`` go.
        name: File name stem.

    Returns:
        The paths written.
    """
    return save_figure(pinch_candidates_figure(plan, config), out_dir, name)


def pinch_candidates_figure(plan: Plan, config: SimConfig) -> Figure:
    """:func:`plot_pinch_candidates`' figure, unsaved."""
    fig = Figure(figsize=(7.2, 6.6), layout="constrained")
    ax = fig.add_subplot()
    xs, ys, feasible = feasible_grid(plan, config)
    step = xs[1] - xs[0] if len(xs) > 1 else 1.0
    ax.imshow(
        feasible,
        origin="lower",
        extent=(xs[0] - step / 2, xs[-1] + step / 2, ys[0] - step / 2, ys[-1] + step / 2),
        cmap=ListedColormap(["#eeeeee", "#cdeccd"]),
        vmin=0,
        vmax=1,
        interpolation="nearest",
    )
    ax.add_patch(Rectangle((0.0, 0.0), config.width_mm, config.height_mm, fill=False, color="black"))
    handles = [
        Patch(color="#cdeccd", label="feasible pinch region"),
        Patch(color="#eeeeee", label="infeasible"),
    ]
    points = ring(plan.contour.points, plan.contour.closed)
    handles += ax.plot(
        points[:, 0], points[:, 1], color="black", linewidth=0.8, linestyle="--", label="contour"
    )
    handles += _draw_segments(ax, plan)
    handles += _draw_candidates(fig, ax, plan)
    for rejected in plan.rejected:
        violates = ", ".join(rejected.get("violates", [])) or "infeasible"
        handles += ax.plot(
            *rejected["point"], marker="x", color="red", markersize=10, markeredgewidth=2, linestyle="",
            label=f"centroid, infeasible ({violates})", zorder=5,
        )  # fmt: skip
    pinch = np.asarray(plan.chosen["pinch"], dtype=np.float64)
    handles += ax.plot(
        *pinch, marker="o", markersize=16, markerfacecolor="none", markeredgecolor="red", markeredgewidth=2.5,
        linestyle="", zorder=6,
        label=f"chosen ({pinch[0]:.1f}, {pinch[1]:.1f}): {plan.chosen['error_vertices']:.1f} vertices",
    )  # fmt: skip
    ax.set_xlim(-2.0, config.width_mm + 2.0)
    ax.set_ylim(-2.0, config.height_mm + 2.0)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    length = "inf" if math.isinf(plan.arm.length_mm) else f"{plan.arm.length_mm:g} mm"
    counted = candidate_summary(plan)
    ax.set_title(
        f"{plan.contour.name}: {counted}\narm radius {plan.arm.radius_mm:g} mm, length {length}",
        fontsize="medium",
    )
    fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize="small", frameon=False)
    return fig


_NOTCH = {"marker": "o", "markersize": 7, "markerfacecolor": "white", "markeredgecolor": "black"}
_TERMINATION = {"marker": "s", "markersize": 6, "markerfacecolor": "white", "markeredgecolor": "black"}


def _draw_segments(ax, plan: Plan) -> list:
    """The plan's segments in cutting order, each with its notch and termination; their legend handles."""
    handles = []
    for rank, k in enumerate(plan.order):
        segment = plan.segments[k]
        handles += ax.plot(
            segment.points[:, 0], segment.points[:, 1], color=f"C{rank % 10}", linewidth=2.0,
            label=f"segment {k}, cut {rank + 1}.",
        )  # fmt: skip
        ax.plot(*segment.notch, linestyle="", zorder=3, **_NOTCH)
        ax.plot(*segment.termination, linestyle="", zorder=3, **_TERMINATION)
    handles.append(Line2D([], [], linestyle="", label="notch (the scissors enter)", **_NOTCH))
    handles.append(Line2D([], [], linestyle="", label="termination", **_TERMINATION))
    return handles


def _draw_candidates(fig: Figure, ax, plan: Plan) -> list:
    """The candidates coloured by their error (one colour bar): sampled ones as dots, the centroid (if a
    candidate) as a diamond; their legend handles (the drawn markers themselves)."""
    if not plan.candidates:
        return []
    points = np.array([c["point"] for c in plan.candidates], dtype=np.float64)
    errors = np.array([c["error_vertices"] for c in plan.candidates], dtype=np.float64)
    is_centroid = np.all(points == np.asarray(plan.contour.centroid, dtype=np.float64), axis=1)
    norm = Normalize(
        vmin=float(errors.min()), vmax=float(errors.max()) + 1e-9 * (errors.min() == errors.max())
    )
    handles = []
    for chosen, marker, size, label in (
        (~is_centroid, "o", 40, "sampled candidate (fill: its error)"),
        (is_centroid, "D", 60, "the centroid, a candidate (fill: its error)"),
    ):
        if chosen.any():
            handles.append(
                ax.scatter(
                    points[chosen, 0], points[chosen, 1], c=errors[chosen], cmap="viridis_r", norm=norm,
                    marker=marker, s=size, edgecolors="black", zorder=4, label=label,
                )
            )  # fmt: skip
    fig.colorbar(
        ScalarMappable(norm=norm, cmap="viridis_r"),
        ax=ax,
        label="error with fixed tension (vertices)",
        shrink=0.8,
    )
    return handles


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
