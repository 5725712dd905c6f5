"""One sheet as a ``gymnasium.Env`` (:class:`PatternCutEnv`); the contract (observations, actions, rewards,
episodes) is :mod:`envs.core`'s, the natively batched env is :class:`envs.vector.PatternCutVecEnv`."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from envs.core import PatternCut, reject_reset_options
from envs.options import PatternCutOptions
from warpcut.task import CuttingTask


class PatternCutEnv(gym.Env):
    """One sheet being cut while the policy tensions it; see :mod:`envs.core` for the contract and
    :class:`PatternCutOptions` (every field is a keyword argument).

    Args:
        options: The scenario; keyword arguments replace its fields.
        render_mode: Must be ``None``: the env does not render.
    """

    metadata = {"render_modes": []}

    def __init__(
        self, options: PatternCutOptions | None = None, render_mode: str | None = None, **kwargs: Any
    ):
        if render_mode is not None:
            raise ValueError(f"render_mode: PatternCutEnv does not render (got {render_mode!r}); use None")
        self.options = PatternCutOptions.build(options, **kwargs)
        self.scene = PatternCut(self.options, num_envs=1)
        self.observation_space = self.scene.observation_space
        self.action_space = self.scene.action_space

    @property
    def task(self) -> CuttingTask:
        """The underlying one-env :class:`~warpcut.task.CuttingTask`."""
        return self.scene.task

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Settled, uncut sheet; the grasp at the pinch point. A ``seed`` also redraws the fiducials.
        There are no reset ``options``."""
        super().reset(seed=seed)
        reject_reset_options(options)
        obs = self.scene.reset(self.np_random, seed is not None or self.options.resample_fiducials)
        return obs[0], {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Move the grasp by ``action`` and advance the scissors one step (:mod:`envs.core`). A simulation
        that diverges ends the episode: ``terminated``, ``info["diverged"]`` True, a NaN score and a zero
        observation and reward."""
        obs, rewards, terminated, truncated, info = self.scene.step(np.asarray(action)[None])
        scalars = {k: bool(v[0]) if k == "diverged" else float(v[0]) for k, v in info.items()}
        return obs[0], float(rewards[0]), terminated, truncated, scalars
