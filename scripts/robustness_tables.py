"""Markdown tables of ``warpcut robustness --json`` reports, as docs/robustness.md quotes them, and the
robustness target check for a policy label: never below no tension in the force sweep (median), and within
10% of its nominal improvement across the noise sweep.

    python scripts/robustness_tables.py REPORT.json [--policy LABEL ...]
    python scripts/robustness_tables.py --summary gains4 DIR/*.json   (one row per contour)
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from agents.pipelines.robustness_target import robustness_target


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
    """The robustness target check (agents.pipelines.robustness_target) as lines: the medians'
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("report", type=Path, nargs="+")
    parser.add_argument("--policy", action="append", default=None)
    parser.add_argument("--summary", metavar="POLICY", help="one row per report for POLICY (see summary())")
    args = parser.parse_args()
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
