"""Is the pinch candidate that fixed tension ranks best also the one where RL does best? (issue 16,
docs/learning.md, "Which pinch candidate RL needs").

For each contour, ``run_pipeline`` plans ``--candidates`` pinch candidates, trains a policy (warpcut's
recipe) at each of the ``--rl-candidates`` best by fixed tension, and scores each policy on its held-out
validation episodes. Prints per contour the fixed-tension rank of the candidate whose policy validated
best, and how much better it validated than the policy at fixed's favourite.

    python scripts/candidate_ranking.py [--contours fls-circle,kidney,crescent,arc-top,s-curve,e-shape]
        [--candidates 8] [--rl-candidates 4] [--iterations 60] [--out DIR]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from agents.pipeline import run_pipeline
from warpcut.io import write_json


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--contours", default="fls-circle,kidney,crescent,arc-top,s-curve,e-shape")
    parser.add_argument("--candidates", type=int, default=8)
    parser.add_argument("--rl-candidates", type=int, default=4)
    parser.add_argument("--iterations", type=int, default=60)
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--out", type=Path, default=Path("logs/candidate-ranking"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    rows = []
    for name in [c.strip() for c in args.contours.split(",") if c.strip()]:
        report = run_pipeline(
            name, args.out / name, candidates=args.candidates, rl_candidates=args.rl_candidates,
            iterations=args.iterations, trials=args.trials, progress=False,
        )  # fmt: skip
        listed = report.candidates
        fixed = [c["fixed_error_vertices"] for c in listed]
        rl = [c["rl_validation_error_vertices"] for c in listed]
        best = int(np.argmin(rl))
        rows.append(
            {
                "contour": name,
                "fixed_error_vertices": fixed,
                "rl_validation_error_vertices": rl,
                "rl_best_fixed_rank": best,
                "rl_gain_vertices": rl[0] - rl[best],
                "rl_improvement_pct": report.row["rl_improvement_pct"],
                "fixed_improvement_pct": report.row["fixed_improvement_pct"],
            }
        )
        print(
            f"{name:<11} fixed {' '.join(f'{e:5.1f}' for e in fixed)} | rl (validation) "
            f"{' '.join(f'{e:5.1f}' for e in rl)} | RL's best is fixed's #{best + 1}, "
            f"{rl[0] - rl[best]:.1f} vertices better than at fixed's #1",
            flush=True,
        )
        write_json(
            args.out / "results.json", {"args": {k: str(v) for k, v in vars(args).items()}, "rows": rows}
        )
    moved = sum(r["rl_best_fixed_rank"] > 0 for r in rows)
    print(f"RL's best candidate is not fixed's best on {moved} of {len(rows)} contours")


if __name__ == "__main__":
    main()
