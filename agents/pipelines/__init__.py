"""warpcut's pipelines as library calls, each the body of a command: :func:`run_pipeline` (``warpcut run``,
the main job), :func:`evaluate_table` (``warpcut evaluate``, the paper's Table I protocol),
:func:`robustness` (``warpcut robustness``, the paper's Fig. 5 studies) and :func:`optimize_contour`
(``warpcut optimize``). Each takes its job (:mod:`agents.jobs`), writes a run directory and returns a
report; what to print, plot or record is the caller's.

The pipelines that train policies (``run``, ``table``) load torch; they are imported when first named, so
that a command checks its settings before torch loads (a refusal in a second, not ten)."""

import importlib

from agents.pipelines.optimize import optimize_contour
from agents.pipelines.robustness import robustness

_LAZY = {
    "RunReport": "agents.pipelines.run",
    "run_pipeline": "agents.pipelines.run",
    "TableReport": "agents.pipelines.table",
    "evaluate_table": "agents.pipelines.table",
}
"""The names whose modules load torch, and those modules."""

__all__ = ["RunReport", "TableReport", "evaluate_table", "optimize_contour", "robustness", "run_pipeline"]


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
