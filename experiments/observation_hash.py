"""A hash of everything an env returns over whole episodes, to check that a speed change keeps the bits. Three
batches: 16 ``fls-circle`` envs for two episodes (seed 3) with the env's default actions (continuous moves,
es's) and with discrete moves (PPO's), and one episode of the 26 built-in contours side by side (seed 5,
continuous); random actions from a seeded generator; every observation, reward and info array (final
observations and scores included). Run it before and after a change (e.g. in a worktree of the commit before);
equal hashes mean training and the evaluation tables are unchanged.

Run: python experiments/observation_hash.py
"""

from __future__ import annotations

import argparse
import hashlib

import numpy as np


def episodes_hash(contour, num_envs: int, episodes: int, seed: int, action_type: str) -> str:
    """The first 16 hex digits of a SHA-256 over ``episodes`` whole episodes of a batched env."""
    from envs.options import PatternCutOptions
    from envs.vector import PatternCutVecEnv

    options = PatternCutOptions(contour=contour, action_type=action_type)
    env = PatternCutVecEnv(num_envs, options, autoreset_mode="same_step")  # as training steps it
    digest = hashlib.sha256()
    obs, _ = env.reset(seed=seed)
    digest.update(obs.tobytes())
    rng = np.random.default_rng(seed)
    space = env.single_action_space

    def actions() -> np.ndarray:
        if action_type == "discrete":
            return rng.integers(0, int(space.n), num_envs)
        return rng.uniform(space.low, space.high, (num_envs, *space.shape)).astype(space.dtype)

    while episodes:
        obs, reward, terminated, truncated, info = env.step(actions())
        digest.update(obs.tobytes())
        digest.update(np.asarray(reward).tobytes())
        for key in sorted(info):
            value = np.stack(list(info[key])) if key == "final_obs" else info[key]
            parts = [value[k] for k in sorted(value)] if isinstance(value, dict) else [value]
            for part in parts:
                digest.update(np.asarray(part).tobytes())
        if np.any(terminated) or np.any(truncated):
            episodes -= 1
    return digest.hexdigest()[:16]


def main() -> None:
    argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    ).parse_args()
    from warpcut.contours import builtin_names

    for action_type in ("continuous", "discrete"):
        print(
            f"fls-circle x16, 2 episodes, {action_type}:", episodes_hash("fls-circle", 16, 2, 3, action_type)
        )
    names = builtin_names()
    print(
        f"{len(names)} contours, 1 episode, continuous:", episodes_hash(names, len(names), 1, 5, "continuous")
    )


if __name__ == "__main__":
    main()
