"""Arc length along polylines, and resampling them at an even arc-length spacing.

A polyline is an (N, D) array of points in any dimension D (material x-y in mm, world x-y-z, ...); a closed
one returns from its last point to its first, which is not repeated.
"""

from __future__ import annotations

import math

import numpy as np


def arc_lengths(points: np.ndarray, closed: bool = False) -> np.ndarray:
    """Cumulative arc length at each vertex, from 0 at ``points[0]``.

    Args:
        points: (N, D) polyline.
        closed: Whether the polyline returns to its first point.

    Returns:
        (N,) lengths; closed: (N + 1,), the last after the closing edge back to ``points[0]``.
    """
    line = ring(points, closed)
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])


def polyline_length(points: np.ndarray) -> float:
    """Length of an open (N, D) polyline: the sum of its edge lengths."""
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def resample_polyline(
    points: np.ndarray, spacing: float, closed: bool = False, *, arc: np.ndarray | None = None
) -> np.ndarray:
    """Points every ``spacing`` of arc length along the polyline, starting at ``points[0]``.

    Args:
        points: (N, D) polyline.
        spacing: Arc length between consecutive samples, positive.
        closed: Whether the polyline returns to its first point.
        arc: The arc length at each vertex that spaces the samples (default :func:`arc_lengths` of
            ``points``, (N,), or (N + 1,) when closed). Pass another polyline's, with the same number of
            vertices, to sample ``points`` where that polyline is evenly spaced (e.g. the material points
            under an evenly spaced world path).

    Returns:
        (M, D) samples. Open: the last is the end point, so the last step may be shorter. Closed: the start
        is not repeated, so the step back to it may be shorter.

    Raises:
        ValueError: for a non-positive ``spacing`` or an ``arc`` that does not match ``points``.
    """
    if not spacing > 0:
        raise ValueError(f"spacing: must be positive (got {spacing!r})")
    line = ring(points, closed)
    arc = arc_lengths(points, closed) if arc is None else np.asarray(arc, dtype=np.float64)
    if arc.shape != (len(line),):
        raise ValueError(f"arc: expected shape ({len(line)},) for this polyline, got {arc.shape}")
    total = arc[-1]
    # Round-off must not add a sample a hair before the end (open) or the start (closed).
    count = int(math.ceil(total / spacing - 1e-9))
    s = spacing * np.arange(count)
    if not closed:
        s = np.append(s, total)
    return np.stack([np.interp(s, arc, line[:, d]) for d in range(line.shape[1])], axis=1)


def ring(points: np.ndarray, closed: bool = True) -> np.ndarray:
    """The polyline as drawn: a closed one with its first point repeated at the end; an open one as is."""
    return np.concatenate([points, points[:1]]) if closed else points
