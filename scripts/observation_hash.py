"""A hash of everything an env returns over whole episodes, to check that a speed change keeps the bits: two
episodes of 16 ``fls-circle`` envs (seed 3) and one episode of the 26 built-in contours side by side (seed
5), warpcut's recipe, random discrete actions from a seeded generator; every observation, reward and info
array (final observations and scores included). Run it before and after a change (e.g. in a worktree of the
commit before); equal hashes mean training and Table I are unchanged. Used in sessions 14 and 32
(docs/performance.md, section 6).

Run: python scripts/observation_hash.py
"""

from __future__ import annotations

import hashlib

import numpy as np


def episodes_hash(contour, num_envs: int, episodes: int, seed: int) -> str:
    """The first 16 hex digits of a SHA-256 over ``episodes`` whole episodes of a batched env."""
    from agents.config import RECIPE
    from envs.options import PatternCutOptions
    from envs.vector import PatternCutVecEnv

    env = PatternCutVecEnv(num_envs, PatternCutOptions(contour=contour, **RECIPE))
    digest = hashlib.sha256()
    obs, _ = env.reset(seed=seed)
    digest.update(obs.tobytes())
    rng = np.random.default_rng(seed)
    choices = int(env.single_action_space.n)
    while episodes:
        obs, reward, terminated, truncated, info = env.step(rng.integers(0, choices, num_envs))
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
    from warpcut.contours import builtin_names

    print("fls-circle x16, 2 episodes:", episodes_hash("fls-circle", 16, 2, 3))
    names = builtin_names()
    print(f"{len(names)} contours, 1 episode:", episodes_hash(names, len(names), 1, 5))


if __name__ == "__main__":
    main()
