"""What domain randomisation costs per episode (docs/robustness.md, "Cost"): env steps/s of a 64-env vector
env cutting fls-circle with random discrete moves, the nominal sheet against
``randomize=gravity,elasticity,noise`` (a new draw per env at every reset). The first episodes of a
randomised env settle the level combinations they meet; the median over episodes is what training sees
once they are kept.

    python scripts/randomization_cost.py [--episodes 12] [--envs 64]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from envs.options import PatternCutOptions
from envs.vector import PatternCutVecEnv


def episode_rates(randomize: list[str], envs: int, episodes: int) -> list[float]:
    options = PatternCutOptions(
        contour="fls-circle", action_type="discrete", randomize=randomize, device="cpu"
    )
    env = PatternCutVecEnv(envs, options, autoreset_mode="same_step")  # resets in the ending step
    choices = int(env.single_action_space.n)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    rates = []
    for _ in range(episodes):
        start, steps = time.perf_counter(), 0
        while True:  # the vector env resets itself (drawing anew) after the last step
            _, _, terminated, truncated, _ = env.step(rng.integers(0, choices, size=envs))
            steps += envs
            if terminated.any() or truncated.any():
                break
        rates.append(steps / (time.perf_counter() - start))
    return rates


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--episodes", type=int, default=12, help="whole episodes timed per setting")
    parser.add_argument("--envs", type=int, default=64, help="the batch")
    args = parser.parse_args()
    nominal = episode_rates([], args.envs, args.episodes)
    randomized = episode_rates(["gravity", "elasticity", "noise_std"], args.envs, args.episodes)
    for name, rates in (("nominal", nominal), ("randomized", randomized)):
        print(f"{name:>10}: median {np.median(rates):,.0f} env steps/s (first episode {rates[0]:,.0f})")
    print(f"randomized / nominal (medians): {np.median(randomized) / np.median(nominal):.2f}")


if __name__ == "__main__":
    main()
