"""What a trained policy does on sheets of different gravity: one deterministic episode per gravity (the
run's nominal sheet otherwise, seed 1), the count of each discrete action, the grasp's final displacement
and the error. docs/robustness.md quotes it for the randomised PPO policies at zero gravity.

    python scripts/policy_actions.py RUN [--gravity 0,130.25,521]

RUN: a run directory of a discrete policy (``warpcut train --algo ppo``, or one of ``warpcut run``'s
candidates).
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
import torch

from agents.policies import _tensordict, load_policy, policy_options, policy_runs
from envs.core import DISCRETE_MOVES
from envs.vector import PatternCutVecEnv

NAMES = ("stay", "+x", "-x", "+y", "-y", "+z", "-z")


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("run", help="a run directory of a discrete policy")
    parser.add_argument("--gravity", default="0,130.25,521", help="gravities (mm/s^2), one episode each")
    args = parser.parse_args()
    gravity = [float(g) for g in args.gravity.split(",")]
    run = policy_runs(args.run)[0][0]
    options = dataclasses.replace(policy_options(run), gravity=gravity)
    if options.action_type != "discrete":
        raise SystemExit("this script counts discrete actions; the run's policy is continuous")
    env, actor, b = PatternCutVecEnv(len(gravity), options), load_policy(run), len(gravity)
    counts = np.zeros((b, len(DISCRETE_MOVES)), dtype=int)
    obs, _ = env.reset(seed=1)
    info = {}
    with torch.inference_mode():
        for _ in range(env.task.num_steps):
            action = actor(_tensordict({"policy": torch.as_tensor(obs)}, b)).numpy().reshape(b, -1)[:, 0]
            action = action.astype(np.int64)
            counts[np.arange(b), action] += 1
            obs, _, terminated, truncated, info = env.scene.step(action)
            if terminated or truncated:
                break
    shown = NAMES[: counts.shape[1]]
    print(f"{'gravity':>8} " + " ".join(f"{n:>5}" for n in shown) + "  displacement (mm)     error (mm^2)")
    displacement = env.task.sim.displacements()
    for k, g in enumerate(gravity):
        moves = " ".join(f"{c:>5d}" for c in counts[k])
        print(f"{g:>8g} {moves}  {np.round(displacement[k], 1)!s:<20} {info['error_mm2'][k]:.1f}")


if __name__ == "__main__":
    main()
