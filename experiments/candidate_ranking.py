"""Is the pinch candidate that fixed tension ranks best also the one where the learned policy does best? The
measurement behind the ``fast`` budget training a policy at fixed tension's favourite only
(``rl_candidates``: 1).

For each contour, ``run_pipeline`` plans ``--candidates`` pinch candidates, trains a policy (the default
learner, or what ``--set`` says) at each of the ``--rl-candidates`` best by fixed tension, and scores each
policy on its held-out validation episodes. Prints per contour the fixed-tension rank of the candidate whose
policy validated best, and how much better it validated than the policy at fixed's favourite.

Run: python experiments/candidate_ranking.py [--contours fls-circle,kidney,crescent,arc-top,s-curve,e-shape]
     [--candidates 8] [--rl-candidates 4] [--iterations N] [--trials 10] [--set KEY=VALUE ...] [--out DIR]
     (--set: any key of 'warpcut run --print-config', e.g. --set train.algo=ppo)
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from pathlib import Path

import numpy as np
import torch

from agents.config_io import apply, parse_override
from agents.jobs import RunJob, with_dependent_defaults
from agents.pipelines import run_pipeline
from warpcut.io import write_json


def base_job(overrides: list[str]) -> RunJob:
    """``warpcut run``'s job with the ``--set`` overrides (the learner's own defaults follow, as there)."""
    sets = dict(parse_override(text) for text in overrides)
    return with_dependent_defaults(apply(RunJob(), sets, "--set"), set(sets))


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--contours", default="fls-circle,kidney,crescent,arc-top,s-curve,e-shape")
    parser.add_argument("--candidates", type=int, default=8, help="pinch candidates planned per contour")
    parser.add_argument("--rl-candidates", type=int, default=4, help="the best by fixed tension get a policy")
    parser.add_argument("--iterations", type=int, default=None, help="per policy (default: the learner's)")
    parser.add_argument("--trials", type=int, default=10, help="evaluation trials")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--out", type=Path, default=None, help="keep the runs and results.json here")
    args = parser.parse_args()
    job = base_job(args.overrides)
    job = dataclasses.replace(
        job,
        candidates=args.candidates,
        rl_candidates=args.rl_candidates,
        trials=args.trials,
        plots=False,
        train=dataclasses.replace(job.train, iterations=args.iterations or job.train.iterations),
    )
    torch.set_num_threads(1)
    rows = []
    with tempfile.TemporaryDirectory(prefix="warpcut-ranking-") as tmp:
        out = args.out or Path(tmp)
        for name in [c.strip() for c in args.contours.split(",") if c.strip()]:
            report = run_pipeline(
                dataclasses.replace(job, contour=name), out / name, overwrite=True, progress=False
            )
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
                f"{' '.join(f'{e:5.1f}' for e in rl)} | rl's best is fixed's #{best + 1}, "
                f"{rl[0] - rl[best]:.1f} vertices better than at fixed's #1",
                flush=True,
            )
            if args.out is not None:
                write_json(
                    args.out / "results.json",
                    {"args": {k: str(v) for k, v in vars(args).items()}, "rows": rows},
                )
    moved = sum(r["rl_best_fixed_rank"] > 0 for r in rows)
    print(f"rl's best candidate is not fixed's best on {moved} of {len(rows)} contours")


if __name__ == "__main__":
    main()
