"""A grad column's plans under both scores: the plans an ``evaluate`` run kept (RUN/grad/NAME.json, played
at their pinch points) and no and fixed tension at the run's planned pinch points and segments
(RUN/plans.json), on the default protocol's 10 paired noisy trials (seed 0), scored by the path score (the
paper's) and by the separated material. Improvement over no tension as the ratio of mean errors. The
figures in docs/learning.md, "Evolution strategies through the batched simulator".

Run: python scripts/score_both.py --run logs/suite-es [--contours all|NAME,...] [--out logs/score_both.txt]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from agents.evaluation import run_method
from agents.gradient import PlanResult
from warpcut.contours import load_contour
from warpcut.io import read_json, safe_name
from warpcut.sim.config import SimConfig

TRIALS = 10


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--run", type=Path, required=True)
    parser.add_argument("--contours", default="all")
    parser.add_argument("--out", type=Path, default=Path("logs/score_both.txt"))
    args = parser.parse_args()
    plans = read_json(args.run / "plans.json")
    names = list(plans) if args.contours == "all" else args.contours.split(",")
    contours = [load_contour(n) for n in names]
    segments = [
        [np.asarray(plans[n]["segments"][k]["points"], float) for k in plans[n]["chosen"]["order"]]
        for n in names
    ]
    pinches = [np.asarray(plans[n]["chosen"]["pinch"], float) for n in names]
    grad = [PlanResult.from_json(read_json(args.run / "grad" / f"{safe_name(n)}.json")) for n in names]
    improvement: dict[str, dict[str, np.ndarray]] = {}
    for score in ("path", "separated"):
        config = SimConfig(score=score)
        errors = {
            method: run_method(
                contours, where, policy, TRIALS, config, None, 0, segments=segments
            ).error_vertices
            for method, where, policy in (
                ("none", [None] * len(names), None),
                ("fixed", pinches, None),
                ("grad", [np.asarray(r.pinch) for r in grad], PlanResult.policy(grad, TRIALS)),
            )
        }
        none = errors["none"].mean(axis=1)
        improvement[score] = {m: 100 * (1 - errors[m].mean(axis=1) / none) for m in ("fixed", "grad")}
    lines = []
    path, separated = improvement["path"], improvement["separated"]
    for k, name in enumerate(names):
        lines.append(
            f"{name:<18} path: fixed {path['fixed'][k]:+7.1f} grad {path['grad'][k]:+7.1f} | separated: "
            f"fixed {separated['fixed'][k]:+7.1f} grad {separated['grad'][k]:+7.1f}"
        )
    for score, columns in improvement.items():
        fixed, plan = columns["fixed"], columns["grad"]
        lines.append(
            f"{score}: mean fixed {fixed.mean():+.1f} grad {plan.mean():+.1f}; median fixed "
            f"{np.median(fixed):+.1f} grad {np.median(plan):+.1f}; grad better on "
            f"{int((plan > fixed + 0.05).sum())}, worse on {int((plan < fixed - 0.05).sum())} of {len(names)}"
        )
    print("\n".join(lines))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
