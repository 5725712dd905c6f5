"""Comparing scores: a method's improvement over no tension (:func:`improvement_pct`, paired per trial:
:func:`paired_improvement`), the mean with its 95% Student t interval (:func:`mean_ci95`, :func:`ci95`) and
seeded percentile-bootstrap intervals of a statistic (:func:`bootstrap_ci`) or of the difference between two
samples' (:func:`bootstrap_difference_ci`). The scores themselves are :mod:`warpcut.scoring`'s."""

from __future__ import annotations

import numpy as np


def improvement_pct(e_none: np.ndarray | float, e_method: np.ndarray | float) -> np.ndarray | float:
    """Relative error reduction of a tensioning method over cutting without tensioning (%).

    Args:
        e_none: Error without tensioning (any unit, > 0), scalar or array.
        e_method: Error with the method, in the same unit, broadcastable against ``e_none``.

    Returns:
        ``100 * (e_none - e_method) / e_none``: 100 for a perfect cut, 0 for no gain, negative when the
        method does worse.

    Raises:
        ValueError: Some ``e_none`` is not > 0 (the improvement is undefined).
    """
    e_none = np.asarray(e_none, dtype=np.float64)
    e_method = np.asarray(e_method, dtype=np.float64)
    if not np.all(e_none > 0):
        raise ValueError(
            f"e_none: the error without tensioning must be > 0 to measure an improvement over it "
            f"(got min {np.min(e_none)})"
        )
    return 100.0 * (e_none - e_method) / e_none


NEGLIGIBLE_ERROR = 1e-3
"""An error (vertices or mm^2) below which no tension's error is zero within the geometry's float precision
(its round-off leaves errors of ~1e-4 mm^2 where the cut is exact; a cut's real errors are tenths of a mm^2
and up): an improvement over it means nothing, and is undefined (NaN), as over an error of 0."""


def paired_improvement(e_none: np.ndarray, e_method: np.ndarray) -> np.ndarray:
    """Per-trial :func:`improvement_pct` of paired trials; NaN where no tension's error is zero within float
    precision (:data:`NEGLIGIBLE_ERROR`): undefined."""
    e_none, e_method = np.broadcast_arrays(
        np.asarray(e_none, dtype=np.float64), np.asarray(e_method, np.float64)
    )
    out = np.full(e_none.shape, np.nan)
    defined = e_none >= NEGLIGIBLE_ERROR
    out[defined] = improvement_pct(e_none[defined], e_method[defined])
    return out


def ci95(values: np.ndarray) -> float:
    """Half-width of the 95% confidence interval of the mean (Student t) of the finite ``values``; 0 for
    fewer than 2 of them."""
    from scipy import stats

    values = np.asarray(values, dtype=np.float64)
    values = values[np.isfinite(values)]
    if values.size < 2:
        return 0.0
    return float(stats.t.ppf(0.975, values.size - 1) * values.std(ddof=1) / np.sqrt(values.size))


def mean_ci95(values: np.ndarray) -> tuple[float, float]:
    """``(mean, ci95)`` of the finite ``values`` (NaN trials, e.g. undefined improvements, are left out);
    the mean is NaN when none is finite."""
    values = np.asarray(values, dtype=np.float64)
    mean = float(np.nanmean(values)) if np.isfinite(values).any() else float("nan")
    return mean, ci95(values)


BOOTSTRAP_RESAMPLES = 10_000
"""Resamples of the percentile-bootstrap 95% confidence intervals (:func:`bootstrap_ci`; seeded: an interval
is the same every time)."""


BOOTSTRAP_STATISTICS = {"mean": np.mean, "median": np.median}
"""The statistics :func:`bootstrap_ci` and :func:`bootstrap_difference_ci` take, by name."""


def _finite(values) -> np.ndarray:
    values = np.asarray(values, dtype=np.float64).ravel()
    return values[np.isfinite(values)]


def _statistic(name: str):
    if name not in BOOTSTRAP_STATISTICS:
        raise ValueError(f"statistic: must be one of {', '.join(BOOTSTRAP_STATISTICS)} (got {name!r})")
    return BOOTSTRAP_STATISTICS[name]


def bootstrap_ci(
    values, statistic: str = "mean", resamples: int = BOOTSTRAP_RESAMPLES, seed: int = 0
) -> tuple[float, float] | None:
    """The 95% percentile-bootstrap confidence interval of the ``statistic`` (``mean`` or ``median``) of the
    finite ``values``; None for fewer than two. It lies within ``[min, max]`` of the values, and is a point
    when they are all equal (a deterministic outcome repeated: one sample, not a certainty)."""
    function, values = _statistic(statistic), _finite(values)
    if values.size < 2:
        return None
    draws = np.random.default_rng(seed).integers(0, values.size, size=(resamples, values.size))
    low, high = np.percentile(function(values[draws], axis=1), [2.5, 97.5])
    return float(low), float(high)


def bootstrap_difference_ci(
    a, b, statistic: str = "median", resamples: int = BOOTSTRAP_RESAMPLES, seed: int = 0
) -> tuple[float, float] | None:
    """The 95% percentile-bootstrap confidence interval of ``statistic(a) - statistic(b)`` for two independent
    samples (each resampled on its own; finite values only); None when either has fewer than two."""
    function, a, b = _statistic(statistic), _finite(a), _finite(b)
    if a.size < 2 or b.size < 2:
        return None
    rng = np.random.default_rng(seed)
    draws_a = rng.integers(0, a.size, size=(resamples, a.size))
    draws_b = rng.integers(0, b.size, size=(resamples, b.size))
    low, high = np.percentile(function(a[draws_a], axis=1) - function(b[draws_b], axis=1), [2.5, 97.5])
    return float(low), float(high)
