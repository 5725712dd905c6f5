"""Figures of a run, as PNG and SVG written atomically: the Table I comparison and the cut regions.

Figures are drawn on ``matplotlib.figure.Figure`` objects (Agg), never through pyplot, so plotting needs
no display and leaves matplotlib's global state alone.
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from warpcut.config import SheetGrid
from warpcut.contours import Contour
from warpcut.io import write_atomic
from warpcut.scoring import Score, symmetric_difference
from warpcut.task import CuttingTask

FORMATS = ("png", "svg")

# Region categories on the sheet: neither, intended and separated, intended only, separated only.
_REGION_LABELS = (
    "sheet",
    "cut as intended",
    "missed (intended, not separated)",
    "excess (separated, not intended)",
)
_REGION_COLOURS = ("#e8e8e8", "#4daf4a", "#ff9f1c", "#e41a1c")


def save_figure(fig: Figure, out_dir: str | os.PathLike, name: str) -> list[Path]:
    """Write ``fig`` as ``out_dir/name.png`` and ``out_dir/name.svg``, each atomically."""
    paths = []
    for fmt in FORMATS:
        buffer = io.BytesIO()
        fig.savefig(buffer, format=fmt, dpi=150, bbox_inches="tight")
        paths.append(write_atomic(Path(out_dir) / f"{name}.{fmt}", buffer.getvalue()))
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
    """One method's cut of the first env of its batch, as it ended."""

    contour: Contour
    grid: SheetGrid
    score: Score
    """The first env's score alone (``B = 1``)."""
    pinch: np.ndarray | None
    """Material pinch point (mm), ``None`` without a grasp."""


class FinalCuts:
    """Step callbacks that keep the end of each method's episode for :func:`plot_regions`."""

    def __init__(self) -> None:
        self.cuts: dict[str, FinalCut] = {}

    def on_step(self, method: str):
        """A callback for ``task.run(policy, on_step=...)`` that scores the first env at the end."""

        def on_step(task: CuttingTask, action) -> None:
            if task.done:
                contour = task.contours[0]
                score = symmetric_difference(task.sim.alive_mask()[0], contour.intended_region(), task.grid)
                pinch = task.pinch_points[0]
                self.cuts[method] = FinalCut(
                    contour, task.grid, score, pinch if task.sim.grasped[0] else None
                )

        return on_step


def plot_regions(cuts: dict[str, FinalCut], out_dir: str | os.PathLike, name: str = "regions") -> list[Path]:
    """Per method, the intended region over the region its cut separated, on the sheet at rest.

    Args:
        cuts: Method name to its final cut (see :class:`FinalCuts`).
        out_dir: Where ``NAME.png`` and ``NAME.svg`` go.
        name: File name stem.

    Returns:
        The paths written.

    Raises:
        ValueError: ``cuts`` is empty.
    """
    if not cuts:
        raise ValueError("plot_regions: no cuts to plot")
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
        points = cut.contour.points
        if cut.contour.closed:
            points = np.vstack([points, points[:1]])
        ax.plot(points[:, 0], points[:, 1], color="black", linewidth=1.0)
        if cut.pinch is not None:
            ax.plot(*cut.pinch, marker="x", color="blue", markersize=8, markeredgewidth=2)
        ax.set_title(f"{method}: {score.error_vertices[0]:.0f} vertices ({score.error_mm2[0]:.0f} mm²)")
        ax.set_xlabel("x (mm)")
        if k == 0:
            ax.set_ylabel("y (mm)")
        ax.set_aspect("equal")
    handles = [Patch(color=c, label=label) for c, label in zip(_REGION_COLOURS, _REGION_LABELS, strict=True)]
    fig.legend(handles=handles, loc="outside lower center", ncol=2, fontsize="small", frameon=False)
    fig.suptitle(
        f"{next(iter(cuts.values())).contour.name}: intended contour (line) over the separated region"
    )
    return save_figure(fig, out_dir, name)
