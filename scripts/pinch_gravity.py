"""A still grasp at every pinch candidate across the force sweep, against no tension: is any pinch never
worse than no tension, and how firmly does one noise seed's median decide "worse"? (docs/robustness.md,
"The target": medians of few trials can flip sign on a light sheet.)

The contour is planned as the pipeline plans it (noise-free); every feasible candidate then holds still at
its point, in its best order, on ``--trials`` noisy trials at each gravity of the force study, paired
trial for trial with no tension (the same batch layout and noise seed). Per candidate and gravity: the
median of the paired per-trial improvements (the robustness study's statistic) and, for the planner's
choice, a bootstrap 95% interval of that median, for each noise seed in ``--seeds``.

Run: python scripts/pinch_gravity.py [--contour fls-circle] [--trials 20] [--seeds 0,1] [--candidates N]
     [--out FILE]   (FILE: also write the lines there)
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from agents.evaluation import run_method
from agents.pipelines.robustness_studies import STUDY_VALUES
from warpcut import SimConfig, plan_cut
from warpcut.contours import load_contour
from warpcut.stats import paired_improvement


def paired_medians(contour, plan, config: SimConfig, gravity: float, trials: int, seed: int) -> np.ndarray:
    """(K, trials) paired per-trial improvements (%) of every candidate's still grasp over no tension."""
    cands = plan.candidates
    segments = [plan.ordered_segments(c["best_order"]) for c in cands]
    config = config.replace(gravity=gravity)
    k = len(cands)
    none = run_method([contour] * k, [None] * k, None, trials, config, None, seed, segments=segments)
    still = run_method(
        [contour] * k,
        [np.asarray(c["point"]) for c in cands],
        None,
        trials,
        config,
        None,
        seed,
        segments=segments,
    )
    return paired_improvement(none.error_vertices, still.error_vertices)


def bootstrap_median(values: np.ndarray, rng: np.random.Generator, draws: int = 2000) -> tuple[float, float]:
    values = values[np.isfinite(values)]
    samples = rng.choice(values, size=(draws, len(values)), replace=True)
    low, high = np.percentile(np.median(samples, axis=1), [2.5, 97.5])
    return float(low), float(high)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--contour", default="fls-circle", help="a built-in name or a contour file")
    parser.add_argument("--trials", type=int, default=20, help="noisy trials per candidate and gravity")
    parser.add_argument("--seeds", default="0,1", help="noise seeds, comma-separated")
    parser.add_argument("--candidates", type=int, default=None, help="pinch candidates (default: the plan's)")
    parser.add_argument("--out", type=Path, default=None, help="also write the lines to this file")
    args = parser.parse_args()
    config = SimConfig()
    contour = load_contour(args.contour)
    sampled = {} if args.candidates is None else {"num_candidates": args.candidates}
    plan = plan_cut(contour, config.replace(noise_std=0.0), seed=0, **sampled)
    gravities = list(STUDY_VALUES["force"])
    chosen = int(np.argmin([np.abs(c["point"] - plan.chosen["pinch"]).max() for c in plan.candidates]))
    rng = np.random.default_rng(0)
    lines = [f"{args.contour}: {len(plan.candidates)} candidates, planner's choice {plan.chosen['pinch']}"]
    print(lines[0], flush=True)
    medians = {}
    for seed in (int(s) for s in args.seeds.split(",")):
        row = []
        for gravity in gravities:
            improvements = paired_medians(contour, plan, config, gravity, args.trials, seed)
            medians.setdefault(seed, []).append(np.nanmedian(improvements, axis=1))
            low, high = bootstrap_median(improvements[chosen], rng)
            row.append(f"{gravity:g}: {np.nanmedian(improvements[chosen]):+.1f} [{low:+.1f}, {high:+.1f}]")
        lines.append(f"planner's pinch, seed {seed}, median paired improvement [95% CI]: " + "; ".join(row))
        print(lines[-1], flush=True)
    ranked = len(lines)
    first = np.array(medians[min(medians)])  # (G, K), the first seed
    worst = first.min(axis=0)
    lines.append(f"candidates by their worst median over the sweep (seed {min(medians)}):")
    for k in np.argsort(-worst)[:6]:
        point = np.round(plan.candidates[k]["point"], 1).tolist()
        nominal = first[gravities.index(config.gravity), k]
        lines.append(
            f"  {point}: worst {worst[k]:+.1f}, nominal {nominal:+.1f}, {np.round(first[:, k], 1).tolist()}"
        )
    print("\n".join(lines[ranked:]))
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
