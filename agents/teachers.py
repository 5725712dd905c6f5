"""A teacher dataset (``warpcut teachers``, :func:`agents.pipelines.teachers.make_teachers`, which has its
layout): the contours, how each is cut, and its teacher's moves, as a generalist learns from them
(:mod:`agents.dagger`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from warpcut.contours import Contour
from warpcut.io import read_json, safe_name

INDEX_FILE = "teachers.json"
"""A finished dataset's index (module docstring)."""

CUT_FILE = "cut.json"
"""A contour's cut in its unit folder: points, pinch point, ordered segments."""

UNITS = "teachers"
"""The dataset's folder of unit folders, one per contour."""

FORMAT = 1
"""The layout of ``teachers.json``."""


@dataclass
class Teacher:
    """One contour of a dataset: how it is cut and its teacher's moves."""

    contour: Contour
    pinch: np.ndarray
    """(2,) the pinch point (material mm)."""
    segments: list[np.ndarray]
    """The polylines cut, in order."""
    plan: np.ndarray
    """(T, 3) the teacher's grasp moves (mm), one per env step of the contour cut alone."""
    error: float
    """The teacher's validation error (vertices, on its optimiser's held-out episodes)."""
    still_error: float
    """The still grasp's on the same episodes."""


def load_teachers(source: str | Path, config=None) -> list[Teacher]:
    """The teachers of the dataset in ``source`` (a finished ``warpcut teachers`` directory).

    Raises:
        ValueError: ``source`` is not a finished dataset, or one of its files cannot be read (named).
    """
    from agents.plan_optimizer.plan import PlanResult
    from warpcut.contours import validate

    source = Path(source)
    index_file = source / INDEX_FILE
    if not index_file.is_file():
        what = "no such directory" if not source.is_dir() else f"holds no {INDEX_FILE} (not finished?)"
        raise ValueError(
            f"teachers: {source}: {what}; give a finished directory of 'warpcut teachers' (or --resume it)"
        )
    try:
        index = read_json(index_file)
        teachers = []
        for row in index["contours"]:
            folder = source / UNITS / safe_name(row["contour"])
            cut = read_json(folder / CUT_FILE)
            shape = cut["contour"]
            size = (100.0, 100.0) if config is None else (config.width_mm, config.height_mm)
            contour = validate(shape["name"], shape["closed"], np.asarray(shape["points"], float), size)
            plan = PlanResult.from_json(read_json(folder / f"{safe_name(row['contour'])}.json")).plan
            teachers.append(
                Teacher(
                    contour,
                    np.asarray(cut["pinch"], float),
                    [np.asarray(s, float) for s in cut["segments"]],
                    np.asarray(plan, np.float32),
                    float(row["error_vertices"]),
                    float(row["still_error_vertices"]),
                )  # fmt: skip
            )
    except (OSError, KeyError, TypeError, ValueError) as exc:
        raise ValueError(
            f"teachers: {source} cannot be read ({exc}); build it again (warpcut teachers)"
        ) from None
    return teachers


__all__ = ["CUT_FILE", "FORMAT", "INDEX_FILE", "UNITS", "Teacher", "load_teachers"]
