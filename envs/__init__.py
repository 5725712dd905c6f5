"""Gymnasium environments and the rsl-rl adapter over warpcut's batched simulator.

Importing this package registers ``warpcut/PatternCut-v0``::

    import gymnasium as gym
    import envs  # noqa: F401  (or use the id "envs:warpcut/PatternCut-v0")

    env = gym.make("warpcut/PatternCut-v0", contour="fls-circle", action_type="discrete")
    vec = gym.make_vec("warpcut/PatternCut-v0", num_envs=64, vectorization_mode="vector_entry_point")

Keyword arguments are the fields of :class:`PatternCutOptions`. The rsl-rl adapter lives in
:mod:`envs.rsl` (imported on demand: it pulls in torch).
"""

import gymnasium

from envs.core import PatternCut
from envs.options import PatternCutOptions
from envs.pattern_cut import PatternCutEnv
from envs.vector import PatternCutVecEnv

ENV_ID = "warpcut/PatternCut-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        id=ENV_ID,
        entry_point="envs.pattern_cut:PatternCutEnv",
        vector_entry_point="envs.vector:PatternCutVecEnv",
    )


def make(num_envs: int | None = None, **options) -> PatternCutEnv | PatternCutVecEnv:
    """One env (``num_envs=None``) or a natively batched vector env; keywords: :class:`PatternCutOptions`."""
    return PatternCutEnv(**options) if num_envs is None else PatternCutVecEnv(num_envs, **options)


__all__ = ["ENV_ID", "PatternCut", "PatternCutEnv", "PatternCutOptions", "PatternCutVecEnv", "make"]
