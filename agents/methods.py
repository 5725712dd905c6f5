"""The tensioning methods warpcut compares, by name: the one registry the evaluation, the pipelines and
the command line read."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from warpcut.task import StepCallback

METHODS = {
    "none": "no tensioning: only the corner clips hold the sheet",
    "fixed": "pinch at the planned (or best searched) point and hold still",
    "analytic": "pinch at the (feasible) centroid and move against the tracking error",
    "rl": "a policy trained for the contour by the learner (es by default; agents.training)",
    "generalist": "one policy for every contour, played zero-shot with no training: the shipped one, or "
    "another that 'warpcut generalist' trained (agents.pipelines.generalist)",
    "grad": "an open-loop plan of grasp moves optimised by Adam through the differentiable simulator, at "
    "fixed's pinch point (agents.plan_optimizer)",
}
"""Every method, in the order tables show them, with what it does."""

TABLE_METHODS = ("none", "fixed", "analytic", "rl")
"""The paper's Table I columns: what ``warpcut evaluate`` runs unless told otherwise (``grad`` is added with
``--methods``)."""

BASELINES = ("none", "fixed", "analytic")
"""The methods that need no training (:mod:`agents.baselines`, :func:`tensioner`)."""

SIMULATED = (*BASELINES, "generalist")
"""The tensioners ``warpcut simulate`` runs: the baselines and the generalist (none needs training)."""

SELECTORS = ("fixed", "analytic", "rl", "generalist")
"""The methods that can choose a plan's pinch candidate (``warpcut run --policy``)."""

StepCallbacks = Callable[[str, int], "StepCallback | None"]
"""``step_callbacks(method, first_contour)``: the step callback of a batch that runs ``method`` on the
contours from ``first_contour`` on (None: none), e.g. a recorder's."""


def check_methods(names: Sequence[str], field: str, allowed: tuple[str, ...] = tuple(METHODS)) -> list[str]:
    """``names`` as a list, if non-empty and each is in ``allowed``; else ``ValueError`` naming ``field``."""
    if isinstance(names, str):  # one name, not a list: read letter by letter it would name none
        raise ValueError(f"{field}: give a list of names, e.g. [{names}] (got {names!r})")
    unknown = [n for n in names if n not in allowed]
    if not names or unknown:
        raise ValueError(
            f"{field}: unknown {', '.join(unknown) or 'empty list'}; choose from {','.join(allowed)}"
        )
    return list(names)


def parse_methods(value: str, field: str, allowed: tuple[str, ...] = tuple(METHODS)) -> list[str]:
    """The comma-separated method names in ``value`` (:func:`check_methods`)."""
    return check_methods([v.strip() for v in value.split(",") if v.strip()], field, allowed)


def tensioner(name: str):
    """A baseline's batched tensioner (:mod:`agents.baselines`) with its own defaults."""
    from agents.baselines import AnalyticTension, FixedTension, NoTension

    classes = {"none": NoTension, "fixed": FixedTension, "analytic": AnalyticTension}
    if name not in classes:
        raise ValueError(f"methods: {name!r} is not a baseline; baselines are {', '.join(BASELINES)}")
    return classes[name]()


def point_text(point) -> str:
    """A point (mm) as the progress lines and tables print it: ``(x, y)`` to 0.1 mm."""
    return f"({float(point[0]):.1f}, {float(point[1]):.1f})"
