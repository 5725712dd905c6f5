"""A grad column's plans under both scores: is the optimised plans' lead over fixed tension an artefact of the
score? The plans a ``warpcut evaluate`` run kept (RUN/grad/NAME.json, played at their pinch points) and no
and fixed tension at the run's planned pinch points and segments (RUN/plans.json), on ``--trials`` paired
noisy trials (seed 0) of the run's sheet, scored by the path score (``sim.score=path``, the paper's and the
default) and by the separated material (``sim.score=separated``). Improvement over no tension as the ratio
of mean errors.

Run: python experiments/score_both.py --run RUN [--contours all|NAME,...] [--trials 10] [--out FILE]
(RUN: a 'warpcut evaluate' run with the grad method, e.g. --methods none,fixed,grad)
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from agents.config_io import apply, read_file
from agents.evaluation import run_method
from agents.jobs import EvaluateJob
from agents.plan_optimizer.plan import PlanResult
from warpcut.contours import load_contour
from warpcut.io import read_json, safe_name
from warpcut.planning import Plan


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--run", type=Path, required=True, help="a warpcut evaluate run with a grad column")
    parser.add_argument("--contours", default="all", help="all (the run's), or comma-separated names")
    parser.add_argument("--trials", type=int, default=10, help="paired noisy trials per method")
    parser.add_argument("--out", type=Path, default=None, help="also write the lines to this file")
    args = parser.parse_args()
    for needed in ("config.json", "plans.json", "grad"):
        if not (args.run / needed).exists():
            raise SystemExit(
                f"--run: no {args.run / needed}; give a warpcut evaluate run with the grad method"
            )
    sim = apply(EvaluateJob(), read_file(args.run / "config.json"), str(args.run / "config.json")).sim
    saved = read_json(args.run / "plans.json")
    names = list(saved) if args.contours == "all" else args.contours.split(",")
    contours = [load_contour(n) for n in names]
    plans = [
        Plan.from_json(saved[n], c, sim.replace(noise_std=0.0)) for n, c in zip(names, contours, strict=True)
    ]
    segments = [p.ordered_segments() for p in plans]
    pinches = [np.asarray(p.chosen["pinch"], float) for p in plans]
    grad = [PlanResult.from_json(read_json(args.run / "grad" / f"{safe_name(n)}.json")) for n in names]
    improvement: dict[str, dict[str, np.ndarray]] = {}
    for score in ("path", "separated"):
        config = sim.replace(score=score)
        errors = {
            method: run_method(
                contours, where, policy, args.trials, config, None, 0, segments=segments
            ).error_vertices
            for method, where, policy in (
                ("none", [None] * len(names), None),
                ("fixed", pinches, None),
                ("grad", [np.asarray(r.pinch) for r in grad], PlanResult.policy(grad, args.trials)),
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
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
