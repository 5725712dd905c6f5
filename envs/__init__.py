"""Gymnasium environments and the rsl-rl adapter over warpcut's batched simulator.

Importing this package registers ``warpcut/PatternCut-v0``::

    import gymnasium as gym
    import envs  # noqa: F401  (or import warpcut.gym, or use the id "warpcut.gym:warpcut/PatternCut-v0")

    env = gym.make("warpcut/PatternCut-v0", contour="fls-circle", action_type="discrete")
    vec = gym.make_vec("warpcut/PatternCut-v0", num_envs=64, vectorization_mode="vector_entry_point")

Keyword arguments are the fields of :class:`PatternCutOptions`, plus ``render_mode`` (``"rgb_array"``,
``"human"``: :mod:`envs.pattern_cut`) and, for the vector env, ``autoreset_mode`` and ``render_envs``
(:mod:`envs.vector`). The rsl-rl adapter lives in :mod:`envs.rsl` (imported on demand: it pulls in torch).

Registration: importing this package runs :func:`register_envs`. A script whose own top-level ``envs``
package comes first on ``sys.path`` cannot ``import envs`` to get this one: it imports :mod:`warpcut.gym`
instead (or names it in the id, ``"warpcut.gym:warpcut/PatternCut-v0"``), which finds this package by
location, loads it under another name if need be (its modules import each other relatively for that), and
registers it. :mod:`warpcut.gym` is also the ``warpcut`` entry point of the ``gymnasium.envs`` group, which
Gymnasium 1.x no longer loads by itself (0.26 to 0.29 did). A script's own ``agents`` package does not get
in the way either.
"""

import gymnasium

from .core import PatternCut
from .options import PatternCutOptions
from .pattern_cut import PatternCutEnv
from .vector import PatternCutVecEnv

ENV_ID = "warpcut/PatternCut-v0"


def register_envs() -> None:
    """Register :data:`ENV_ID` with Gymnasium (once; importing this package does it). Also the
    ``gymnasium.envs`` entry point of the ``warpcut`` distribution, for tools that load that group.

    The entry points are the modules' full names (``envs.pattern_cut:PatternCutEnv``), as this package was
    imported, so ``gym.make`` and ``gym.make_vec`` build the envs from this package and no other.
    """
    if ENV_ID in gymnasium.registry:
        return
    gymnasium.register(
        id=ENV_ID,
        entry_point=f"{PatternCutEnv.__module__}:{PatternCutEnv.__qualname__}",
        vector_entry_point=f"{PatternCutVecEnv.__module__}:{PatternCutVecEnv.__qualname__}",
    )


register_envs()


def make(num_envs: int | None = None, **options) -> PatternCutEnv | PatternCutVecEnv:
    """One env (``num_envs=None``) or a natively batched vector env; keywords: :class:`PatternCutOptions`."""
    return PatternCutEnv(**options) if num_envs is None else PatternCutVecEnv(num_envs, **options)


__all__ = [
    "ENV_ID",
    "PatternCut",
    "PatternCutEnv",
    "PatternCutOptions",
    "PatternCutVecEnv",
    "make",
    "register_envs",
]
