"""Markdown tables of ``warpcut robustness --json`` reports, as docs/robustness.md quotes them, and the
issue-20 target check for a policy label: never below no tension in the force sweep (median), and within
10% of its nominal improvement across the noise sweep.

    python scripts/robustness_tables.py logs/robust/fls-circle-studies.json [--policy randomized]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path


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


def targets(reports: dict[str, dict], policy: str) -> list[str]:
    out = []
    force = reports.get("force")
    if force and policy in force:
        medians = force[policy]["median"]
        worst = min((m, v) for m, v in zip(medians, force["values"], strict=True) if m is not None)
        below = [v for m, v in zip(medians, force["values"], strict=True) if m is not None and m < 0]
        out.append(
            f"force: {policy}'s lowest median improvement {worst[0]:+.1f}% (at {worst[1]:g}); below no "
            f"tension at {', '.join(f'{v:g}' for v in below) or 'no value'}"
        )
    noise = reports.get("noise")
    if noise and policy in noise:
        medians = noise[policy]["median"]
        k = min(range(len(noise["values"])), key=lambda i: abs(noise["values"][i] - noise["nominal"]))
        nominal = medians[k]
        gaps = [
            (abs(m - nominal), v, m) for m, v in zip(medians, noise["values"], strict=True) if m is not None
        ]
        worst = max(gaps)
        within = sum(1 for g, _, _ in gaps if g <= 0.1 * abs(nominal))
        not_below = sum(1 for _, _, m in gaps if m >= nominal - 0.1 * abs(nominal))
        out.append(
            f"noise: {policy}'s median improvement at the nominal {noise['values'][k]:g} mm is "
            f"{nominal:+.1f}%; within 10% of it ({0.1 * abs(nominal):.1f} points) at {within} of {len(gaps)} "
            f"values (no more than that below it at {not_below}); farthest {worst[2]:+.1f}% at "
            f"{worst[1]:g} mm"
        )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("report", type=Path)
    parser.add_argument("--policy", action="append", default=None)
    args = parser.parse_args()
    data = json.loads(args.report.read_text())
    reports = data["studies"] if "studies" in data else {data["study"]: data}
    for report in reports.values():
        print("\n".join(table(report)), end="\n\n")
    for policy in args.policy or []:
        print("\n".join(targets(reports, policy)))


if __name__ == "__main__":
    main()
