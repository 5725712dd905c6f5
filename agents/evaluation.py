"""Compare tensioners: the paper's Table I protocol, with every (contour, trial) of a method one env of
one simulator batch."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from agents.baselines import search_fixed_pinches
from agents.config import EVALUATION_TRIALS
from agents.methods import BASELINES, StepCallbacks, tensioner
from warpcut.contours import Contour
from warpcut.planning import ArmModel, check_pinch, default_pinch
from warpcut.sim.config import SimConfig
from warpcut.sim.memory import batch_named
from warpcut.stats import mean_ci95, paired_improvement
from warpcut.task import CuttingTask, SimulationDiverged, StepCallback, divergence_error
from warpcut.trajectory import default_segments


@dataclass
class Method:
    """One method of an evaluation: its name (:data:`agents.methods.METHODS`) and where it departs from
    its own choices.

    Attributes:
        name: The method.
        pinches: A pinch point per contour replacing the method's own (e.g. the planned pinch for fixed).
        segments: Per contour, the polylines cut in order, replacing the suite's ``segments`` for this
            method (e.g. the order that is best at the method's own pinch point); a None entry: the suite's.
        result: The method's outcome, run elsewhere (e.g. ``rl`` through its env): taken as is.
        allow_infeasible_pinch: Run ``pinches`` the gripper could not hold (e.g. the analytic controller at
            the centroid, the paper's literal choice); its rows mark them (``METHOD_pinch_feasible``).
    """

    name: str
    pinches: Sequence[np.ndarray | None] | None = None
    segments: Sequence[list[np.ndarray] | None] | None = None
    result: MethodResult | None = None
    allow_infeasible_pinch: bool = False


@dataclass
class MethodResult:
    """A method's outcome on a suite: per (contour, trial) the error under the protocol's score, whether
    the piece came free and the share of the cut path dropped; the pinch point used per contour (None: no
    grasp)."""

    error_vertices: np.ndarray
    """(num_contours, trials) error in vertices (``config.score``: path or separated)."""
    error_mm2: np.ndarray
    """(num_contours, trials) the same error in mm^2."""
    pinches: list[np.ndarray | None]
    separated: np.ndarray | None = None
    """(num_contours, trials) bool: the intended piece came free (None: not measured)."""
    dropped: np.ndarray | None = None
    """(num_contours, trials) share of cutting updates dropped from the path (None: not measured)."""
    diverged: np.ndarray | None = None
    """(num_contours, trials) bool: the trial's simulation diverged, its error is NaN (None: not
    measured; a NaN error counts as diverged all the same)."""
    pinch_problems: list[str | None] | None = None
    """Per contour, why its pinch point is not a feasible grasp (:func:`warpcut.planning.pinch_problems`),
    or None: feasible, or no grasp (the list None: not judged)."""

    @classmethod
    def from_rollouts(cls, rollouts: Sequence[dict]) -> MethodResult:
        """From one rollout dict per contour (:func:`agents.policies.rollout_errors`)."""
        diverged = None
        if any("diverged" in r for r in rollouts):
            diverged = np.array([np.asarray(r.get("diverged", False), dtype=bool) for r in rollouts])
        return cls(
            np.array([r["error_vertices"] for r in rollouts]),
            np.array([r["error_mm2"] for r in rollouts]),
            [r["pinch"] for r in rollouts],
            np.array([r["separated"] for r in rollouts]),
            np.array([r["dropped_fraction"] for r in rollouts]),
            diverged,
            [r.get("pinch_problem") for r in rollouts],
        )

    def diverged_trials(self) -> np.ndarray:
        """(num_contours, trials) bool: trials whose simulation diverged (flagged, or a NaN error)."""
        flagged = np.zeros(self.error_vertices.shape, dtype=bool) if self.diverged is None else self.diverged
        return flagged | ~np.isfinite(np.asarray(self.error_vertices, dtype=np.float64))


def baseline_pinches(
    contours: Sequence[Contour],
    method: str,
    config: SimConfig,
    device: str | None,
    seed: int,
    arm: ArmModel = ArmModel(),
) -> list[np.ndarray | None]:
    """A baseline's own pinch point per contour, feasible with the cutting ``arm``: none has no grasp; fixed
    searches (one batched random search over all contours, noise-free); analytic pinches the centroid, or
    the feasible point nearest it."""
    if method == "none":
        return [None] * len(contours)
    if method == "fixed":
        found = search_fixed_pinches(list(contours), config, device=device, seed=seed, arm=arm)
        return [best for best, _, _ in found]
    if method == "analytic":
        return [default_pinch(c, config, arm) for c in contours]
    raise ValueError(f"methods: {method!r} is not a baseline; baselines are {', '.join(BASELINES)}")


def run_method(
    contours: Sequence[Contour],
    pinches: Sequence[np.ndarray | None],
    policy: Callable | None,
    trials: int,
    config: SimConfig,
    device: str | None,
    seed: int,
    on_step: StepCallback | None = None,
    segments: Sequence[list[np.ndarray] | None] | None = None,
    allow_diverged: bool = False,
    arm: ArmModel | None = None,
    allow_infeasible_pinch: bool = False,
) -> MethodResult:
    """A tensioner on every (contour, trial): one simulator batch for everything.

    Args:
        contours: The contours.
        pinches: A pinch point per contour (None: no grasp).
        policy: The batched tensioner (``policy(task) -> (B, 3) moves``; None: hold still).
        trials: Trials per contour; envs are ordered contour by contour, trials within.
        config: Simulation parameters.
        device: Warp device.
        seed: Seed of the process noise.
        on_step: Passed to :meth:`CuttingTask.run`.
        segments: Per contour, the polylines cut in order (None: the default single segment).
        allow_diverged: Return trials whose simulation diverged (NaN errors, flagged in ``diverged``)
            instead of raising (the sensitivity studies, which count them).
        arm: The cutting arm a pinch point must stay clear of (default: the paper's).
        allow_infeasible_pinch: Run pinch points the gripper could not hold instead of refusing them; the
            result says which (``pinch_problems``).

    Raises:
        ValueError: The batch (``trials`` x contours envs) would not fit in memory (the message names
            ``trials``, the estimate and the limit: :mod:`warpcut.sim.memory`), or a pinch point is not
            finite, or not a feasible grasp (:class:`~warpcut.planning.InfeasiblePinch`, unless
            ``allow_infeasible_pinch``).
        SimulationDiverged: Some trials diverged (non-finite or runaway vertex positions), unless
            ``allow_diverged``; the message counts them per contour and names the parameters to lower. No
            error is averaged over them.
    """
    contours = list(contours)
    if not isinstance(trials, int | np.integer) or trials < 1:
        raise ValueError(f"trials: must be a positive integer (got {trials!r})")
    trials = int(trials)
    pinches = list(pinches)
    _check_pinches(contours, pinches)
    cut = None
    if segments is not None:
        cut = [s if s is not None else default_segments(c) for c, s in zip(contours, segments, strict=True)]
    envs = [(c, p) for c, p in zip(contours, pinches, strict=True) for _ in range(trials)]
    points = np.array([np.full(2, np.nan) if p is None else p for _, p in envs], dtype=np.float64)
    per_env_segments = None if cut is None else [s for s in cut for _ in range(trials)]
    with batch_named("trials", envs_per_unit=len(contours)):  # the task checks its memory, in trials
        task = CuttingTask(
            config, [c for c, _ in envs], pinch_points=points, segments=per_env_segments, device=device,
            seed=seed, arm=arm, allow_infeasible_pinch=allow_infeasible_pinch,
        )  # fmt: skip
    score = task.run(policy, on_step=on_step)
    shape = (len(contours), trials)
    result = MethodResult(
        score.error_vertices.reshape(shape),
        score.error_mm2.reshape(shape),
        pinches,
        score.separated.reshape(shape),
        score.dropped_fraction.reshape(shape),
        task.diverged().reshape(shape),
        task.pinch_problems[::trials],
    )
    if result.diverged_trials().any() and not allow_diverged:
        reasons = [r for r in task.divergence_reasons() if r is not None]
        raise divergence_error(contours, result.diverged_trials(), config, sorted(set(reasons)))
    return result


def _check_pinches(contours: Sequence[Contour], pinches: Sequence[np.ndarray | None]) -> None:
    """Raise ``ValueError`` naming ``pinch_point`` and the contour for a pinch point that is not finite (it
    would silently mean no grasp)."""
    for contour, pinch in zip(contours, pinches, strict=True):
        if pinch is not None and not np.all(np.isfinite(np.asarray(pinch, dtype=np.float64))):
            raise ValueError(
                f"pinch_point: {contour.name}'s pinch point {np.asarray(pinch).tolist()} is not finite; give "
                "material coordinates (mm), or None for no grasp"
            )


def evaluate_suite(
    contours: Sequence[Contour],
    methods: Sequence[str | Method] = BASELINES,
    trials: int = EVALUATION_TRIALS,
    config: SimConfig | None = None,
    device: str | None = None,
    seed: int = 0,
    segments: Sequence[list[np.ndarray] | None] | None = None,
    progress: Callable[[str], None] = lambda _: None,
    step_callbacks: StepCallbacks | None = None,
    arm: ArmModel | None = None,
    allow_infeasible_pinch: bool = False,
) -> dict:
    """The Table I protocol: per contour the no-tension error and each method's improvement over it.

    Trials differ by their process-noise stream (``config.noise_std``; without noise they coincide and
    the CI is 0). Improvements are paired per trial (same seed, same noise stream index).

    Args:
        contours: The contours to evaluate.
        methods: Method names or :class:`Method` specs; baselines are run here, others must carry their
            ``result``. ``none`` is always run (the reference); listed, it is also a column.
        trials: Trials per contour and method.
        config: Simulation parameters.
        device: Warp device.
        seed: Seed of the pinch search and the process noise.
        segments: Per contour, the polylines the scissors cut in order (a cut plan), for every method;
            None (or a None entry): the whole contour as one segment.
        progress: Called with a short description before each method runs.
        step_callbacks: ``step_callbacks(method, first_contour)`` gives the step callback of a batch run
            here (all contours, so ``first_contour`` is 0), e.g. a recorder's; None: none.
        arm: The cutting arm every pinch point must stay clear of (default: the paper's).
        allow_infeasible_pinch: Run given pinch points the gripper could not hold instead of refusing them
            (:class:`~warpcut.planning.InfeasiblePinch`, before anything runs); a method may allow its own
            (:attr:`Method.allow_infeasible_pinch`). Rows mark them.

    Raises:
        SimulationDiverged: A method's trials diverged (:func:`run_method`; a given result with NaN
            errors, too): the message starts with the method, counts the trials per contour and names the
            parameters to lower. The table never averages a diverged trial.

    Returns:
        ``{"score": "path"|"separated", "rows": [{"contour", "none_error_vertices", "none_error_mm2",
        "METHOD_error_vertices", "METHOD_improvement_pct", "METHOD_ci95", "METHOD_pinch",
        "METHOD_pinch_feasible" (null without a grasp), "METHOD_pinch_problem" (why not, or null),
        "METHOD_separated_fraction", "METHOD_dropped_fraction", ...}], "mean": {"METHOD_improvement_pct",
        "METHOD_ci95"}, "trials": int}``. Errors are under ``config.score``. The mean row averages the
        per-contour improvements; its CI is over contours, as in the paper's table.
    """
    config = (config or SimConfig()).validated()
    if not isinstance(trials, int) or trials < 1:
        raise ValueError(f"trials: must be a positive integer (got {trials!r})")
    contours = list(contours)
    if not contours:
        raise ValueError("contours: give at least one contour")
    specs = {m.name: m for m in (m if isinstance(m, Method) else Method(m) for m in methods)}
    shown = list(specs)
    specs.setdefault("none", Method("none"))
    order = ["none"] + [m for m in specs if m != "none"]
    for name, value in [("segments", segments)] + [(f"{m}.segments", s.segments) for m, s in specs.items()]:
        if value is not None and len(value) != len(contours):
            raise ValueError(f"{name}: give one list of polylines (or None) per contour ({len(contours)})")
    arm = ArmModel() if arm is None else arm
    for spec in specs.values():  # before anything runs
        if spec.pinches is not None and len(spec.pinches) == len(contours) and spec.result is None:
            _check_pinches(contours, spec.pinches)
            allowed = allow_infeasible_pinch or spec.allow_infeasible_pinch
            for k, (contour, pinch) in enumerate(zip(contours, spec.pinches, strict=True)):
                cut = spec.segments[k] if spec.segments is not None else None
                cut = cut if cut is not None else (None if segments is None else segments[k])
                if pinch is not None:
                    check_pinch(pinch, contour, config, cut, arm, allow=allowed)
    results = {}
    for method in order:
        spec = specs[method]
        if spec.result is not None:
            diverged = spec.result.diverged_trials()
            if diverged.any():
                raise SimulationDiverged(f"{method}: {divergence_error(contours, diverged, config)}")
            results[method] = spec.result
            continue
        if method not in BASELINES:
            raise ValueError(f"methods: {method!r} is not a baseline; give its result (Method.result)")
        pinches = spec.pinches
        if pinches is None:
            pinches = baseline_pinches(contours, method, config, device, seed, arm)
        elif len(pinches) != len(contours):
            raise ValueError(f"{method}.pinches: give one point per contour ({len(contours)})")
        pinches = [None if p is None else np.asarray(p, dtype=np.float64) for p in pinches]
        cut = (
            segments
            if spec.segments is None
            else [
                s if s is not None else (None if segments is None else segments[k])
                for k, s in enumerate(spec.segments)
            ]
        )
        progress(f"{method}: {len(contours)} contour(s) x {trials} trial(s)")
        callback = step_callbacks(method, 0) if step_callbacks is not None else None
        try:
            results[method] = run_method(
                contours, pinches, tensioner(method), trials, config, device, seed, callback, segments=cut,
                arm=arm, allow_infeasible_pinch=allow_infeasible_pinch or spec.allow_infeasible_pinch,
            )  # fmt: skip
        except SimulationDiverged as error:
            raise SimulationDiverged(f"{method}: {error}") from None
    rows = [
        _row(contour.name, k, results, [m for m in order if m in shown]) for k, contour in enumerate(contours)
    ]
    mean = {}
    for method in order:
        if method in shown:
            values = [r[f"{method}_improvement_pct"] for r in rows]
            mean[f"{method}_improvement_pct"], mean[f"{method}_ci95"] = mean_ci95(values)
    return {"score": config.score, "rows": rows, "mean": mean, "trials": trials}


def _row(name: str, k: int, results: dict[str, MethodResult], shown: list[str]) -> dict:
    """Contour ``k``'s row of :func:`evaluate_suite`'s table."""
    none = results["none"]
    row = {
        "contour": name,
        "none_error_vertices": float(none.error_vertices[k].mean()),
        "none_error_mm2": float(none.error_mm2[k].mean()),
        "none_trials_error_vertices": [float(e) for e in none.error_vertices[k]],
    }
    for method in shown:
        result = results[method]
        pinch = result.pinches[k]
        problem = None if result.pinch_problems is None else result.pinch_problems[k]
        improvement = paired_improvement(none.error_vertices[k], result.error_vertices[k])
        row[f"{method}_error_vertices"] = float(result.error_vertices[k].mean())
        row[f"{method}_error_mm2"] = float(result.error_mm2[k].mean())
        row[f"{method}_improvement_pct"], row[f"{method}_ci95"] = mean_ci95(improvement)
        row[f"{method}_pinch"] = None if pinch is None else [float(v) for v in pinch]
        judged = pinch is not None and result.pinch_problems is not None
        row[f"{method}_pinch_feasible"] = problem is None if judged else None
        row[f"{method}_pinch_problem"] = problem
        row[f"{method}_trials_error_vertices"] = [float(e) for e in result.error_vertices[k]]
        row[f"{method}_separated_fraction"] = _mean_or_none(result.separated, k)
        row[f"{method}_dropped_fraction"] = _mean_or_none(result.dropped, k)
    return row


def _mean_or_none(values: np.ndarray | None, contour: int) -> float | None:
    """Mean over a contour's trials (NaN trials ignored); None where not measured or all NaN."""
    if values is None:
        return None
    row = np.asarray(values[contour], dtype=np.float64)
    return float(np.nanmean(row)) if np.isfinite(row).any() else None


def compare_policies(
    contour: Contour,
    methods: Sequence[str] = BASELINES,
    trials: int = 1,
    config: SimConfig | None = None,
    pinch: tuple[float, float] | None = None,
    device: str | None = None,
    seed: int = 0,
    step_callbacks: StepCallbacks | None = None,
    allow_infeasible_pinch: bool = False,
    results: dict[str, MethodResult] | None = None,
) -> dict:
    """One contour, the baseline tensioners (and methods run elsewhere, ``results``: e.g. the generalist's,
    :func:`agents.generalist.generalist_result`): the ``warpcut simulate`` report.

    ``pinch`` replaces the pinch point of fixed and analytic: one the gripper could not hold (on or near the
    cut line, under the cutting arm: :func:`warpcut.planning.pinch_problems`) is refused
    (:class:`~warpcut.planning.InfeasiblePinch`) unless ``allow_infeasible_pinch``. ``step_callbacks`` as
    in :func:`evaluate_suite`.

    Returns:
        ``{"contour": name, "score": "path"|"separated", "results": {method: {"error_vertices",
        "error_mm2", "improvement_pct", "ci95_pct", "trials_error_vertices", "separated_fraction",
        "dropped_fraction", "pinch", "pinch_feasible", "pinch_problem"}}}``: means over trials;
        ``improvement_pct`` is the mean paired improvement over no tension (0 for ``none`` itself);
        ``separated_fraction`` the share of trials whose piece came free, ``dropped_fraction`` the mean share
        of the cut path dropped; ``pinch_feasible`` false (and ``pinch_problem`` why) for a pinch point
        the gripper could not hold, null without a grasp.
    """
    given = None if pinch is None else [np.asarray(pinch, dtype=np.float64)]
    specs = [Method(m, pinches=given if m in ("fixed", "analytic") else None) for m in methods]
    for spec in specs:
        spec.result = (results or {}).get(spec.name)
    report = evaluate_suite(
        [contour], specs, trials, config, device, seed, step_callbacks=step_callbacks,
        allow_infeasible_pinch=allow_infeasible_pinch,
    )  # fmt: skip
    row = report["rows"][0]
    results = {}
    for method in methods:
        results[method] = {
            "error_vertices": row[f"{method}_error_vertices"],
            "error_mm2": row[f"{method}_error_mm2"],
            "improvement_pct": row[f"{method}_improvement_pct"],
            "ci95_pct": row[f"{method}_ci95"],
            "trials_error_vertices": row[f"{method}_trials_error_vertices"],
            "separated_fraction": row[f"{method}_separated_fraction"],
            "dropped_fraction": row[f"{method}_dropped_fraction"],
            "pinch": row[f"{method}_pinch"],
            "pinch_feasible": row[f"{method}_pinch_feasible"],
            "pinch_problem": row[f"{method}_pinch_problem"],
        }
    return {"contour": contour.name, "score": report["score"], "results": results}
