"""The pattern-cutting env natively batched: one :class:`~warpcut.task.CuttingTask` of B sheets.

Autoreset is ``AutoresetMode.SAME_STEP``. All B envs share one episode clock, so every episode ends on
the same step; the env then resets all of them at once inside that ``step`` and returns the new
episodes' first observations. Following the Gymnasium spec for same-step autoreset
(https://farama.org/Vector-Autoreset-Mode), the ending step's observations and score are in
``info["final_obs"]`` (an object array of B observations) and ``info["final_info"]`` (a dict of (B,)
arrays), each with its ``"_final_obs"`` / ``"_final_info"`` mask (all True). Every step's info also has
the per-step ``cut_deviation_mm`` and ``running_path_error_mm2`` of :mod:`envs.core` (of the
episode that the step ended, where it ended one), with their masks. Same-step rather than
next-step because a next-step reset would spend a whole ``step`` call of B envs ignoring their actions
after every episode, and because rsl-rl (:mod:`envs.rsl`) expects resets inside ``step``.

An env whose simulation diverges (:mod:`envs.core`, "Divergence") is terminated at that step on its own:
``terminated[env]`` is True, ``info["final_obs"][env]`` is its (zero) observation and ``info["final_info"]``
holds ``diverged`` (with ``_final_info``, ``_final_obs`` and ``_diverged`` True for the envs that ended
there); it has no score. It cannot restart before the others (one clock), so until the batch's episode ends
it idles: zero observations, zero rewards, its actions ignored; at the batch's end it is reset with the
others, its ``terminated`` True but its ``_final_obs`` and ``_final_info`` False (nothing more to report).
Every step's info has ``diverged`` (with its mask) once an env has diverged.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from envs.core import PatternCut, reject_reset_options
from envs.options import PatternCutOptions
from warpcut.task import CuttingTask


class PatternCutVecEnv(VectorEnv):
    """B sheets cut at once (see :mod:`envs.core` for observations, actions and rewards).

    Args:
        num_envs: Batch size B.
        options: The scenario; keyword arguments (any :class:`~envs.options.PatternCutOptions` field)
            replace its fields. Per-env lists (contours, physical parameters, pinch points) have length B.

    ``reset(seed=...)`` takes one int (not a list): it seeds the process noise and the fiducials of all
    envs, which differ from env to env. Actions are (B,) indices (discrete) or (B, A) moves (continuous).
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 1, options: PatternCutOptions | None = None, **kwargs: Any):
        self.options = PatternCutOptions.build(options, **kwargs)
        self.num_envs = num_envs
        self.scene = PatternCut(self.options, num_envs)
        self.single_observation_space = self.scene.observation_space
        self.single_action_space = self.scene.action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._started = False
        self._ended = np.zeros(num_envs, dtype=bool)

    @property
    def task(self) -> CuttingTask:
        """The underlying :class:`~warpcut.task.CuttingTask` of B envs."""
        return self.scene.task

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every env; a ``seed`` also redraws the fiducials. There are no reset ``options``."""
        if seed is not None and not isinstance(seed, int | np.integer):
            raise TypeError(f"reset: seed must be one int for the whole batch (got {type(seed).__name__})")
        super().reset(seed=None if seed is None else int(seed))
        reject_reset_options(options)
        self._started = True
        self._ended[:] = False
        return self.scene.reset(self.np_random, seed is not None or self.options.resample_fiducials), {}

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every env; at the episode's end, reset them all in the same call (module docstring)."""
        if not self._started:
            raise RuntimeError("step: call reset() first")
        obs, rewards, terminated, truncated, info = self.scene.step(actions)
        b = self.num_envs
        every_env = np.ones(b, dtype=bool)
        step_keys = [k for k in ("cut_deviation_mm", "running_path_error_mm2", "diverged") if k in info]
        infos: dict[str, Any] = {k: info[k] for k in step_keys}
        infos.update({f"_{k}": every_env for k in step_keys})
        ended = np.full(b, terminated)
        if terminated or truncated:
            ending = ~self._ended  # envs that ended earlier (diverged) have nothing more to report
            final_info = {**info, **{f"_{k}": ending.copy() for k in info}}
            infos |= self._final(obs, ending, final_info)
            obs = self.scene.reset(self.np_random, self.options.resample_fiducials)
            self._ended[:] = False
        elif self.scene.newly_diverged.any():
            newly = self.scene.newly_diverged.copy()
            ended |= newly
            self._ended |= newly
            infos |= self._final(obs, newly, {"diverged": info["diverged"], "_diverged": newly.copy()})
        return obs, rewards, ended, np.full(b, truncated), infos

    @staticmethod
    def _final(obs: np.ndarray, ending: np.ndarray, final_info: dict[str, Any]) -> dict[str, Any]:
        """The same-step autoreset entries of the envs ``ending`` (B,) bool (module docstring)."""
        final_obs = np.empty(len(obs), dtype=object)
        for env in range(len(obs)):
            final_obs[env] = obs[env]
        return {
            "final_obs": final_obs,
            "_final_obs": ending.copy(),
            "final_info": final_info,
            "_final_info": ending.copy(),
        }
