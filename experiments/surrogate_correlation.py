"""How well the path surrogate (what warpcut.gradients differentiates; grad's tape estimator and APG descend
it) tracks the path score (the paper's symmetric difference): both measured on random open-loop plans, per
contour of the built-in suite.

Each contour is cut in one batch of ``--plans`` envs at its planned pinch point and order (noisy, the
default protocol's noise): env 0 holds still (fixed tension), the others play random plans, smooth
random walks of grasp moves (a new direction every few steps, up to 1 mm per axis, z at a third of x-y),
of a random strength. Reported per contour: the Pearson and Spearman correlations between the surrogate
(mean squared material distance, mm^2) and the path error (vertices) over the plans, and over the suite:
their medians and the pooled rank correlation (each contour's values ranked within it).

Run: python experiments/surrogate_correlation.py [--plans 64] [--contours all] [--out FILE] [--json PATH]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy import stats

from agents.plan_optimizer.plan import PlanPolicy
from warpcut import SimConfig, plan_cut
from warpcut.contours import builtin_contours, load_contour
from warpcut.gradients import path_surrogate
from warpcut.io import write_json
from warpcut.task import CuttingTask


def random_plans(rng: np.random.Generator, count: int, steps: int, max_step: float) -> list[np.ndarray]:
    """``count`` plans (steps, 3): the first holds still, the others are smooth random walks."""
    plans = [np.zeros((steps, 3), np.float32)]
    for _ in range(count - 1):
        hold = int(rng.integers(4, 16))
        directions = rng.normal(size=(steps // hold + 1, 3)) * np.array([1.0, 1.0, 1 / 3])
        strength = rng.uniform(0.1, 1.0)
        moves = np.repeat(directions, hold, axis=0)[:steps] * strength
        plans.append(np.clip(moves, -max_step, max_step).astype(np.float32))
    return plans


def measure(name: str, plans_per_contour: int, seed: int) -> dict:
    config = SimConfig()
    contour = load_contour(name)
    plan = plan_cut(contour, config.replace(noise_std=0.0), seed=seed)
    segments = plan.ordered_segments()
    task = CuttingTask(
        config, [contour] * plans_per_contour, pinch_points=[plan.chosen["pinch"]] * plans_per_contour,
        segments=[segments] * plans_per_contour, seed=seed,
    )  # fmt: skip
    rng = np.random.default_rng(seed)
    plans = random_plans(rng, plans_per_contour, task.num_steps, config.max_step_mm)
    score = task.run(PlanPolicy(plans, 1))
    surrogate, _ = path_surrogate(task.cut_path(), task.target_points())
    error = score.error_vertices
    ok = np.isfinite(surrogate) & np.isfinite(error)
    return {
        "contour": name,
        "pearson": float(stats.pearsonr(surrogate[ok], error[ok])[0]),
        "spearman": float(stats.spearmanr(surrogate[ok], error[ok])[0]),
        "error_range": [float(error[ok].min()), float(error[ok].max())],
        "surrogate_range": [float(surrogate[ok].min()), float(surrogate[ok].max())],
        "fixed_error": float(error[0]),
        "ranks": (stats.rankdata(surrogate[ok]).tolist(), stats.rankdata(error[ok]).tolist()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--plans", type=int, default=64, help="plans per contour, the first holding still")
    parser.add_argument("--contours", default="all", help="all, or comma-separated names")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None, help="also write the lines to this file")
    parser.add_argument("--json", type=Path, default=None, help="write the summary and rows here")
    args = parser.parse_args()
    names = list(builtin_contours()) if args.contours == "all" else args.contours.split(",")
    rows = []
    lines = [f"{'contour':<18} {'pearson':>8} {'spearman':>9} {'error range (vertices)':>24}"]
    for name in names:
        row = measure(name, args.plans, args.seed)
        rows.append(row)
        lo, hi = row["error_range"]
        lines.append(f"{name:<18} {row['pearson']:>8.2f} {row['spearman']:>9.2f} {lo:>11.1f} .. {hi:<10.1f}")
        print(lines[-1], flush=True)
    pooled_x = np.concatenate([r["ranks"][0] for r in rows])
    pooled_y = np.concatenate([r["ranks"][1] for r in rows])
    summary = {
        "median_pearson": float(np.median([r["pearson"] for r in rows])),
        "median_spearman": float(np.median([r["spearman"] for r in rows])),
        "pooled_within_contour_spearman": float(stats.pearsonr(pooled_x, pooled_y)[0]),
        "contours_spearman_above_0_5": sum(r["spearman"] > 0.5 for r in rows),
        "contours": len(rows),
        "plans_per_contour": args.plans,
    }
    lines.append(
        f"median pearson {summary['median_pearson']:.2f}, median spearman {summary['median_spearman']:.2f}, "
        f"pooled within-contour rank correlation {summary['pooled_within_contour_spearman']:.2f}; "
        f"spearman > 0.5 on {summary['contours_spearman_above_0_5']} of {len(rows)} contours "
        f"({args.plans} plans each)"
    )
    print(lines[-1])
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text("\n".join(lines) + "\n")
    if args.json:
        for row in rows:
            del row["ranks"]
        write_json(args.json, {"summary": summary, "rows": rows})


if __name__ == "__main__":
    main()
