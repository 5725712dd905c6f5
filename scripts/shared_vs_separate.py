"""Does one PPO policy shared by all pinch candidates lose anything against one policy per candidate?
(docs/learning.md, "One policy for all pinch candidates").

For each contour: plan the cut (``--candidates`` pinch candidates plus the centroid when feasible), then

* ``shared``: one policy over every candidate (``PatternCutOptions(candidates=...)``, as ``warpcut run``
  trains it);
* ``separate``: one policy per candidate (``PatternCutOptions(pinch_point=..., segments=...)``), each with
  the same PPO budget as the shared one,

and score every (approach, candidate) on the same held-out episodes (seed 100, neither training's nor
validation's), deterministic policies, each candidate cut in its best order. Prints per contour the error
of each approach at its chosen candidate (the one its own validation chose) and at the best candidate by
these episodes, the mean error over candidates, and the training wall time.

    python scripts/shared_vs_separate.py [--contours fls-circle,ellipse-tall,arc-top] [--candidates 8]
        [--iterations 60] [--episodes 16] [--json PATH]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from agents.config import RECIPE, TrainConfig
from agents.export import load_policy
from agents.rl import chosen_candidate, policy_errors, train_contour
from envs.options import PatternCutOptions
from envs.vector import PatternCutVecEnv
from warpcut.contours import load_contour
from warpcut.io import write_json
from warpcut.planning import ArmModel, plan_cut
from warpcut.sim.config import SimConfig

EPISODE_SEED = 100


def score(actor: torch.nn.Module, options: PatternCutOptions, episodes: int) -> float:
    env = PatternCutVecEnv(episodes, options)
    return float(np.mean(policy_errors(actor, env, EPISODE_SEED)["error_vertices"]))


def compare(
    name: str,
    candidates: int,
    iterations: int,
    episodes: int,
    out: Path,
    top: int | None = None,
    envs_per_candidate: int = 8,
    separate: bool = True,
) -> dict:
    contour = load_contour(name)
    plan = plan_cut(
        contour, SimConfig(), num_candidates=candidates, seed=0, device="cpu", arm=ArmModel(length_mm=15.0)
    )
    ranked = sorted(plan.candidates, key=lambda c: c["error_vertices"])[: top or len(plan.candidates)]
    listed = [
        {
            "pinch": [float(v) for v in c["point"]],
            "segments": [s.tolist() for s in plan.ordered_segments(c["best_order"])],
        }
        for c in ranked
    ]
    k = len(listed)
    fixed = [float(c["error_vertices"]) for c in ranked]
    shared = PatternCutOptions(contour=name, candidates=listed, device="cpu", **RECIPE)
    start = time.perf_counter()
    train_contour(
        shared,
        out / "shared",
        TrainConfig(num_envs=max(64, envs_per_candidate * k), iterations=iterations),
        progress=False,
    )
    shared_s = time.perf_counter() - start
    actor = load_policy(out / "shared")
    shared_errors = [score(actor, shared.at_candidate(c), episodes) for c in range(k)]
    shared_choice = chosen_candidate(out / "shared")
    separate_errors, separate_val, separate_s = [], [], 0.0
    for c, cand in enumerate(listed if separate else []):
        single = PatternCutOptions(
            contour=name, pinch_point=cand["pinch"], segments=cand["segments"], device="cpu", **RECIPE
        )
        start = time.perf_counter()
        result = train_contour(
            single, out / f"separate-{c}", TrainConfig(num_envs=64, iterations=iterations), progress=False
        )
        separate_s += time.perf_counter() - start
        separate_val.append(result["summary"]["best"]["validation_error"])
        separate_errors.append(score(load_policy(out / f"separate-{c}"), single, episodes))
    separate_choice = int(np.argmin(separate_val)) if separate_val else 0
    if not separate_errors:
        separate_errors = [float("nan")] * k
    return {
        "contour": name,
        "candidates": k,
        "fixed_error_vertices": fixed,
        "shared_error_vertices": shared_errors,
        "separate_error_vertices": separate_errors,
        "shared_chosen": shared_choice,
        "separate_chosen": separate_choice,
        "shared_at_chosen": shared_errors[shared_choice],
        "separate_at_chosen": separate_errors[separate_choice],
        "shared_train_s": shared_s,
        "separate_train_s": separate_s,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--contours", default="fls-circle,ellipse-tall,arc-top")
    parser.add_argument("--candidates", type=int, default=8)
    parser.add_argument("--iterations", type=int, default=60)
    parser.add_argument("--episodes", type=int, default=16)
    parser.add_argument(
        "--top", type=int, default=None, help="only the best TOP candidates (by fixed tension)"
    )
    parser.add_argument("--envs-per-candidate", type=int, default=8, help="shared batch: max(64, this x K)")
    parser.add_argument("--no-separate", action="store_true", help="train only the shared policy")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    torch.set_num_threads(1)
    rows = []
    with tempfile.TemporaryDirectory(prefix="warpcut-shared-") as tmp:
        for name in [c.strip() for c in args.contours.split(",") if c.strip()]:
            row = compare(
                name,
                args.candidates,
                args.iterations,
                args.episodes,
                Path(tmp) / name,
                args.top,
                args.envs_per_candidate,
                not args.no_separate,
            )
            rows.append(row)
            parts = [
                f"{name:<14} K={row['candidates']:<3} fixed best {min(row['fixed_error_vertices']):6.1f}"
            ]
            for kind in ("shared", "separate"):
                errors = row[f"{kind}_error_vertices"]
                parts.append(
                    f"{kind}: chosen {row[f'{kind}_at_chosen']:6.1f}, best {min(errors):6.1f}, "
                    f"mean {np.mean(errors):6.1f}, {row[f'{kind}_train_s']:5.0f} s"
                )
            print(" | ".join(parts), flush=True)
    if args.json:
        write_json(args.json, {"rows": rows, "args": vars(args) | {"json": str(args.json)}})


if __name__ == "__main__":
    main()
