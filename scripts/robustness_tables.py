"""Markdown tables of ``warpcut robustness --json`` reports, as docs/robustness.md quotes them, and the
robustness target check for a policy label: never below no tension in the force sweep (median), and within
10% of its nominal improvement across the noise sweep.

    python scripts/robustness_tables.py REPORT.json [--policy LABEL ...]
    python scripts/robustness_tables.py --summary gains4 DIR/*.json   (one row per contour)
    python scripts/robustness_tables.py --sweep-medians DIR/robustness-*.json   (a row per contour, study)
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from warpcut.stats import bootstrap_difference_ci


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
    (:func:`agents.pipelines.robustness.robustness_study`'s, by study name): a policy that never does worse
    than no tension across the force sweep (its median improvement >= 0 at every gravity), and whose
    improvement stays within ``band`` of its nominal improvement across the noise sweep, judged two ways.

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


def table(report: dict) -> list[str]:
    methods = report["methods"]
    metric = "improvement over none (%)" if report["metric"] == "improvement_pct" else "error (% of sheet)"
    lines = [
        f"**{report['contour']}, {report['study']}** ({report['trials']} trials; median [q25, q75] {metric})",
        "",
        f"| {report['unit']} | " + " | ".join(methods) + " |",
        "|---" * (len(methods) + 1) + "|",
    ]
    for k, value in enumerate(report["values"]):
        cells = []
        for m in methods:
            med, lo, hi = (report[m][q][k] for q in ("median", "q25", "q75"))
            cells.append("-" if med is None else f"{med:.1f} [{lo:.1f}, {hi:.1f}]")
        mark = " (nominal)" if math.isclose(value, report["nominal"]) else ""
        lines.append(f"| {value:g}{mark} | " + " | ".join(cells) + " |")
    if report.get("skipped"):
        lines.append(f"\nskipped (mesh too coarse): {', '.join(f'{v:g}' for v in report['skipped'])}")
    return lines


def _counts(verdicts: list[str], table: bool = False) -> str:
    """How many values are in, open and out: "3 in, 6 open, 0 out", or "3/6/0" for a table."""
    counts = [verdicts.count(v) for v in ("in", "open", "out")]
    return (
        "/".join(map(str, counts))
        if table
        else ", ".join(f"{c} {v}" for c, v in zip(counts, ("in", "open", "out"), strict=True))
    )


def targets(reports: dict[str, dict], policy: str) -> list[str]:
    """The robustness target check (:func:`robustness_target`) as lines: the medians'
    reading, then the 95% intervals' (per value: in, open = undecided at these trials, out)."""
    result = robustness_target(reports, policy)
    out = []
    force = result.get("force")
    if force:
        worst = force["lowest"]
        out.append(
            f"force: {policy}'s lowest median improvement {worst[0]:+.1f}% (at {worst[1]:g}); below no "
            f"tension at {', '.join(f'{v:g}' for v in force['below']) or 'no value'}"
        )
        verdict = f"{_counts(force['ci'])}: {force['ci_met']}"
        out.append(f"force, 95% intervals of the medians against 0: {verdict}")
    noise = result.get("noise")
    if noise:
        medians = reports["noise"][policy]["median"]
        nominal, width = noise["nominal_median"], noise["band"]
        values = reports["noise"]["values"]
        k0 = values.index(noise["nominal"])
        pairs = [
            (m, v) for k, (m, v) in enumerate(zip(medians, values, strict=True)) if k != k0 and m is not None
        ]
        gaps = [(abs(m - nominal), v, m) for m, v in pairs]
        worst = max(gaps)
        out.append(
            f"noise: {policy}'s median improvement at the nominal {noise['nominal']:g} mm is "
            f"{nominal:+.1f}%; within 10% of it ({width:.1f} points) at {noise['within'] + 1} of "
            f"{len(gaps) + 1} values (no more than that below it at {noise['not_below'] + 1}); farthest "
            f"{worst[2]:+.1f}% at {worst[1]:g} mm"
        )
        one = ", ".join(f"{v:g}" for v in noise["deterministic"])
        deterministic = f"; deterministic (one outcome): {one}"
        out.append(
            f"noise, 95% intervals of each median minus the nominal against +-{width:.1f}: "
            f"{_counts(noise['ci'])}: {noise['ci_met']}; one-sided {_counts(noise['ci_one_sided'])}: "
            f"{noise['ci_met_one_sided']}" + (deterministic if noise["deterministic"] else "")
        )
    for study, reading in result.items():
        if reading.get("diverged_more"):
            at = ", ".join(f"{v:g}" for v in reading["diverged_more"])
            out.append(f"{study}: {policy} diverged in more trials than no tension at {at} (counted as out)")
    return out


def _read(path: Path) -> dict[str, dict]:
    data = json.loads(path.read_text())
    return data["studies"] if "studies" in data else {data["study"]: data}


def summary(paths: list[Path], policy: str) -> list[str]:
    """One markdown row per report (a contour's force and noise studies): the nominal improvement, the lowest
    force median, and the target by medians and by 95% intervals (in / open / out values; met: yes, no, or
    open when no value misses clearly but some cannot be decided at these trials)."""
    lines = [
        "| contour | trials | nominal (%) | force: lowest median (at) | force by medians | force by intervals"
        " (in/open/out) | noise by medians (within, not below, of 9) | noise by intervals, two-sided |"
        " one-sided |",
        "|---" * 9 + "|",
    ]
    for path in paths:
        reports = _read(path)
        result, force = robustness_target(reports, policy), reports["force"]
        f, n = result["force"], result["noise"]
        low = f["lowest"]

        def ci(verdicts, met, reading=None):
            more = ", ".join(f"{v:g}" for v in (reading or {}).get("diverged_more", []))
            return f"{_counts(verdicts, table=True)}: {met}" + (f" (diverged more at {more})" if more else "")

        lines.append(
            f"| {force['contour']} | {force['trials']} | {n['nominal_median']:+.1f} | "
            f"{low[0]:+.1f} ({low[1]:g}) | {'met' if f['median_met'] else 'no'} | "
            f"{ci(f['ci'], f['ci_met'], f)} | "
            f"{n['within']}, {n['not_below']} | {ci(n['ci'], n['ci_met'], n)} | "
            f"{ci(n['ci_one_sided'], n['ci_met_one_sided'])} |"
        )
    return lines


def sweep_medians(paths: list[Path]) -> list[str]:
    """One markdown row per study of each report: every method's median over the sweep of its per-value median
    improvement over no tension (%), and, for each method besides fixed and the first plan, the values where
    its median is at least that plan's (of all)."""
    lines = []
    for path in paths:
        for study, report in _read(path).items():
            methods = [m for m in report["methods"] if m != "none"] + [
                m for m in (*report.get("runs", {}), *report.get("plans", {})) if m not in report["methods"]
            ]
            plan = next(iter(report.get("plans", {})), None)
            if not lines:
                lines = ["| contour | study | " + " | ".join(methods) + " | values where ≥ the plan |", ""]
                lines[1] = "|---" * (len(methods) + 3) + "|"
            medians = {m: np.asarray(report[m]["median"], dtype=float) for m in methods}
            overall = " | ".join(f"{float(np.nanmedian(medians[m])):+.1f}" for m in methods)
            ahead = ""
            if plan is not None:
                ahead = ", ".join(
                    f"{m} {int(np.sum(medians[m] >= medians[plan]))}/{len(medians[plan])}"
                    for m in methods
                    if m not in ("fixed", plan)
                )
            lines.append(f"| {report['contour']} | {study} | {overall} | {ahead} |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("report", type=Path, nargs="+")
    parser.add_argument("--policy", action="append", default=None)
    parser.add_argument("--summary", metavar="POLICY", help="one row per report for POLICY (see summary())")
    parser.add_argument("--sweep-medians", action="store_true", help="medians over sweeps (sweep_medians())")
    args = parser.parse_args()
    if args.sweep_medians:
        print("\n".join(sweep_medians(args.report)))
        return
    if args.summary:
        print("\n".join(summary(args.report, args.summary)))
        return
    if len(args.report) != 1:
        parser.error("give one report, or --summary POLICY with several")
    reports = _read(args.report[0])
    for report in reports.values():
        print("\n".join(table(report)), end="\n\n")
    for policy in args.policy or []:
        print("\n".join(targets(reports, policy)))


if __name__ == "__main__":
    main()
