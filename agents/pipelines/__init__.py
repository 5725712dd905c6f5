"""warpcut's pipelines as library calls, each the body of a command: :func:`run_pipeline` (``warpcut run``,
the main job), :func:`evaluate_table` (``warpcut evaluate``, the paper's Table I protocol) and
:func:`robustness` (``warpcut robustness``, the paper's Fig. 5 studies). Each takes its job
(:mod:`agents.jobs`), writes a run directory and returns a report; what to print, plot or record is the
caller's."""

from agents.pipelines.robustness import robustness
from agents.pipelines.run import RunReport, run_pipeline
from agents.pipelines.table import TableReport, evaluate_table

__all__ = ["RunReport", "TableReport", "evaluate_table", "robustness", "run_pipeline"]

from agents.pipelines.optimize import optimize_contour  # noqa: E402  (``warpcut optimize``)

__all__ += ["optimize_contour"]
