"""The sensitivity studies and what they play (:mod:`agents.pipelines.robustness` runs them): each study's
swept setting, default values and units; the nominal scenario a study sweeps around (the first trained
run's, or a plan of the contour); and the runs and plans it plays, checked before any work."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from agents.methods import BASELINES
from agents.plan_optimizer.plan import PlanResult
from warpcut.contours import Contour
from warpcut.planning import ArmModel, InfeasiblePinch, check_pinch, resolve_contour
from warpcut.sim.config import GRAVITY_MM_S2, SimConfig
from warpcut.sim.memory import batch_named
from warpcut.validation import ConfigError

STUDIES = ("resolution", "noise", "force")
"""The studies, in the paper's order (Fig. 5a-c)."""


STUDY_VALUES: dict[str, tuple[float, ...]] = {
    "resolution": (12, 16, 20, 25, 35, 50),
    "noise": tuple(round(0.03 * k, 2) for k in range(10)),
    "force": tuple(GRAVITY_MM_S2 * k / 4 for k in range(9)),
}
"""Each study's default sweep: vertices per side (the paper's 400, 625 and 2500 vertices; 144 for its 100,
as 10 x 10 leaves no room for the default grasp beside most contours; 256 and 1225 between), process noise
(mm; ten values, the paper's count, 0 to nine times the default 0.03 in its steps: the paper's largest sigma
was 0.21 mm), and gravity (mm/s^2; 0 to twice the nominal 521 in quarters)."""


STUDY_METHODS = (*BASELINES, "generalist", "grad")
"""The methods a study can run besides trained policies: the baselines, and ``grad``, an open-loop plan
optimised through the simulator on the nominal sheet (:func:`agents.plan_optimizer.optimizer.optimize_plan`)
and played unchanged at every value."""


REPORT_FIELDS = (
    "study", "values", "unit", "metric", "contour", "trials", "nominal", "pinch", "runs", "methods",
    "seconds", "skipped", "none_error_mm2", "own_order_none", "plans", "diverged",
)  # fmt: skip
"""The keys of a study's report besides its methods' (:func:`robustness_study`)."""


RESERVED_LABELS = (*STUDY_METHODS, *REPORT_FIELDS)
"""Names a run's label may not take: a method's, or a report field's."""


STUDY_FIELDS = {"resolution": "resolution", "noise": "noise_std", "force": "gravity"}
"""The :class:`~warpcut.sim.config.SimConfig` field each study sweeps."""


STUDY_UNITS = {"resolution": "vertices per side", "noise": "noise_std (mm)", "force": "gravity (mm/s^2)"}
"""What a study's values are, in words (plots, tables)."""


def check_study(study: str, values: Sequence[float] | None) -> list[float]:
    """``study``'s values (default :data:`STUDY_VALUES`), checked; ``ValueError`` naming the field."""
    if study not in STUDIES:
        raise ValueError(f"study: choose one of {', '.join(STUDIES)} (got {study!r})")
    values = list(STUDY_VALUES[study] if values is None else values)
    if not values:
        raise ValueError("values: give at least one value")
    if study == "resolution":
        if not all(float(v).is_integer() and v >= 2 for v in values):
            raise ValueError(f"values: resolutions are whole numbers of vertices per side (got {values})")
        values = [int(v) for v in values]
    for v in values:  # each value must be one SimConfig accepts
        try:
            SimConfig(**{STUDY_FIELDS[study]: v}).validated()
        except ConfigError as error:  # the field as the study sweeps it: "values: force -1.0: gravity: ..."
            raise ValueError(f"values: {study} {v}: {error.field}: {error.requirement}") from None
    return values


def infeasible_pinches(
    scenario: dict, methods: Sequence[str] | None, plans: Mapping | None, runs: Mapping, allow: bool
) -> dict[str, str]:
    """The report's ``infeasible_pinches``, ``{method: why}``, for the methods whose pinch point on the
    nominal sheet the gripper could not hold (:func:`warpcut.planning.pinch_problems`): each run and plan
    at its own, fixed and grad at the scenario's (None: not known yet, planned later); an
    :class:`InfeasiblePinch` naming the first unless ``allow``. They are judged on the nominal sheet: a
    sweep keeps every pinch point where it is, as the paper's Fig. 5 does, though a coarser mesh's wider
    grasp may reach the cut."""
    contour, config, segments = scenario["contour"], scenario["config"], scenario["segments"]
    arm = scenario.get("arm", ArmModel())
    pinches = dict(scenario.get("run_pinches", {}))
    for label, plan in check_plans(plans, contour, runs).items():
        pinches[label] = (np.asarray(plan.pinch), segments)
    for method in ("fixed", "grad") if scenario["pinch"] is not None else ():
        if method in (methods or BASELINES):
            pinches[method] = (scenario["pinch"], segments)
    found = {}
    for method, (point, cut) in pinches.items():
        problem = check_pinch(point, contour, config, cut, arm, allow=True)
        if problem is not None and not allow:
            fix = "give runs and plans made at feasible pinch points (without --pinch)"
            raise InfeasiblePinch(point, contour, f"{problem} ({method}'s)", fix)
        if problem is not None:
            found[method] = problem
    return found


def check_label(field: str, label, taken: Mapping = ()) -> None:
    """``ValueError`` naming ``field`` unless ``label`` is a plain name that no method, report field or
    ``taken`` label (another method's) already has."""
    import re

    if label in RESERVED_LABELS or label in taken or not re.fullmatch(r"[A-Za-z][\w.-]*", str(label)):
        also = ", a run's" if taken else ""
        raise ValueError(
            f"{field}: label {label!r} must be a plain name (letters, digits, - _ .) other than a method's"
            f"{also} or a report field's ({', '.join(RESERVED_LABELS)})"
        )


def check_runs(runs: Mapping[str, str | Path] | str | Path | None) -> dict[str, Path]:
    """``runs`` as ``{label: run directory}`` (one run: ``{"rl": run}``), each a trained run; ``ValueError``
    naming ``runs`` for a label that is a baseline's, or not a plain name."""
    from agents.policies import is_run, policy_runs

    if runs is None:
        return {}
    if isinstance(runs, str | Path):
        runs = {"rl": runs}
    checked = {}
    for label, run in dict(runs).items():
        check_label("runs", label)
        try:
            found = policy_runs(run) if Path(run).is_dir() else []
        except ValueError:  # holds no policy
            found = []
        if len(found) != 1 or not is_run(found[0][0]):
            raise ValueError(
                f"runs: {run} is not one trained policy's run; give a directory of 'warpcut train' or "
                "'warpcut run' (or one contour's policies/NAME of 'warpcut evaluate')"
            )
        checked[str(label)] = found[0][0]
    return checked


def check_plans(
    plans: Mapping[str, str | Path] | None, contour: Contour, runs: Mapping[str, Path]
) -> dict[str, PlanResult]:
    """``plans`` (``{label: plan file}``) read, each checked to be ``contour``'s; ``ValueError`` naming
    ``plans`` for a label taken by a method, a run or a report field, a file that is not an optimised plan,
    or a plan of another contour."""
    checked = {}
    for label, path in dict(plans or {}).items():
        check_label("plans", label, taken=runs)
        result = read_plan(path)
        if result.contour != contour.name:
            raise ValueError(f"plans: {path} is a plan for {result.contour!r}, not {contour.name!r}")
        checked[str(label)] = result
    return checked


def read_plan(path: str | Path) -> PlanResult:
    """The optimised plan in ``path``; ``ValueError`` naming ``plans`` for a file that is not one."""
    from warpcut.io import read_json

    try:
        return PlanResult.from_json(read_json(path))
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ValueError(
            f"plans: {path} is not an optimised plan ({error}); give a NAME.json of 'warpcut optimize' "
            "(or a grad/NAME.json of 'warpcut evaluate')"
        ) from None


def nominal_scenario(contour, runs: dict[str, Path], config, device, seed, log) -> dict:
    """The contour, nominal simulation, pinch point and segments: the first run's, or planned."""
    if runs:
        from agents.policies import policy_options, same_contour

        given = None
        if contour is not None:
            given = resolve_contour(contour)
        first, cuts, pinches = None, {}, {}
        for label, run in runs.items():
            # judged on the nominal sheet with the others (infeasible_pinches): refused there unless allowed
            options = dataclasses.replace(policy_options(run, device), allow_infeasible_pinch=True)
            trained = options.contours(1)[0]
            given = given or trained
            if not same_contour(given, trained):
                raise ValueError(
                    f"runs: {label} ({run}) was trained on {trained.name!r}, not {given.name!r}; give runs "
                    "of one contour (and leave the contour out, or give that one)"
                )
            first = first or options
            cuts[label] = None if options.segments is None else [np.asarray(s) for s in options.segments]
            pinches[label] = (np.asarray(options.per_env(1)[1][0], dtype=np.float64), cuts[label])
        return {
            "contour": first.contours(1)[0],
            "config": first.config(),
            "pinch": np.asarray(first.per_env(1)[1][0], dtype=np.float64),
            "segments": next(iter(cuts.values())),
            "run_segments": cuts,
            "run_pinches": pinches,
            "arm": first.arm,
        }
    from warpcut.planning import plan_cut

    if contour is None:
        raise ValueError("contour: give a contour (or a run, whose contour is used)")
    contour = resolve_contour(contour)
    config = (config or SimConfig()).validated()
    log(f"  planning {contour.name}")
    with batch_named(  # the planner's own advice names a candidates setting this job lacks
        "the planner's batch (pinch candidates x segment orders)",
        "lower sim.resolution, or give a trained run (--run LABEL=DIR) whose pinch point and order are used",
    ):
        plan = plan_cut(contour, config.replace(noise_std=0.0), seed=seed, device=device)
    return {
        "contour": contour,
        "config": config,
        "pinch": np.asarray(plan.chosen["pinch"], dtype=np.float64),
        "segments": plan.ordered_segments(),
    }


def parse_studies(value: str | Sequence[str]) -> list[str]:
    """Study names from a list or a comma-separated string (``all``: every study); ``ValueError`` naming
    ``study`` for an unknown one."""
    names = [value] if isinstance(value, str) else list(value)
    names = [n.strip() for arg in names for n in str(arg).split(",") if n.strip()]
    if "all" in names:
        names = list(STUDIES)
    unknown = [n for n in names if n not in STUDIES]
    if not names or unknown:
        raise ValueError(
            f"study: choose from {', '.join(STUDIES)} or all (got {', '.join(unknown) or 'none'})"
        )
    return list(dict.fromkeys(names))
