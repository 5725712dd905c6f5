"""Compare tensioners: the paper's Table I protocol, with every (contour, trial) of a method one env of
one simulator batch."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

from agents.baselines import AnalyticTension, FixedTension, NoTension, search_fixed_pinches
from warpcut.contours import Contour
from warpcut.scoring import improvement_pct
from warpcut.sim.config import SimConfig
from warpcut.task import CuttingTask, default_segments

BASELINES = ("none", "fixed", "analytic")


def ci95(values: np.ndarray) -> float:
    """Half-width of the 95% confidence interval of the mean (Student t); 0 for fewer than 2 values."""
    values = np.asarray(values, dtype=np.float64)
    values = values[np.isfinite(values)]
    if values.size < 2:
        return 0.0
    return float(stats.t.ppf(0.975, values.size - 1) * values.std(ddof=1) / np.sqrt(values.size))


def paired_improvement(e_none: np.ndarray, e_method: np.ndarray) -> np.ndarray:
    """Per-trial :func:`~warpcut.scoring.improvement_pct`; NaN where no tension scored 0 (undefined)."""
    e_none, e_method = np.broadcast_arrays(
        np.asarray(e_none, dtype=np.float64), np.asarray(e_method, np.float64)
    )
    out = np.full(e_none.shape, np.nan)
    defined = e_none > 0
    out[defined] = improvement_pct(e_none[defined], e_method[defined])
    return out


@dataclass
class MethodSpec:
    """How one method is run: a pinch point per contour (None: no grasp) and a batched policy."""

    pinches: list[np.ndarray | None]
    policy: Callable | None


@dataclass
class MethodResult:
    """A method's outcome on a suite: per (contour, trial) the error under the protocol's score, whether
    the piece came free and the share of the cut path dropped; the pinch point used per contour (None: no
    grasp)."""

    errors: np.ndarray
    """(num_contours, trials) error in vertices (``config.score``: path or separated)."""
    areas: np.ndarray
    """(num_contours, trials) the same error in mm^2."""
    pinches: list[np.ndarray | None]
    separated: np.ndarray | None = None
    """(num_contours, trials) bool: the intended piece came free (None: not measured)."""
    dropped: np.ndarray | None = None
    """(num_contours, trials) share of cutting updates dropped from the path (None: not measured)."""

    @classmethod
    def from_rollouts(cls, rollouts: Sequence[dict]) -> MethodResult:
        """From one :func:`agents.rl.policy_errors` dict per contour."""
        return cls(
            np.array([r["error_vertices"] for r in rollouts]),
            np.array([r["error_mm2"] for r in rollouts]),
            [r["pinch"] for r in rollouts],
            np.array([r["separated"] for r in rollouts]),
            np.array([r["dropped_fraction"] for r in rollouts]),
        )


def baseline_specs(
    contours: Sequence[Contour],
    methods: Sequence[str],
    config: SimConfig,
    pinch: tuple[float, float] | None,
    device: str | None,
    seed: int,
    pinches: dict[str, list[np.ndarray]] | None = None,
) -> dict[str, MethodSpec]:
    """Pinch points and policies of the baseline tensioners (fixed: one batched random search, unless
    ``pinches`` gives a method's pinch point per contour, e.g. from a cut plan)."""
    specs: dict[str, MethodSpec] = {}
    pinches = pinches or {}
    for method in methods:
        if method in pinches and method != "none":
            points = [np.asarray(p, dtype=np.float64) for p in pinches[method]]
            if len(points) != len(contours):
                raise ValueError(f"pinches[{method!r}]: give one point per contour ({len(contours)})")
            policy = AnalyticTension() if method == "analytic" else FixedTension()
            specs[method] = MethodSpec(points, policy)
        elif method == "none":
            specs[method] = MethodSpec([None] * len(contours), NoTension())
        elif method == "fixed":
            points = (
                [np.asarray(pinch, dtype=np.float64)] * len(contours)
                if pinch is not None
                else [
                    best
                    for best, _, _ in search_fixed_pinches(list(contours), config, device=device, seed=seed)
                ]
            )
            specs[method] = MethodSpec(points, FixedTension())
        elif method == "analytic":
            policy = AnalyticTension(pinch=pinch)
            specs[method] = MethodSpec([policy.pinch_point(c, config) for c in contours], policy)
        else:
            raise ValueError(f"methods: unknown {method!r}; baselines are {', '.join(BASELINES)}")
    return specs


def run_method(
    contours: Sequence[Contour],
    spec: MethodSpec,
    trials: int,
    config: SimConfig,
    device: str | None,
    seed: int,
    on_step: Callable[[CuttingTask, np.ndarray | None], None] | None = None,
    segments: Sequence[list[np.ndarray] | None] | None = None,
) -> MethodResult:
    """One method on every (contour, trial): one simulator batch for everything.

    ``on_step`` is passed to :meth:`CuttingTask.run`; envs are ordered contour by contour, trials within.
    ``segments`` gives, per contour, the polylines cut in order (None: the default single segment).
    """
    envs = [(c, p) for c, p in zip(contours, spec.pinches, strict=True) for _ in range(trials)]
    pinches = np.array([np.full(2, np.nan) if p is None else p for _, p in envs], dtype=np.float64)
    per_env_segments = None
    if segments is not None:
        per_env_segments = [
            s if s is not None else default_segments(c)
            for c, s in zip(contours, segments, strict=True)
            for _ in range(trials)
        ]
    task = CuttingTask(
        config,
        [c for c, _ in envs],
        pinch_points=pinches,
        segments=per_env_segments,
        device=device,
        seed=seed,
    )
    score = task.run(spec.policy, on_step=on_step)
    shape = (len(contours), trials)
    return MethodResult(
        score.error_vertices.reshape(shape),
        score.error_mm2.reshape(shape),
        list(spec.pinches),
        score.separated.reshape(shape),
        score.dropped_fraction.reshape(shape),
    )


def evaluate_suite(
    contours: Sequence[Contour],
    methods: Sequence[str] = BASELINES,
    trials: int = 10,
    config: SimConfig | None = None,
    pinch: tuple[float, float] | None = None,
    device: str | None = None,
    seed: int = 0,
    extra: dict[str, MethodResult] | None = None,
    progress: Callable[[str], None] = lambda _: None,
    on_step: Callable[[str], Callable[[CuttingTask, np.ndarray | None], None] | None] | None = None,
    segments: Sequence[list[np.ndarray] | None] | None = None,
    pinches: dict[str, list[np.ndarray]] | None = None,
    method_segments: dict[str, list[list[np.ndarray] | None]] | None = None,
) -> dict:
    """The Table I protocol: per contour the no-tension error and each method's improvement over it.

    Trials differ by their process-noise stream (``config.noise_std``; without noise they coincide and
    the CI is 0). Improvements are paired per trial (same seed, same noise stream index).

    Args:
        contours: The contours to evaluate.
        methods: Method names; baselines are built here, others must be given in ``extra``.
        trials: Trials per contour and method.
        config: Simulation parameters.
        pinch: Override the pinch point of fixed and analytic for every contour.
        device: Warp device.
        seed: Seed of the pinch search and the process noise.
        extra: Results of further methods run elsewhere (e.g. ``rl`` through its env), by name.
        progress: Called with a short description before each method runs.
        on_step: Maps a method's name to the step callback of its batch (e.g. ``recorder.on_step``), for
            the methods run here (not those in ``extra``).
        segments: Per contour, the polylines the scissors cut in order (a cut plan), for every method;
            None (or a None entry): the whole contour as one segment.
        pinches: Per method, a pinch point per contour that replaces the method's own choice (e.g. the
            planned pinch for ``fixed``).
        method_segments: Per method, segments per contour that replace ``segments`` for that method (e.g.
            the cutting order that is best at the method's own pinch point).

    Returns:
        ``{"score": "path"|"separated", "rows": [{"contour", "none_error_vertices", "none_error_mm2",
        "METHOD_error_vertices", "METHOD_improvement_pct", "METHOD_ci95", "METHOD_pinch",
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
    extra = extra or {}
    order = ["none"] + [m for m in methods if m != "none"]
    method_segments = method_segments or {}
    for name, value in [("segments", segments)] + [
        (f"method_segments[{m!r}]", v) for m, v in method_segments.items()
    ]:
        if value is not None and len(value) != len(contours):
            raise ValueError(f"{name}: give one list of polylines (or None) per contour ({len(contours)})")
    specs = baseline_specs(
        contours, [m for m in order if m not in extra], config, pinch, device, seed, pinches
    )
    results = dict(extra)
    for method in order:
        if method not in results:
            progress(f"{method}: {len(contours)} contour(s) x {trials} trial(s)")
            callback = on_step(method) if on_step is not None else None
            cut = method_segments.get(method, segments)
            results[method] = run_method(
                contours, specs[method], trials, config, device, seed, callback, segments=cut
            )
    errors = {m: r.errors for m, r in results.items()}
    areas = {m: r.areas for m, r in results.items()}
    rows = []
    for k, contour in enumerate(contours):
        row = {
            "contour": contour.name,
            "none_error_vertices": float(errors["none"][k].mean()),
            "none_error_mm2": float(areas["none"][k].mean()),
        }
        for method in order:
            if method == "none" and "none" not in methods:
                continue
            pinch_k = results[method].pinches[k]
            improvement = paired_improvement(errors["none"][k], errors[method][k])
            row[f"{method}_error_vertices"] = float(errors[method][k].mean())
            row[f"{method}_error_mm2"] = float(areas[method][k].mean())
            row[f"{method}_improvement_pct"] = (
                float(np.nanmean(improvement)) if np.isfinite(improvement).any() else float("nan")
            )
            row[f"{method}_ci95"] = ci95(improvement)
            row[f"{method}_pinch"] = None if pinch_k is None else [float(v) for v in pinch_k]
            row[f"{method}_trials_error_vertices"] = [float(e) for e in errors[method][k]]
            row[f"{method}_separated_fraction"] = _mean_or_none(results[method].separated, k)
            row[f"{method}_dropped_fraction"] = _mean_or_none(results[method].dropped, k)
        rows.append(row)
    mean = {}
    for method in order:
        if method == "none" and "none" not in methods:
            continue
        values = np.array([r[f"{method}_improvement_pct"] for r in rows])
        mean[f"{method}_improvement_pct"] = (
            float(np.nanmean(values)) if np.isfinite(values).any() else float("nan")
        )
        mean[f"{method}_ci95"] = ci95(values)
    return {"score": config.score, "rows": rows, "mean": mean, "trials": trials}


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
    on_step: Callable[[str], Callable[[CuttingTask, np.ndarray | None], None] | None] | None = None,
) -> dict:
    """One contour, the baseline tensioners: the ``warpcut simulate`` report.

    ``on_step`` maps a method's name to the step callback of its batch, as in :func:`evaluate_suite`.

    Returns:
        ``{"contour": name, "score": "path"|"separated", "results": {method: {"error_vertices",
        "error_mm2", "improvement_pct", "ci95_pct", "trials_error_vertices", "separated_fraction",
        "dropped_fraction", "pinch"}}}``: means over trials; ``improvement_pct`` is the mean paired
        improvement over no tension (0 for ``none`` itself); ``separated_fraction`` the share of trials
        whose piece came free, ``dropped_fraction`` the mean share of the cut path dropped.
    """
    report = evaluate_suite([contour], methods, trials, config, pinch, device, seed, on_step=on_step)
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
        }
    return {"contour": contour.name, "score": report["score"], "results": results}
