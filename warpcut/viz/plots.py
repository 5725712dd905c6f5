"""Figures of a cut, as PNG and SVG written atomically (:func:`save_figure`, which the figures of agents'
reports use too, :mod:`agents.plots`): the cut regions of each method (:func:`plot_regions`, from the final
cuts a step callback collects, :class:`FinalCuts`) and a cut plan's pinch candidates
(:func:`plot_pinch_candidates` saves what :func:`pinch_candidates_figure` draws).

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

from warpcut.contours import Contour, ring
from warpcut.io import WriteFailed, safe_name, write_atomic
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
        except WriteFailed as exc:
            raise ValueError(
                f"{exc.path}: not written, {exc.reason}; {exc.fix}, then plot again (or skip the plots: "
                "--set plots=false)"
            ) from exc.__cause__
    return paths


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
