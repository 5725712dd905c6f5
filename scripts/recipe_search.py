"""Compare RL training recipes under the Table I protocol on the same plans (issue 16, docs/learning.md).

Each contour is planned once (30 pinch candidates, noise-free); then, for each recipe, a policy is trained
per contour at the planned pinch and order and evaluated against none / fixed / analytic over paired,
noisy trials (:func:`agents.pipeline.evaluate_table` with ``plan=plans``). Prints per recipe the suite
means, RL's lead over the better baseline, on how many contours RL is best or within its CI of the best,
how often model selection kept the initial policy, and the training time per contour.

    python scripts/recipe_search.py [--contours fls-circle,kidney,crescent,arc-top,s-curve,e-shape]
        [--recipes warpcut,paper,...] [--iterations 60] [--num-envs 64] [--trials 10] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import pickle
import time
from pathlib import Path

import numpy as np
import torch

from agents.baselines import AnalyticTension
from agents.config import RECIPE, RECIPES, Recipe
from agents.pipeline import evaluate_table, resolve_contours
from warpcut.io import write_atomic, write_json
from warpcut.planning import plan_cut
from warpcut.sim.config import PINCH_CANDIDATES, SimConfig

OLD = {"stay_prior": 0.9, "entropy_coef": 0.01}
"""warpcut's PPO settings before issue 16 (entropy 0.01, rsl-rl's usual value)."""

CANDIDATES = {
    **RECIPES,
    "warpcut-0.01": Recipe(RECIPE, OLD),
    "no-prior": Recipe(RECIPE, {**OLD, "stay_prior": 0.0}),
    "prior-0.5": Recipe(RECIPE, {**OLD, "stay_prior": 0.5}),
    "continuous": Recipe(
        {**RECIPE, "action_type": "continuous"}, {"init_noise_std": 0.3, "entropy_coef": 0.01}
    ),
    "entropy-0.03": Recipe(RECIPE, {**OLD, "entropy_coef": 0.03}),
    "entropy-0.1": Recipe(RECIPE, {**OLD, "entropy_coef": 0.1}),
    "sparse": Recipe({**RECIPE, "dense_reward": False}, OLD),
    "validation-32": Recipe(RECIPE, {**OLD, "entropy_coef": 0.03}, validation_trials=32),
    "paper-0.01": Recipe(RECIPES["paper"].options, {"stay_prior": 0.0, "entropy_coef": 0.01}, 0),
    "margin-0": Recipe(RECIPE, {**OLD, "entropy_coef": 0.03, "selection_margin": 0.0}),
    "residual": Recipe({**RECIPE, "residual_gain": AnalyticTension.gain}, {**OLD, "entropy_coef": 0.03}),
}
"""The recipes this script knows: warpcut's and the paper's (``RECIPES``), and the variations measured for
issue 16 (``warpcut-0.01`` was warpcut's before; ``entropy-0.03`` is warpcut's now)."""


def summarise(rows: list[dict]) -> dict:
    """Suite means and RL's standing among the methods (best, or within its CI of the best)."""
    means = {
        m: float(np.mean([r[f"{m}_improvement_pct"] for r in rows])) for m in ("fixed", "analytic", "rl")
    }
    within = 0
    for r in rows:
        best = max(r[f"{m}_improvement_pct"] for m in ("fixed", "analytic", "rl"))
        within += r["rl_improvement_pct"] + r["rl_ci95"] >= best
    kept = [r.get("rl_policy_iteration") for r in rows]
    return {
        **{f"{m}_mean_pct": v for m, v in means.items()},
        "rl_lead_pct": means["rl"] - max(means["fixed"], means["analytic"]),
        "rl_best_or_within_ci": within,
        "rl_initial_policy": sum(1 for k in kept if k == 0),
        "contours": len(rows),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--contours", default="fls-circle,kidney,crescent,arc-top,s-curve,e-shape")
    parser.add_argument("--recipes", default=",".join(CANDIDATES))
    parser.add_argument("--iterations", type=int, default=60)
    parser.add_argument("--num-envs", type=int, default=64)
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("logs/recipe-search"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    config = SimConfig()
    contours = resolve_contours(args.contours)
    start = time.perf_counter()
    cache = args.out / f"plans-seed{args.seed}.pkl"  # planning is deterministic: reuse it across runs
    plans = pickle.loads(cache.read_bytes()) if cache.is_file() else {}
    for _, c in contours:
        if c.name not in plans:
            plans[c.name] = plan_cut(
                c, config.replace(noise_std=0.0), num_candidates=PINCH_CANDIDATES, seed=args.seed
            )
            write_atomic(cache, pickle.dumps(plans))
    plans = [plans[c.name] for _, c in contours]
    print(f"planned {len(plans)} contours in {time.perf_counter() - start:.0f} s", flush=True)
    results = {}
    for name in [r.strip() for r in args.recipes.split(",") if r.strip()]:
        recipe = CANDIDATES[name]
        out = args.out / f"{name}-it{args.iterations}-envs{args.num_envs}"
        start = time.perf_counter()
        report = evaluate_table(
            [s for s, _ in contours], out, trials=args.trials, config=config, plan=plans, recipe=recipe,
            iterations=args.iterations, num_envs=args.num_envs, seed=args.seed, resume=True,
        )  # fmt: skip
        train_s = [
            json.loads((run / "summary.json").read_text())["wall_time_s"] for run in report.policy_runs
        ]
        summary = {
            **summarise(report.table["rows"]),
            "train_s_per_contour": float(np.mean(train_s)),
            "seconds": time.perf_counter() - start,
        }
        results[name] = {"summary": summary, "rows": report.table["rows"]}
        print(
            f"{name:<11} fixed {summary['fixed_mean_pct']:+6.1f}  "
            f"analytic {summary['analytic_mean_pct']:+6.1f}  rl {summary['rl_mean_pct']:+6.1f}  "
            f"lead {summary['rl_lead_pct']:+5.1f}  best/within {summary['rl_best_or_within_ci']}/"
            f"{summary['contours']}  initial kept {summary['rl_initial_policy']}  "
            f"train {summary['train_s_per_contour']:.0f} s/contour",
            flush=True,
        )
        tag = f"it{args.iterations}-envs{args.num_envs}"
        write_json(
            args.out / f"results-{tag}.json", {"args": {k: str(v) for k, v in vars(args).items()}, **results}
        )


if __name__ == "__main__":
    main()
