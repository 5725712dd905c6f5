"""Figures of a run, as PNG and SVG written atomically: the Table I comparison, the cut regions, a
training run's learning curve and a cut plan's pinch candidates.

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
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Rectangle

from warpcut.contours import Contour, ring
from warpcut.io import DiskFull, safe_name, write_atomic
from warpcut.planning import Plan, pinch_feasible
from warpcut.scoring import Score
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
        except DiskFull as exc:
            raise ValueError(f"{exc}: free space, then plot again (or skip the plots with --no-plots)") from (
                exc.__cause__
            )
    return paths


def plot_improvements(report: dict, methods: Sequence[str], out_dir: str | os.PathLike) -> list[Path]:
    """Table I as grouped bars: per contour (and their mean) each method's improvement over no tension,
    with its 95% confidence interval.

    Args:
        report: :func:`agents.evaluation.evaluate_suite`'s report.
        methods: The methods to show; ``none`` (the reference, 0 by definition) is left out.
        out_dir: Where ``improvement.png`` and ``improvement.svg`` go.

    Returns:
        The paths written.
    """
    shown = [m for m in methods if m != "none"]
    groups = [*report["rows"], {"contour": "mean", **report["mean"]}]
    fig = Figure(
        figsize=(max(6.0, 0.9 * len(groups) * max(1, len(shown)) ** 0.5 + 2), 4.5), layout="constrained"
    )
    ax = fig.add_subplot()
    x = np.arange(len(groups))
    width = 0.8 / max(1, len(shown))
    for k, method in enumerate(shown):
        values = [g[f"{method}_improvement_pct"] for g in groups]
        ci = [g[f"{method}_ci95"] for g in groups]
        ax.bar(x + (k - (len(shown) - 1) / 2) * width, values, width, yerr=ci, capsize=3, label=method)
    ax.axhline(0.0, color="black", linewidth=0.8)
    ax.set_xticks(x, [g["contour"] for g in groups], rotation=45 if len(groups) > 4 else 0, ha="right")
    ax.set_ylabel("improvement over no tension (%)")
    ax.set_title(f"Cut error reduction, {report['trials']} trial(s) per contour (95% CI)")
    if shown:
        ax.legend()
    return save_figure(fig, out_dir, "improvement")


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


def plot_learning_curve(
    metrics: Sequence[dict],
    validation: Sequence[dict],
    out_dir: str | os.PathLike,
    name: str = "learning_curve",
    title: str | None = None,
) -> list[Path]:
    """A training run over its learning iterations: errors above, throughput below.

    Top: the mean final error of the training episodes that ended in each iteration (``final_error``,
    error mm² / intended area; iterations where none ended are skipped) and, on its own y axis on the
    right, the deterministic policy's validation error in vertices, with its minimum marked (the
    policy kept as ``best.pt``). Bottom: env steps per second of each iteration.

    Args:
        metrics: One dict per iteration: ``iteration`` (iterations done, from 1), ``final_error`` (float
            or None), ``mean_return`` (float or None, not drawn) and ``iteration_steps_per_s``.
        validation: ``{"iterations": int, "error": float}`` per validation (0 = the initial policy);
            may be empty.
        out_dir: Where ``NAME.png`` and ``NAME.svg`` go.
        name: File name stem.
        title: Figure title; default "Learning curve".

    Returns:
        The paths written.
    """
    fig = Figure(figsize=(7.5, 6.0), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=[2, 1])
    ended = [(m["iteration"], m["final_error"]) for m in metrics if m.get("final_error") is not None]
    handles = []
    if ended:
        x, y = zip(*ended, strict=True)
        marker = "o" if len(x) == 1 else None  # a line needs two points
        handles += top.plot(
            x, y, color="C0", linewidth=1.2, marker=marker, label="final error, training episodes"
        )
    else:
        top.text(0.5, 0.5, "no training episode has ended", transform=top.transAxes, ha="center", color="C0")
    top.set_ylabel("final error (error mm² / intended area)", color="C0")
    top.tick_params(axis="y", colors="C0")
    right = top.twinx()
    if validation:
        x = [v["iterations"] for v in validation]
        y = [v["error"] for v in validation]
        handles += right.plot(x, y, "o-", color="C1", markersize=4, label="validation error (vertices)")
        best = int(np.argmin(y))
        handles.append(
            right.scatter(
                x[best],
                y[best],
                marker="*",
                s=220,
                color="C3",
                zorder=5,
                label=f"best validation: {y[best]:.1f} vertices at iteration {x[best]}",
            )
        )
    else:
        right.text(0.5, 0.4, "no validation yet", transform=top.transAxes, ha="center", color="C1")
    right.set_ylabel("validation error (vertices)", color="C1")
    right.tick_params(axis="y", colors="C1")
    if handles:
        top.legend(handles=handles, loc="upper right", fontsize="small")
    rates = [(m["iteration"], m["iteration_steps_per_s"]) for m in metrics if m.get("iteration_steps_per_s")]
    if rates:
        x, y = zip(*rates, strict=True)
        bottom.plot(x, y, color="C2", linewidth=1.2, marker="o" if len(x) == 1 else None)
        bottom.set_ylim(bottom=0.0)
    bottom.set_ylabel("env steps/s")
    bottom.set_xlabel("learning iteration")
    top.grid(alpha=0.3)
    bottom.grid(alpha=0.3)
    fig.suptitle(title or "Learning curve")
    return save_figure(fig, out_dir, name)


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


def plot_pinch_candidates(
    plan: Plan, config: SimConfig, out_dir: str | os.PathLike, name: str = "pinch_candidates"
) -> list[Path]:
    """The plan on the rest sheet: where a pinch is feasible, the contour and its segments, every
    candidate coloured by its error with fixed tension, the rejected points and the chosen pinch.

    The feasible region is :func:`feasible_grid` at 1 mm (shaded green); segments are drawn in cutting
    order with their notch (circle, where the scissors enter) and termination (square); candidates are
    coloured by ``error_vertices`` (their best order's, colour bar); rejected points (``plan.rejected``,
    e.g. the centroid when infeasible) are crosses labelled with the rules they break; the chosen pinch
    is ringed.

    Args:
        plan: From :func:`~warpcut.planning.plan_cut`.
        config: The simulation parameters the plan was made with.
        out_dir: Where ``NAME.png`` and ``NAME.svg`` go.
        name: File name stem.

    Returns:
        The paths written.
    """
    fig = Figure(figsize=(7.2, 6.2), layout="constrained")
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
    for rank, k in enumerate(plan.order):
        segment = plan.segments[k]
        colour = f"C{rank % 10}"
        handles += ax.plot(
            segment.points[:, 0],
            segment.points[:, 1],
            color=colour,
            linewidth=2.0,
            label=f"segment {k}, cut {rank + 1}.",
        )
        ax.plot(*segment.notch, marker="o", color=colour, markersize=7, markeredgecolor="black")
        ax.plot(*segment.termination, marker="s", color=colour, markersize=6, markeredgecolor="black")
    handles.append(
        Line2D([], [], marker="o", color="grey", markeredgecolor="black", linestyle="", label="notch")
    )
    handles.append(
        Line2D([], [], marker="s", color="grey", markeredgecolor="black", linestyle="", label="termination")
    )
    if plan.candidates:
        candidates = np.array([c["point"] for c in plan.candidates], dtype=np.float64)
        errors = np.array([c["error_vertices"] for c in plan.candidates], dtype=np.float64)
        dots = ax.scatter(
            candidates[:, 0], candidates[:, 1], c=errors, cmap="viridis_r", s=40, edgecolors="black", zorder=4
        )
        fig.colorbar(dots, ax=ax, label="error with fixed tension (vertices)", shrink=0.8)
    for rejected in plan.rejected:
        violates = ", ".join(rejected.get("violates", [])) or "infeasible"
        handles += ax.plot(
            *rejected["point"],
            marker="x",
            color="red",
            markersize=10,
            markeredgewidth=2,
            linestyle="",
            label=f"rejected ({violates})",
            zorder=5,
        )
    pinch = np.asarray(plan.chosen["pinch"], dtype=np.float64)
    handles += ax.plot(
        *pinch,
        marker="o",
        markersize=16,
        markerfacecolor="none",
        markeredgecolor="red",
        markeredgewidth=2.5,
        linestyle="",
        label=f"chosen ({pinch[0]:.1f}, {pinch[1]:.1f}): {plan.chosen['error_vertices']:.1f} vertices",
        zorder=6,
    )
    ax.set_xlim(-2.0, config.width_mm + 2.0)
    ax.set_ylim(-2.0, config.height_mm + 2.0)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    length = "inf" if math.isinf(plan.arm.length_mm) else f"{plan.arm.length_mm:g} mm"
    ax.set_title(
        f"{plan.contour.name}: {len(plan.candidates)} pinch candidate(s), "
        f"arm radius {plan.arm.radius_mm:g} mm, length {length}"
    )
    fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize="small", frameon=False)
    return save_figure(fig, out_dir, name)
