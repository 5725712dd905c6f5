"""The per-contour tables of docs/results.md from a ``warpcut evaluate`` run (its ``results.json``): every
method's improvement over no tension ± its 95% CI over the paired trials, what rl's model selection kept
(the still grasp, the teacher's plan or the trained student), the policy's paired difference from the plan
(``grad``), and the summary rows the targets read: each method's mean over contours ± its 95% CI over
contours, on how many contours the policy is the best method or the best lies within its CI, and on how
many it is at least the plan's level (above it, or the plan within the policy's CI).

Run: python scripts/policy_tables.py RESULTS.json [--policy rl] [--plan grad]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from warpcut.stats import mean_ci95, paired_improvement

METHODS = ("fixed", "analytic", "rl", "grad", "generalist")
"""The columns, in this order, where the run has them."""


def _trials(row: dict, method: str) -> np.ndarray:
    return paired_improvement(row["none_trials_error_vertices"], row[f"{method}_trials_error_vertices"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results")
    parser.add_argument("--policy", default="rl", help="the policy's column")
    parser.add_argument("--plan", default="grad", help="the open-loop plan's column")
    args = parser.parse_args()
    report = json.loads(open(args.results).read())
    rows, policy, plan = report["rows"], args.policy, args.plan
    methods = [m for m in METHODS if f"{m}_improvement_pct" in rows[0]]
    has_plan = plan in methods
    head = ["contour", "no tension (vertices)", *methods, "kept"]
    head += [f"{policy} - {plan} (paired)"] if has_plan else []
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    best_or_within, plan_level, vs_plan, kept = 0, 0, [], {}
    for row in rows:
        imps = {m: row[f"{m}_improvement_pct"] for m in methods}
        cells = [f"{imps[m]:+.1f} ± {row[f'{m}_ci95']:.1f}" for m in methods]
        best = max(v for v in imps.values() if np.isfinite(v))
        if best - imps[policy] <= row[f"{policy}_ci95"]:
            best_or_within += 1
            cells[methods.index(policy)] = f"**{cells[methods.index(policy)]}**"
        what = row.get("rl_kept") or "-"
        kept[what] = kept.get(what, 0) + 1
        cells.append(what)
        if has_plan:
            diff = _trials(row, policy) - _trials(row, plan)
            mean, ci = mean_ci95(diff)
            # the kept policy plays the plan, trial for trial: no difference to estimate (not a CI of 0)
            cells.append("the plan" if not np.any(diff) else f"{mean:+.1f} ± {ci:.1f}")
            vs_plan.append(imps[policy] - imps[plan])
            plan_level += imps[policy] >= imps[plan] or imps[plan] - imps[policy] <= row[f"{policy}_ci95"]
        print(f"| {row['contour']} | {row['none_error_vertices']:.1f} | " + " | ".join(cells) + " |")
    means = {m: mean_ci95([r[f"{m}_improvement_pct"] for r in rows]) for m in methods}
    cells = [f"{means[m][0]:+.1f} ± {means[m][1]:.1f}" for m in methods] + [""]
    if has_plan:
        cells.append("{:+.1f} ± {:.1f}".format(*mean_ci95(vs_plan)))
    print("| **mean** | | " + " | ".join(cells) + " |")
    print()
    print(f"- contours: {len(rows)}; trials per contour and method: {report['trials']}")
    for m in methods:
        print(f"- {m}, mean over contours: {means[m][0]:+.1f} ± {means[m][1]:.1f}")
    print(f"- {policy}: best of every method, or the best within its CI, on {best_or_within} of {len(rows)}")
    print(f"- {policy} kept: " + ", ".join(f"{k} on {v}" for k, v in sorted(kept.items())))
    if has_plan:
        print(f"- {policy} above {plan}, or {plan} within {policy}'s CI, on {plan_level} of {len(rows)}")
        print(f"- {policy} - {plan}, mean over contours: {np.mean(vs_plan):+.1f} points")


if __name__ == "__main__":
    main()
