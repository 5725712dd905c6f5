"""Stable-Baselines3 view of :class:`~envs.vector.PatternCutVecEnv`: SB3 trains on the whole Warp batch.

:class:`PatternCutSB3Env` is a ``stable_baselines3.common.vec_env.VecEnv`` over one natively batched env of
B sheets (no subprocesses, no per-env Python envs); :func:`make_sb3_env` builds one in a ``VecMonitor`` so
SB3's logger sees episode returns and lengths::

    from stable_baselines3 import PPO
    from envs.sb3 import make_sb3_env

    model = PPO("MlpPolicy", make_sb3_env(64, contour="fls-circle", device="cuda"), n_steps=80)
    model.learn(100_000)

Stable-Baselines3 is an optional dependency (``pip install 'warpcut[sb3]'``): ``import envs`` never needs it,
importing this module does.

Spaces are one env's (SB3's convention): ``Discrete(5)`` (7 with ``allow_z``) indices, shape (B,), or
``Box(-1, 1, (A,))`` moves, shape (B, A), for ``action_type="continuous"``. ``reset()`` returns (B, D)
float32 observations; ``step_wait()`` returns ``(observations, rewards (B,) float32, dones (B,) bool, infos)``
with ``infos`` a list of B dicts.

Autoreset (SB3's): an env whose episode ended is already reset in that ``step_wait``; its observation is the
new episode's first and its info holds ``"terminal_observation"`` (the ending step's observation) and
``"TimeLimit.truncated"`` (in every step's info, as ``DummyVecEnv`` gives it: True only when
``max_episode_steps`` cut the episode short; a completed cut is a true terminal state, so SB3 bootstraps only
past truncations). All B envs share one episode clock (:mod:`envs.vector`), so every episode ends on the same
step, except that an env whose simulation diverges ends at that step (``dones[i]`` True, its zero observation
as ``terminal_observation``, ``"diverged"`` True) and then idles until the batch's episode ends: zero
observations and rewards, its actions ignored. That idle stretch shows up as a short episode of its own which
ends, ``TimeLimit.truncated`` False (nothing to bootstrap: it earns nothing), with the others.

Info keys, as a ``DummyVecEnv`` of :class:`~envs.pattern_cut.PatternCutEnv` would give them (Python
scalars): every step ``cut_deviation_mm`` and ``running_path_error_mm2``, and ``diverged`` (for every env)
once an env of the batch has diverged; at a completed cut also the score (``relative_error``,
``error_mm2``, ``error_vertices``, ... of :meth:`warpcut.scoring.Score.info`; ``relative_error`` is minus
the final reward), NaN for an env that diverged on that last step.

Seeding: the batch takes one seed. ``seed(s)`` (what ``model.set_random_seed`` and SB3's ``seed=`` call)
seeds the next ``reset()`` with ``s``, env 0's seed in SB3's per-env list; the fiducials and process noise
still differ from env to env.

Rendering: build the batched env with ``render_mode="rgb_array"`` (``make_sb3_env(B,
render_mode="rgb_array", render_envs=4)``); ``render()`` then returns SB3's tiling of its first
``render_envs`` images (e.g. for ``VecVideoRecorder``). Without it, ``render_mode`` is None and nothing is
drawn.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode

try:
    from stable_baselines3.common.vec_env import VecEnv, VecMonitor
    from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices
except ImportError as error:  # pragma: no cover - exercised only without the extra
    raise ImportError(
        "envs.sb3 needs Stable-Baselines3; install it with pip install 'warpcut[sb3]' "
        "(or pip install 'stable-baselines3>=2.3')"
    ) from error

from .options import PatternCutOptions
from .vector import PatternCutVecEnv

STEP_KEYS = ("cut_deviation_mm", "running_path_error_mm2", "diverged")
"""The per-step info keys of :class:`~envs.vector.PatternCutVecEnv` copied into every env's info."""


class PatternCutSB3Env(VecEnv):
    """Adapter from a :class:`~envs.vector.PatternCutVecEnv` to Stable-Baselines3's ``VecEnv``.

    Args:
        env: The batched env (any action type), built with ``autoreset_mode=AutoresetMode.SAME_STEP`` (not
            its default; :func:`make_sb3_env` does). It is reset by the first :meth:`reset` (SB3's ``learn``
            does that).

    ``get_attr`` reads an attribute of the one batched env (the same value for every index);
    ``set_attr`` and ``env_method`` act on it once and so take no index subset (``indices=None``, or all
    B). ``env_is_wrapped`` is False: there are no per-env gymnasium wrappers.
    """

    def __init__(self, env: PatternCutVecEnv):
        if not isinstance(env, PatternCutVecEnv):
            raise ValueError(
                f"env: expected an envs.PatternCutVecEnv (got {type(env).__name__}); use envs.sb3."
                "make_sb3_env, or build one with envs.PatternCutVecEnv(B, autoreset_mode='same_step', ...)"
            )
        mode = env.metadata.get("autoreset_mode")
        if mode is not AutoresetMode.SAME_STEP:
            raise ValueError(
                "env: SB3 resets envs inside step, so the batched env needs "
                f"autoreset_mode=AutoresetMode.SAME_STEP; build it so, or use make_sb3_env (got {mode!r})"
            )
        self.env = env
        super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)
        self._actions: np.ndarray | None = None

    @property
    def options(self) -> PatternCutOptions:
        """The batched env's scenario."""
        return self.env.options

    def reset(self) -> np.ndarray:
        """Reset every env, with the seed and options of the last ``seed()`` / ``set_options()`` if any."""
        seed = self._seeds[0]
        # The first env's non-empty options, used once; the batched env refuses unknown ones (ValueError).
        options = next((o for o in self._options if o), None)
        self._reset_seeds()
        self._reset_options()
        obs, _ = self.env.reset(seed=seed, options=options)
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._actions = None
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        """Store ``actions``: (B,) indices (discrete) or (B, A) moves (continuous)."""
        self._actions = np.asarray(actions)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        """Step every env; reset those whose episode ended and report them (module docstring)."""
        if self._actions is None:
            raise RuntimeError("step_wait: call step_async(actions) first")
        actions, self._actions = self._actions, None
        obs, rewards, terminated, truncated, info = self.env.step(actions)
        dones = terminated | truncated
        return obs, rewards.astype(np.float32), dones, self._infos(obs, terminated, truncated, info)

    def _infos(
        self, obs: np.ndarray, terminated: np.ndarray, truncated: np.ndarray, info: dict[str, Any]
    ) -> list[dict[str, Any]]:
        """One SB3 info dict per env from the vector env's dict of (B,) arrays."""
        columns = {k: info[k].tolist() for k in STEP_KEYS if k in info}
        columns["TimeLimit.truncated"] = (truncated & ~terminated).tolist()
        infos = [{k: column[i] for k, column in columns.items()} for i in range(self.num_envs)]
        ended = np.flatnonzero(terminated | truncated)
        if not ended.size:
            return infos
        reported = info.get("_final_obs", np.zeros(self.num_envs, dtype=bool))
        final_info = info.get("final_info", {})
        finals = {k: v.tolist() for k, v in final_info.items() if not k.startswith("_")}
        for i in ended:
            env_info = infos[i]
            if reported[i]:
                env_info["terminal_observation"] = info["final_obs"][i]
                env_info.update({k: v[i] for k, v in finals.items() if final_info[f"_{k}"][i]})
            else:  # diverged earlier and idled since (zero observations): nothing to bootstrap
                env_info["terminal_observation"] = np.zeros_like(obs[i])
                env_info["TimeLimit.truncated"] = False
        return infos

    def close(self) -> None:
        self.env.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        """The batched env's images (``render_mode="rgb_array"``): its first ``render_envs`` envs, each
        (H, W, 3) uint8; SB3's ``render()`` tiles them. Without a render mode, a warning and Nones."""
        if self.render_mode != "rgb_array":
            warnings.warn(
                "get_images: the batched env was made without render_mode='rgb_array'; build it with "
                "make_sb3_env(..., render_mode='rgb_array')",
                stacklevel=2,
            )
            return [None] * self.num_envs
        return list(self.env.render())

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The batched env's attribute ``attr_name``, once per index (``AttributeError`` if it has none)."""
        value = getattr(self.env, attr_name)
        return [value] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set ``attr_name`` on the batched env (all envs at once)."""
        self._whole_batch("set_attr", indices)
        setattr(self.env, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        """Call the batched env's method once; its result is repeated for every env."""
        self._whole_batch("env_method", indices)
        result = getattr(self.env, method_name)(*method_args, **method_kwargs)
        return [result] * self.num_envs

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        """False for every env: the batch has no per-env gymnasium wrappers."""
        return [False] * len(self._get_indices(indices))

    def _whole_batch(self, what: str, indices: VecEnvIndices) -> None:
        """Raise ``ValueError`` unless ``indices`` covers every env."""
        chosen = sorted({int(i) for i in self._get_indices(indices)})
        if chosen != list(range(self.num_envs)):
            raise ValueError(
                f"indices: the {self.num_envs} envs are one batched PatternCutVecEnv, so {what} acts on all "
                f"of them; pass indices=None (got {chosen})"
            )


def make_sb3_env(
    num_envs: int,
    options: PatternCutOptions | None = None,
    monitor: bool = True,
    torch_threads: int | None = 1,
    **kwargs: Any,
) -> VecEnv:
    """A :class:`PatternCutSB3Env` of ``num_envs`` sheets, in a ``VecMonitor`` unless ``monitor`` is False.

    Args:
        num_envs: Batch size B.
        options: The scenario; keyword arguments (any :class:`~envs.options.PatternCutOptions` field, or
            :class:`~envs.vector.PatternCutVecEnv`'s ``render_mode``, ``render_envs``, ...) replace its
            fields.
        monitor: Wrap in ``VecMonitor`` (``info["episode"]``: SB3's ``ep_rew_mean`` / ``ep_len_mean``).
        torch_threads: Where the simulator runs on the CPU, set torch to this many threads
            (``torch.set_num_threads``; None: leave torch as it is). The simulator steps the batch on
            threads of its own, and torch's threads spinning beside them made SB3's PPO about ten times
            slower on a 2-core machine (``python scripts/sb3_throughput.py``); SB3's small MLPs gain nothing
            from more threads.
    """
    if not isinstance(num_envs, int | np.integer) or isinstance(num_envs, bool) or num_envs < 1:
        raise ValueError(f"num_envs: must be an integer >= 1 (got {num_envs!r})")
    kwargs.setdefault("autoreset_mode", AutoresetMode.SAME_STEP)  # SB3 resets inside step
    env = PatternCutSB3Env(PatternCutVecEnv(int(num_envs), options, **kwargs))
    if torch_threads is not None and str(env.env.task.sim.device).startswith("cpu"):
        import torch

        torch.set_num_threads(int(torch_threads))
    return VecMonitor(env) if monitor else env


__all__ = ["STEP_KEYS", "PatternCutSB3Env", "make_sb3_env"]
