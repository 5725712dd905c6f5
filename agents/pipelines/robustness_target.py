"""The robustness target of a tensioning policy in the force and noise studies of one contour
(:func:`robustness_target`, on :func:`agents.pipelines.robustness.robustness_study`'s reports): never worse
than no tension across gravity, and as good across noise as on the nominal sheet, read on medians and on
95% bootstrap intervals."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from warpcut.scoring import bootstrap_difference_ci


def _diverged_more(report: dict, policy: str) -> list[bool]:
    """Per value: the policy diverged in more trials than no tension did (False for a report without
    counts)."""
    counts = report.get("diverged") or {}
    mine, none = counts.get(policy), counts.get("none")
    if mine is None or none is None:
        return [False] * len(report["values"])
    return [a > b for a, b in zip(mine, none, strict=True)]


TARGET_BAND = 0.1
"""The target's noise half (:func:`robustness_target`): a policy's improvement stays within this fraction
of its nominal improvement across the noise sweep."""


def _trials(report: dict, method: str, k: int) -> np.ndarray:
    """Value ``k``'s per-trial statistics of ``method`` (NaN where undefined); empty for a report written
    before the reports kept them."""
    rows = report[method].get("per_trial")
    return np.array([] if rows is None else rows[k], dtype=np.float64)


def _verdict(interval: tuple[float, float] | None, low: float, high: float = float("inf")) -> str:
    """``in`` when the 95% ``interval`` lies within ``[low, high]``, ``out`` when it lies wholly outside,
    ``open`` when it straddles an edge or there is none (too few trials)."""
    if interval is None:
        return "open"
    if interval[0] >= low and interval[1] <= high:
        return "in"
    return "out" if interval[1] < low or interval[0] > high else "open"


def robustness_target(reports: Mapping[str, dict], policy: str, band: float = TARGET_BAND) -> dict:
    """The robustness target for the method ``policy`` in the force and noise reports of one contour
    (:func:`robustness_study`'s, by study name): a policy that never does worse than no tension across the
    force sweep (its median improvement >= 0 at every gravity), and whose improvement stays within ``band``
    of its nominal improvement across the noise sweep, judged two ways.

    - ``median``: on the medians over trials, as the target reads.
    - ``ci``: on 95% bootstrap intervals: a force value is ``in`` if its median's interval lies at or above
      0, ``out`` if wholly below it, ``open`` if it straddles 0; a noise value compares the interval of its
      median minus the nominal one with ``+- band x |nominal median|`` (``in`` inside it, ``out`` outside
      it, ``open`` across an edge; ``one_sided`` with the lower edge only). Values whose trials all agree
      (a deterministic sheet, e.g. no noise) are listed in ``deterministic``: their interval is the nominal
      one's alone, and their one outcome stands for a chaotic distribution.

    A value where the policy diverged in more trials than no tension (the report's ``diverged`` counts) is
    ``out`` in both readings and listed in ``diverged_more``; at the noise sweep's nominal value, which has
    no verdict of its own, it fails the noise half (``nominal_diverged_more``).

    Returns ``{"force": {...}, "noise": {...}}`` for the studies present, each with ``values``, the median
    reading (``median_met``; force ``lowest`` [median, value] and ``below``, noise ``within`` /
    ``not_below`` counts and the band) and the interval reading (``ci``: a verdict per value; ``ci_met``:
    "yes" when every value is ``in``, "no" when one is ``out``, else "open"). ``ValueError`` names a missing
    policy."""
    out: dict = {}
    force, noise = reports.get("force"), reports.get("noise")
    for study, report in (("force", force), ("noise", noise)):
        if report is not None and policy not in report:
            methods = ", ".join(report["methods"])
            raise ValueError(f"policy: {policy!r} is not in the {study} report (methods: {methods})")
    if force is not None:
        medians = force[policy]["median"]
        cis = force[policy].get("median_ci95") or [None] * len(medians)
        more = _diverged_more(force, policy)
        verdicts = [
            "out" if worse else _verdict(None if ci is None else tuple(ci), 0.0)
            for ci, worse in zip(cis, more, strict=True)
        ]
        out["force"] = {
            "values": force["values"],
            "lowest": list(
                min((m, v) for m, v in zip(medians, force["values"], strict=True) if m is not None)
            ),
            "below": [v for v, m in zip(force["values"], medians, strict=True) if m is not None and m < 0],
            "diverged_more": [v for v, worse in zip(force["values"], more, strict=True) if worse],
            "median_met": all(m is None or m >= 0 for m in medians) and not any(more),
            "ci": verdicts,
            "ci_met": _overall(verdicts),
        }
    if noise is not None:
        values, medians = noise["values"], noise[policy]["median"]
        k0 = int(np.argmin([abs(v - noise["nominal"]) for v in values]))
        nominal, width = medians[k0], band * abs(medians[k0])
        reference = _trials(noise, policy, k0)
        more = _diverged_more(noise, policy)
        two, one, deterministic = [], [], []
        for k, value in enumerate(values):
            if k == k0:
                continue
            trials = _trials(noise, policy, k)
            finite = trials[np.isfinite(trials)]
            if finite.size > 1 and np.all(finite == finite[0]):
                deterministic.append(value)
            interval = bootstrap_difference_ci(trials, reference) if trials.size else None
            two.append("out" if more[k] else _verdict(interval, -width, width))
            one.append("out" if more[k] else _verdict(interval, -width))
        # a value where the policy diverged more often than no tension counts as outside the band; at the
        # nominal one, the band's reference itself is a policy that fails more often: no value is within
        others = [None if more[k] or more[k0] else m for k, m in enumerate(medians) if k != k0]
        if more[k0]:
            two, one = ["out"] * len(two), ["out"] * len(one)
        out["noise"] = {
            "values": [v for k, v in enumerate(values) if k != k0],
            "nominal": values[k0],
            "nominal_median": nominal,
            "band": width,
            "diverged_more": [v for v, worse in zip(values, more, strict=True) if worse],
            "nominal_diverged_more": bool(more[k0]),
            "within": sum(m is not None and abs(m - nominal) <= width for m in others),
            "not_below": sum(m is not None and m >= nominal - width for m in others),
            "median_met": all(m is not None and abs(m - nominal) <= width for m in others),
            "median_met_one_sided": all(m is not None and m >= nominal - width for m in others),
            "ci": two,
            "ci_one_sided": one,
            "ci_met": _overall(two),
            "ci_met_one_sided": _overall(one),
            "deterministic": deterministic,
        }
    return out


def _overall(verdicts: Sequence[str]) -> str:
    """ "yes" if every verdict is ``in``, "no" if one is ``out``, else "open"."""
    return "no" if "out" in verdicts else "yes" if all(v == "in" for v in verdicts) else "open"
