"""Rerun component columns built straight from numpy buffers as arrow arrays, without a Python object per
element: a fraction of what rerun's archetype constructors (``rr.Mesh3D.columns``, ...) spend on a batch
of frames. tests/test_recording.py checks that they are the archetypes' columns.

rerun and pyarrow are imported on first use, so that importing this module stays cheap.
"""

from __future__ import annotations

from functools import cache

import numpy as np


@cache
def _arrow_types():
    """Rerun's arrow types of a 3D point or vector, of a 3D line strip (rerun.components.LineStrip3D) and
    of a triangle's vertex indices, spelled out."""
    import pyarrow as pa

    point = pa.list_(pa.field("item", pa.float32(), nullable=False), 3)
    strip = pa.list_(pa.field("item", point, nullable=False))
    triangle = pa.list_(pa.field("item", pa.uint32(), nullable=False), 3)
    return point, strip, triangle


@cache
def descriptors() -> dict:
    """Rerun's descriptors of the components recorded, by name (``Archetype:component``)."""
    import rerun as rr

    return {
        d.component: d
        for d in (
            rr.Mesh3D.descriptor_vertex_positions(),
            rr.Mesh3D.descriptor_vertex_colors(),
            rr.Mesh3D.descriptor_triangle_indices(),
            rr.Scalars.descriptor_scalars(),
            rr.LineStrips3D.descriptor_strips(),
            rr.Points3D.descriptor_positions(),
            rr.Points3D.descriptor_colors(),
            rr.Arrows3D.descriptor_origins(),
            rr.Arrows3D.descriptor_vectors(),
        )
    }


class _Arrow:
    """A ready-made arrow array as rerun's ``ComponentBatchLike``."""

    __slots__ = ("array",)

    def __init__(self, array):
        self.array = array

    def as_arrow_array(self):
        return self.array


def column(component: str, array, rows: np.ndarray | None = None):
    """The ``rr.ComponentColumn`` of ``component`` (e.g. ``"Mesh3D:vertex_positions"``) holding the arrow
    ``array``, ``rows[i]`` elements in the i-th row (default: one)."""
    import rerun as rr

    return rr.ComponentColumn(descriptors()[component], _Arrow(array), lengths=rows)


def vec3_array(values: np.ndarray):
    """(..., 3) values as an arrow array of 3D points (or vectors)."""
    return _fixed_size_lists(values, np.float32, _arrow_types()[0])


def strip_array(points: np.ndarray):
    """(F, K, 3) points as an arrow array of F line strips of K points."""
    import pyarrow as pa

    frames, k = points.shape[:2]
    offsets = pa.array(np.arange(frames + 1, dtype=np.int32) * k)
    return pa.ListArray.from_arrays(offsets, vec3_array(points), type=_arrow_types()[1])


def ragged_strip_array(strips: list[np.ndarray]):
    """F line strips of (K_f, 3) points each as an arrow array of F strips."""
    import pyarrow as pa

    lengths = [len(strip) for strip in strips]
    offsets = pa.array(np.concatenate([[0], np.cumsum(lengths)]).astype(np.int32))
    points = np.concatenate(strips) if strips else np.zeros((0, 3))
    return pa.ListArray.from_arrays(offsets, vec3_array(points), type=_arrow_types()[1])


def triangle_array(faces: np.ndarray):
    """(T, 3) vertex indices as an arrow array of triangles."""
    return _fixed_size_lists(faces, np.uint32, _arrow_types()[2])


def _fixed_size_lists(values: np.ndarray, dtype, arrow_type):
    """(..., 3) ``values`` as ``dtype`` in an arrow array of ``arrow_type`` (3-element lists)."""
    import pyarrow as pa

    flat = pa.array(np.ascontiguousarray(values, dtype=dtype).reshape(-1))
    return pa.FixedSizeListArray.from_arrays(flat, type=arrow_type)


def uint32_array(values: np.ndarray):
    """``values`` flattened as an arrow array of uint32 (packed colours)."""
    import pyarrow as pa

    return pa.array(np.ascontiguousarray(values, dtype=np.uint32).reshape(-1))


def float64_array(values: np.ndarray):
    """``values`` flattened as an arrow array of float64 (scalars)."""
    import pyarrow as pa

    return pa.array(np.ascontiguousarray(values, dtype=np.float64).reshape(-1))


def cutting_runs(tip: np.ndarray) -> np.ndarray:
    """(R, 2) ``[start, end)`` update ranges in which the (T, 4) ``tip`` trajectory cuts."""
    cutting = np.concatenate([[0], (tip[:, 3] > 0).astype(np.int8), [0]])
    return np.flatnonzero(np.diff(cutting)).reshape(-1, 2)


def cut_path_strips(tip: np.ndarray, runs: np.ndarray, updates: np.ndarray):
    """The path cut so far after each of F ``updates``: per frame, the part of every cutting run
    (:func:`cutting_runs`) of the (T, 4) ``tip`` trajectory that the scissors have passed (at least two
    points), as an arrow array of all frames' line strips, and (F,) how many strips each frame has."""
    import pyarrow as pa

    starts = runs[:, 0]
    lengths = np.minimum(runs[None, :, 1], np.asarray(updates)[:, None]) - starts[None, :]  # (F, R)
    lengths = np.where(lengths >= 2, lengths, 0)
    counts = np.count_nonzero(lengths, axis=1)
    kept = lengths.ravel() > 0
    lengths, starts = (
        lengths.ravel()[kept],
        np.broadcast_to(starts, (len(updates), len(starts))).ravel()[kept],
    )
    offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int32)
    points = tip[np.repeat(starts - offsets[:-1], lengths) + np.arange(offsets[-1]), :3]
    return pa.ListArray.from_arrays(pa.array(offsets), vec3_array(points), type=_arrow_types()[1]), counts
