"""Compare tensioners on a contour: every trial of a method is one env of one simulator batch."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import stats

from agents.baselines import make_policy
from warpcut.config import SimConfig
from warpcut.contours import Contour
from warpcut.scoring import improvement_pct
from warpcut.task import CuttingTask


def ci95(values: np.ndarray) -> float:
    """Half-width of the 95% confidence interval of the mean (Student t); 0 for fewer than 2 values."""
    values = np.asarray(values, dtype=np.float64)
    if values.size < 2:
        return 0.0
    return float(stats.t.ppf(0.975, values.size - 1) * values.std(ddof=1) / np.sqrt(values.size))


def compare_policies(
    contour: Contour,
    methods: Sequence[str] = ("none", "fixed", "analytic"),
    trials: int = 1,
    config: SimConfig | None = None,
    pinch: tuple[float, float] | None = None,
    device: str | None = None,
    seed: int = 0,
) -> dict:
    """Run each baseline tensioner for ``trials`` seeded trials on ``contour`` and score it.

    Trials differ by their process-noise stream (``config.noise_std``); without noise they coincide.
    The no-tension baseline always runs: improvements are relative to it.

    Returns:
        ``{"contour": name, "results": {method: {"error_vertices", "error_mm2", "improvement_pct",
        "ci95_pct", "trials_error_vertices", "pinch"}}}``; per-method figures are means over trials,
        ``improvement_pct`` is ``100 * (E_none - E_method) / E_none`` of the means, ``ci95_pct`` the
        95% CI half-width of the per-trial improvements.
    """
    config = (config or SimConfig()).validated()
    if not isinstance(trials, int) or trials < 1:
        raise ValueError(f"trials: must be a positive integer (got {trials!r})")
    order = ["none"] + [m for m in methods if m != "none"]
    errors: dict[str, np.ndarray] = {}
    areas: dict[str, np.ndarray] = {}
    pinches: dict[str, list[float] | None] = {}
    for method in order:
        policy = make_policy(method, pinch)
        point = policy.pinch_point(contour, config, device=device, seed=seed)
        task = CuttingTask(config, contour, num_envs=trials, pinch_points=point, device=device, seed=seed)
        score = task.run(policy)
        errors[method], areas[method] = score.error_vertices, score.error_mm2
        pinches[method] = None if point is None else [float(v) for v in point]
    none = errors["none"]
    results = {}
    for method in order:
        if method not in methods:
            continue
        per_trial = improvement_pct(none, errors[method]) if np.all(none > 0) else np.full(trials, np.nan)
        mean_none = none.mean()
        results[method] = {
            "error_vertices": float(errors[method].mean()),
            "error_mm2": float(areas[method].mean()),
            "improvement_pct": float(improvement_pct(mean_none, errors[method].mean()))
            if mean_none > 0
            else float("nan"),
            "ci95_pct": ci95(per_trial),
            "trials_error_vertices": [float(e) for e in errors[method]],
            "pinch": pinches[method],
        }
    return {"contour": contour.name, "results": results}
