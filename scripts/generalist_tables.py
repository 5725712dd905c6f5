"""The generalist's zero-shot tables of docs/results.md from a ``warpcut evaluate`` run with the
``generalist`` column (``results.json``): per contour every method's improvement over no tension ± its 95%
CI over the paired trials, the generalist's paired difference from per-contour training (``rl``) and from
the better baseline, where it holds still (validating no better than that) and what it scores played
there too (unguarded), the gain on its moves it plays with (×g where not 1), and the summary rows the
targets read (the mean over contours ± its 95% CI over contours, the lead over the better of fixed and
analytic, on how many contours the generalist is the best method or the best lies within its CI).

Run: python scripts/generalist_tables.py RESULTS.json [--others fixed,analytic]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from warpcut.stats import mean_ci95, paired_improvement


def _trials(row: dict, method: str) -> np.ndarray:
    return paired_improvement(row["none_trials_error_vertices"], row[f"{method}_trials_error_vertices"])


def _zero_shot_best(row: dict, method: str, baselines: list[str]) -> bool:
    """``method`` is the best of ``baselines`` and itself, or the best lies within its CI."""
    best = max(row[f"{b}_improvement_pct"] for b in baselines)
    return best - row[f"{method}_improvement_pct"] <= row[f"{method}_ci95"]


def _worse_than_still(row: dict, method: str) -> bool:
    """``method``'s paired improvement over fixed tension (holding still) is below zero beyond its CI."""
    mean, ci = mean_ci95(_trials(row, method) - _trials(row, "fixed"))
    return mean + ci < 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results")
    parser.add_argument("--others", default="fixed,analytic", help="the baselines the lead is measured over")
    args = parser.parse_args()
    report = json.loads(open(args.results).read())
    rows = report["rows"]
    methods = [m for m in ("fixed", "analytic", "rl", "generalist") if f"{m}_improvement_pct" in rows[0]]
    guarded = (
        "generalist_played_improvement_pct" in rows[0]
    )  # the column holds still where it validates worse
    baselines = [b for b in args.others.split(",") if b in methods]
    has_rl = "rl" in methods
    head = ["contour", "no tension (vertices)", *methods]
    head += ["generalist played (unguarded)"] if guarded else []
    head += ["generalist - rl (paired)"] if has_rl else []
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    best_or_within, zero_shot_best, vs_rl, vs_base = 0, 0, [], []
    for row in rows:
        imps = {m: row[f"{m}_improvement_pct"] for m in methods}
        cells = [f"{imps[m]:+.1f} ± {row[f'{m}_ci95']:.1f}" for m in methods]
        best = max(v for v in imps.values() if np.isfinite(v))
        zero_shot_best += _zero_shot_best(row, "generalist", baselines)
        if imps["generalist"] >= best or best - imps["generalist"] <= row["generalist_ci95"]:
            best_or_within += 1
            cells[methods.index("generalist")] = f"**{cells[methods.index('generalist')]}**"
        if row.get("generalist_holds_still"):
            cells[methods.index("generalist")] += " (holds still)"
        elif row.get("generalist_gain", 1.0) != 1.0:  # its moves scaled by the gain it validated best with
            cells[methods.index("generalist")] += f" ×{row['generalist_gain']:g}"
        if not row.get("generalist_holds_still") and row.get("generalist_member"):  # another member plays
            cells[methods.index("generalist")] += f" (m{row['generalist_member']})"
        if guarded:
            cells.append(
                f"{row['generalist_played_improvement_pct']:+.1f} ± {row['generalist_played_ci95']:.1f}"
            )
        if has_rl:
            diff = _trials(row, "generalist") - _trials(row, "rl")
            mean, ci = mean_ci95(diff)
            cells.append(f"{mean:+.1f} ± {ci:.1f}")
            vs_rl.append(imps["generalist"] - imps["rl"])
        vs_base.append(imps["generalist"] - max(imps[b] for b in baselines))
        print(f"| {row['contour']} | {row['none_error_vertices']:.1f} | " + " | ".join(cells) + " |")
    means = {m: mean_ci95([r[f"{m}_improvement_pct"] for r in rows]) for m in methods}
    cells = [f"{means[m][0]:+.1f} ± {means[m][1]:.1f}" for m in methods]
    if guarded:
        cells.append(
            "{:+.1f} ± {:.1f}".format(*mean_ci95([r["generalist_played_improvement_pct"] for r in rows]))
        )
    if has_rl:
        cells.append("{:+.1f} ± {:.1f}".format(*mean_ci95(vs_rl)))
    print("| **mean** | | " + " | ".join(cells) + " |")
    better = max(means[b][0] for b in baselines)
    print()
    print(f"- contours: {len(rows)}; trials per contour and method: {report['trials']}")
    print(f"- generalist, mean over contours: {means['generalist'][0]:+.1f} ± {means['generalist'][1]:.1f}")
    print(
        f"- lead over the better baseline's mean ({better:+.1f}): {means['generalist'][0] - better:+.1f} "
        f"points; contour by contour {np.mean(vs_base):+.1f} ± {mean_ci95(vs_base)[1]:.1f}"
    )
    print(f"- above both baselines on {sum(v > 0 for v in vs_base)} of {len(rows)} contours")
    print(
        f"- best of the methods that need no training ({', '.join(baselines)}, generalist), or the best "
        f"within its CI: {zero_shot_best} of {len(rows)} ({100 * zero_shot_best / len(rows):.0f}%)"
    )
    print(
        f"- best of every method, or the best within its CI: {best_or_within} of {len(rows)} "
        f"({100 * best_or_within / len(rows):.0f}%)"
    )
    if guarded:  # the generalist itself, never holding still, against the same baselines
        within = sum(_zero_shot_best(row, "generalist_played", baselines) for row in rows)
        mean = mean_ci95([r["generalist_played_improvement_pct"] for r in rows])[0]
        print(
            f"- the generalist played: mean {mean:+.1f}; the best of the methods that need no training, or "
            f"within its CI: {within} of {len(rows)}"
        )
    for played in ("generalist", "generalist_played") if guarded else ("generalist",):
        worse = sum(_worse_than_still(row, played) for row in rows)
        what = played.replace("_", " ")
        print(f"- {what} worse than holding still (fixed) beyond its CI: {worse} of {len(rows)}")
    if guarded:
        still = sum(bool(r["generalist_holds_still"]) for r in rows)
        print(f"- holds still where its choice cuts no better: {still} of {len(rows)} contours")
    if "generalist_gain" in rows[0]:
        plays = [r["generalist_gain"] for r in rows if not r["generalist_holds_still"]]
        gains, counts = np.unique(plays, return_counts=True)
        listed = ", ".join(f"×{g:g} on {n}" for g, n in zip(gains, counts, strict=True))
        print(f"- the gain on its moves where it plays: {listed}")
    if any(r.get("generalist_member") for r in rows):
        members = [r["generalist_member"] for r in rows if not r["generalist_holds_still"]]
        index, counts = np.unique(members, return_counts=True)
        listed = ", ".join(f"member {m} on {n}" for m, n in zip(index, counts, strict=True))
        print(f"- the member that plays where it plays (0: its own policy): {listed}")
    if has_rl:
        print(
            "- generalist - per-contour rl, mean over contours: {:+.1f} ± {:.1f} points".format(
                *mean_ci95(vs_rl)
            )
        )


if __name__ == "__main__":
    main()
