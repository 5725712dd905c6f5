"""The scissors' open-loop trajectories: the segments a cut follows in material coordinates
(:func:`default_segments`: the whole contour, from where the scissors enter), laid on the settled sheet
(:class:`Trajectory`: one tip position per update, ``trajectory_spacing_mm`` apart along the world path),
and how long a batch's longest one runs before any sheet is settled (:func:`estimate_horizon`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from warpcut.contours import Contour, arc_lengths, resample_polyline, ring
from warpcut.sim.config import SheetGrid, SimConfig
from warpcut.sim.material import material_to_world
from warpcut.validation import fail

MAX_TRAJECTORY_STRETCH = 4.0
"""A trajectory longer than this many times the material path it follows (plus the travel between
segments) means the settled sheet is stretched far beyond gauze: :class:`CuttingTask` refuses it
(:class:`SimulationDiverged`) instead of running an episode that long. A sane sheet stretches a few %."""


def default_segments(contour: Contour) -> list[np.ndarray]:
    """One segment that starts where the scissors enter (the largest x) and follows the whole contour.

    Closed contours run counter-clockwise from their rightmost point back to it; open ones run from
    their end with the larger x. :mod:`warpcut.planning` splits contours the wrist can actually cut.
    """
    points = np.asarray(contour.points, dtype=np.float64)
    if contour.closed:
        start = int(np.argmax(points[:, 0]))
        loop = np.roll(points, -start, axis=0)
        return [ring(loop)]
    return [points if points[0, 0] >= points[-1, 0] else points[::-1].copy()]


@dataclass
class Trajectory:
    """The scissor tip's path for one env, one entry per update.

    Attributes:
        tip: (T, 4) world ``(x, y, z, cutting)``; ``cutting`` is 0 while travelling between segments.
        material: (T, 2) the material point the tip aims at (NaN while travelling).
    """

    tip: np.ndarray
    material: np.ndarray

    @classmethod
    def from_segments(
        cls, segments: Sequence[np.ndarray], settled: np.ndarray, grid: SheetGrid, spacing_mm: float
    ) -> Trajectory:
        """Follow each segment's world position on the settled sheet (open loop), resampled to
        ``spacing_mm`` per update along the world path, with straight non-cutting travel between them."""
        tips, materials = [], []
        for k, segment in enumerate(segments):
            segment = np.asarray(segment, dtype=np.float64)
            dense = _densify(segment, 0.25 * min(grid.spacing_mm))
            world = material_to_world(dense, settled, grid)
            if k > 0:
                travel = resample_polyline(np.stack([tips[-1][-1, :3], world[0]]), spacing_mm)[1:-1]
                tips.append(np.column_stack([travel, np.zeros(len(travel))]))
                materials.append(np.full((len(travel), 2), np.nan))
            arc = arc_lengths(world)
            tip = resample_polyline(world, spacing_mm, arc=arc)
            mat = resample_polyline(dense, spacing_mm, arc=arc)
            tips.append(np.column_stack([tip, np.ones(len(tip))]))
            materials.append(mat)
        return cls(np.vstack(tips).astype(np.float32), np.vstack(materials))


def segments_key(segments: Sequence[np.ndarray] | None) -> int | None:
    """A hashable identity of a cut's polylines (None: the contour as one segment), for caches of what a
    cut order determines (trajectories, no-tension errors)."""
    if segments is None:
        return None
    return hash(tuple(np.ascontiguousarray(s, dtype=np.float64).tobytes() for s in segments))


def estimate_horizon(
    contours: Sequence[Contour],
    segments: Sequence[Sequence[np.ndarray]] | None,
    config: SimConfig,
    margin: float = 1.1,
) -> int:
    """Updates the longest trajectory of a batch takes, from the material paths alone (before the sheet is
    settled): ``margin`` times the longest path (its segments and the travel between them) over
    ``trajectory_spacing_mm``. Each distinct contour or segment list is measured once."""
    lengths = [0.0]
    if segments is None:
        for contour in {id(c): c for c in contours}.values():
            lengths.append(contour.length)
    else:
        for polylines in {id(s): s for s in segments}.values():
            ends, total = [], 0.0
            for polyline in polylines:
                points = np.asarray(polyline, dtype=np.float64).reshape(-1, 2)
                if len(points):
                    total += float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())
                    ends.append((points[0], points[-1]))
            total += sum(float(np.linalg.norm(b[0] - a[1])) for a, b in zip(ends[:-1], ends[1:], strict=True))
            lengths.append(total)
    return math.ceil(margin * max(lengths) / config.trajectory_spacing_mm) + 2


def _densify(polyline: np.ndarray, max_step: float) -> np.ndarray:
    out = [polyline[:1]]
    for a, b in zip(polyline[:-1], polyline[1:], strict=True):
        k = max(1, math.ceil(np.linalg.norm(b - a) / max_step))
        out.append(a + (b - a) * (np.arange(1, k + 1) / k)[:, None])
    return np.vstack(out)


def checked_segments(segments: Any) -> list[list[np.ndarray]] | None:
    """``CuttingTask``'s ``segments`` as float arrays: per env a non-empty list of polylines, each (K >= 2,
    2) finite numbers (mm); :class:`~warpcut.validation.ConfigError` naming the first that is not."""
    if segments is None:
        return None
    what = "per env, a list of polylines, each (K >= 2, 2) finite x, y in mm"
    if isinstance(segments, str | bytes) or not isinstance(segments, Sequence | np.ndarray):
        fail("CuttingTask.segments", what, segments)
    checked = []
    for env, listed in enumerate(segments):
        listable = isinstance(listed, Sequence | np.ndarray) and not isinstance(listed, str | bytes)
        if not (listable and len(listed)):
            fail(f"CuttingTask.segments[{env}]", what, listed)
        polylines = []
        for polyline in listed:
            raw = None if isinstance(polyline, str | bytes) else np.asarray(polyline)
            good = raw is not None and raw.dtype.kind in "iuf" and raw.ndim == 2 and raw.shape[1:] == (2,)
            if not (good and len(raw) >= 2 and np.all(np.isfinite(raw))):
                fail(f"CuttingTask.segments[{env}]", what, polyline)
            polylines.append(raw.astype(np.float64))
        checked.append(polylines)
    return checked
