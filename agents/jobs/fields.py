"""What every job shares: each field checked by its name as it is given (the same name means the same in
every job), the keys a job would not use, and the file a run directory keeps its job in."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from agents.config import (
    ANALYTIC_PINCHES,
    SEED_RANGE,
    TrainConfig,
)
from agents.plan_optimizer.config import GradConfig
from envs.options import EnvConfig
from warpcut.planning.feasibility import ArmModel
from warpcut.sim.config import SimConfig
from warpcut.validation import (
    ConfigError,
    check_choice,
    check_flag,
    check_instance,
    check_integer,
    check_number,
    check_text,
    fail,
    is_integer,
    is_number,
)
from warpcut.viz.colours import COLOUR_FIELDS


def _counted(where: str, value: Any, optional: bool = False, note: str = "the budget's") -> None:
    """A count (trials, candidates): an integer >= 1 (None where ``optional``)."""
    if optional and value is None:
        return
    if not (is_integer(value) and value >= 1):
        fail(where, "must be an integer >= 1" + (f", or null for {note}" if optional else ""), value)


def _names(where: str, value: Any, what: str) -> None:
    """A list of names (methods, studies, contours): never one string, which would be read letter by
    letter."""
    if not (isinstance(value, list | tuple) and all(isinstance(v, str) for v in value)):
        fail(where, f"a list of {what}", value)


def _paths(where: str, value: Any) -> None:
    if not (
        isinstance(value, dict) and all(isinstance(k, str) and isinstance(v, str) for k, v in value.items())
    ):
        fail(where, "a mapping {label: path}", value)


def _point(where: str, value: Any) -> None:
    if value is None:
        return
    ok = isinstance(value, list | tuple) and len(value) == 2 and all(is_number(v) for v in value)
    if not (ok and all(math.isfinite(float(v)) for v in value)):
        fail(where, "[x, y], finite numbers in mm, or None", value)


_FIELD_CHECKS = {
    "contour": lambda w, v: check_instance(
        w, v, (str, dict, type(None)), "a built-in name, a contour file, or a contour {name, closed, points}"
    ),
    "pinch": _point,
    "allow_infeasible_pinch": check_flag,
    "allow_partial": check_flag,
    "plan": check_flag,
    "plots": check_flag,
    "arm": lambda w, v: check_instance(w, v, ArmModel, "an ArmModel (length_mm, width_mm, ...)"),
    "segments": lambda w, v: check_instance(w, v, (list, tuple, type(None)), "a list of polylines, or None"),
    "seed": lambda w, v: check_integer(w, v, *SEED_RANGE),
    "eval_trials": _counted,
    "sim": lambda w, v: check_instance(w, v, SimConfig, "a SimConfig (the sim section)"),
    "env": lambda w, v: check_instance(w, v, EnvConfig, "an EnvConfig (the env section)"),
    "train": lambda w, v: check_instance(w, v, TrainConfig, "a TrainConfig (the train section)"),
    "grad": lambda w, v: check_instance(w, v, GradConfig, "a GradConfig (the grad section)"),
    "record": lambda w, v: check_integer(w, v, 1, optional=True, note="no recording"),
    "video": lambda w, v: check_integer(w, v, 1, optional=True, note="no video"),
    "colour_by": lambda w, v: v in COLOUR_FIELDS or fail(w, f"choose one of {', '.join(COLOUR_FIELDS)}", v),
    "export_mesh": lambda w, v: check_text(w, v, optional=True, note="no meshes"),
    "generalist": lambda w, v: check_text(w, v),
    "init": lambda w, v: check_text(w, v, optional=True, note="a fresh policy"),
    "init_gain": lambda w, v: check_number(w, v, 0.0, 10.0, low_open=True, note="1: the moves as they are"),
    "checkpoints": lambda w, v: check_text(w, v, optional=True, note="train a policy per contour"),
    "analytic_pinch": lambda w, v: check_choice(w, v, ANALYTIC_PINCHES),
    "methods": lambda w, v: _names(w, v, "method names"),
    "study": lambda w, v: _names(w, v, "studies"),
    "contours": lambda w, v: _names(w, v, "contour names or files"),
    "runs": _paths,
    "plans": _paths,
}
"""How each job's field is checked as it is given, by its name (the same name means the same in every job);
the fields a job reads its own way are its ``__post_init__``'s."""


def _check_fields(job: Any) -> None:
    """``ConfigError`` naming ``Job.field`` for the first field that is not what it takes (each on its own:
    a file and ``--set`` set one key at a time; what depends on several fields is the job's ``check``)."""
    for f in dataclasses.fields(job):
        check = _FIELD_CHECKS.get(f.name)
        if check is not None:
            check(f"{type(job).__name__}.{f.name}", getattr(job, f.name))


def other_learners(train: TrainConfig) -> dict[str, str]:
    """The sections of the learners ``train`` does not train with, ``{key: when it applies}``."""
    from agents.algorithms import ALGORITHMS

    return {f"train.{name}": f"read by --algo {name} only" for name in ALGORITHMS if name != train.algo}


def _pinch_keys(no_pinch: bool, source: str = "a pinch point (--pinch)") -> dict[str, str]:
    """``allow_infeasible_pinch`` where no pinch point is given (``source`` says what gives one): the
    default pinch points are feasible by construction."""
    if no_pinch:
        return {"allow_infeasible_pinch": f"read with {source} only; the default ones are feasible"}
    return {}


def _recording_keys(job: Any) -> dict[str, str]:
    """``colour_by`` without a recording."""
    if getattr(job, "record", None) is None:
        return {"colour_by": "colours a recording, and record is off (add --record [N])"}
    return {}


CONFIG_FILE = "config.json"
"""A run directory's job (this module's dataclasses, as plain data): ``--config`` takes it back, ``--resume``
checks it."""


OUTPUT_KEYS = ("record", "colour_by", "video", "plots", "export_mesh")
"""The keys of a job that say only what a run writes besides its results: a resumed run may change them."""


def _sim_validated(sim: SimConfig) -> SimConfig:
    """``sim`` validated, or ``ValueError`` naming the ``sim.`` key (``sim.elasticity: ...``)."""
    try:
        return sim.validated()
    except ConfigError as error:
        raise error.renamed(f"sim.{error.field}") from None


def _grad_validated(grad: GradConfig) -> GradConfig:
    """``grad`` validated (its one spelling of ranges), or ``ValueError`` naming the ``grad.`` key."""
    try:
        return grad.validated()
    except ValueError as error:
        raise ValueError(f"grad.{error}") from None
