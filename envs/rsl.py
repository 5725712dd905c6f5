"""rsl-rl (5.5.1) view of :class:`~envs.vector.PatternCutVecEnv`: torch tensors, resets inside ``step``.

Observations are a ``TensorDict`` with one group, ``"policy"`` (B, D) float32; configure the runner with
``obs_groups={"actor": ["policy"], "critic": ["policy"]}``.

Actions, a tensor on any device:
    * discrete: choice indices, shape (B,) or (B, 1), of any dtype holding integers in
      ``[0, num_choices)`` -- what ``agents.ppo.distributions.Categorical`` samples (floats of shape
      ``(B, num_actions)`` with ``num_actions == 1``). Set its ``num_choices`` to :attr:`num_action_choices`.
    * continuous: (B, num_actions) moves in units of ``max_step_mm``, clipped to [-1, 1].

``step`` returns ``dones`` (B,) long, 1 where an episode ended (all envs together: they share one clock)
and the env has already reset. ``extras["time_outs"]`` (B,) bool is True only where the episode was cut
short by ``max_episode_steps``: a completed cut is a true terminal state (its reward is final), so PPO must
not bootstrap past it, nor past an env that diverged (it ended when it diverged, and idled since). On the
step where cuts complete, ``extras["log"]`` holds one value per env of ``Episode/final_error``
(:data:`FINAL_ERROR_KEY`: ``error_mm2 / area_mm2``, minus the final reward), ``Cut/error_mm2`` and
``Cut/error_vertices``; rsl-rl's logger records their means under those names. The key is absent on other
steps (and after truncated episodes, which have no score). On the step where the batch's episode ends,
``extras["episode_cost"]`` (:data:`EPISODE_COST_KEY`) holds every env's cost of the cut that ended, (B,)
float: its path error over the intended area, weighed as its reward is weighed (``relative_reward``), NaN
where the env diverged or the episode was cut short (es ranks its policies by it).

Training can restart the current episode exactly as it began (:meth:`PatternCutRslEnv.episode_start`,
:meth:`PatternCutRslEnv.restart_episode`): a resumed run continues the episodes' stream where it stopped.
"""

from __future__ import annotations

import numpy as np
import torch
from gymnasium.vector import AutoresetMode
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from .options import PatternCutOptions
from .vector import PatternCutVecEnv

FINAL_ERROR_KEY = "Episode/final_error"
"""``extras["log"]`` key of each completed cut's relative error (the name ``agents.training`` reads)."""

EPISODE_COST_KEY = "episode_cost"
"""``extras`` key of every env's cost of the cut that ended this step (module docstring)."""


class PatternCutRslEnv(VecEnv):
    """Adapter from a :class:`~envs.vector.PatternCutVecEnv` to ``rsl_rl.env.VecEnv``.

    Args:
        env: The batched env (any action type), built with ``autoreset_mode=AutoresetMode.SAME_STEP`` (not
            its default): rsl-rl expects resets inside ``step``. It is reset here.
        torch_device: Torch device of the returned tensors (the simulator's Warp device is
            ``env.options.device``).
        seed: Seed of the first reset.

    Attributes:
        num_envs: Batch size B.
        num_actions: 1 for discrete actions (one index per env), else the action dimension.
        num_action_choices: Number of discrete actions (5, or 7 with ``allow_z``); ``None`` for continuous.
        device: Torch device of observations, rewards, dones and extras (rsl-rl's name for it).
        cfg: The env's :class:`~envs.options.PatternCutOptions` (``to_dict()`` for loggers).
    """

    def __init__(self, env: PatternCutVecEnv, torch_device: str | torch.device = "cpu", seed: int | None = 0):
        if not isinstance(env, PatternCutVecEnv):
            raise ValueError(f"env: expected an envs.PatternCutVecEnv (got {type(env).__name__})")
        if env.autoreset_mode is not AutoresetMode.SAME_STEP:
            raise ValueError(
                "env: rsl-rl resets envs inside step, so the batched env needs "
                f"autoreset_mode=AutoresetMode.SAME_STEP; build it with that (got {env.autoreset_mode!r})"
            )
        self.env = env
        self.device = torch.device(torch_device)
        self.cfg: PatternCutOptions = env.options
        self.num_envs = env.num_envs
        space = env.single_action_space
        discrete = env.options.action_type == "discrete"
        self.num_action_choices: int | None = int(space.n) if discrete else None
        self.num_actions = 1 if discrete else int(space.shape[0])
        self.seed(seed)

    @property
    def max_episode_length(self) -> int:
        """Steps per episode (the same for every env; with domain randomisation, this episode's)."""
        return self.env.scene.episode_steps

    def seed(self, seed: int | None) -> None:
        """Reseed the env's randomness (noise, fiducials) and reset every env."""
        obs, _ = self.env.reset(seed=seed)
        self._obs = self._tensordict(obs)

    @property
    def episode_length_buf(self) -> torch.Tensor:
        """(B,) long: steps taken in the current episode, the same for every env."""
        return torch.full((self.num_envs,), self.env.scene.step_index, dtype=torch.long, device=self.device)

    @episode_length_buf.setter
    def episode_length_buf(self, value: torch.Tensor) -> None:
        raise ValueError(
            "episode_length_buf: the pattern-cutting envs share one episode clock and cannot start at random "
            "episode lengths; train with init_at_random_ep_len=False"
        )

    @property
    def common_sheets(self) -> int:
        """With randomised parameters, the batch is this many copies of ``num_envs / common_sheets`` sheets
        (env ``e`` cuts sheet ``e % (num_envs / common_sheets)``: es's perturbed policies cut the same
        sheets); 1: every env its own sheet. Takes effect at the next reset."""
        return self.env.common_sheets

    @common_sheets.setter
    def common_sheets(self, copies: int) -> None:
        self.env.common_sheets = copies

    def episode_start(self) -> dict:
        """What :meth:`restart_episode` needs to start the current episode again as it began (the random
        stream's state before its reset)."""
        return self.env.episode_start()

    def restart_episode(self, start: dict) -> None:
        """Start the episode that :meth:`episode_start` described again, in every env, as it began: the same
        process noise, fiducials and randomised sheets (for the same options and seed of the first reset)."""
        self._obs = self._tensordict(self.env.restart_episode(start))

    def get_observations(self) -> TensorDict:
        """The current observations, ``{"policy": (B, D) float32}``."""
        return self._obs

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """Apply ``actions`` (module docstring); reset every env in the same call when the episode ends.

        Returns:
            ``(observations, rewards (B,) float32, dones (B,) long, extras)``.
        """
        actions = actions.detach().cpu().numpy()
        if self.num_action_choices is not None and actions.ndim == 2 and actions.shape[1] == 1:
            actions = actions[:, 0]
        scale = self.env.scene.reward_scale  # this episode's (the env resets inside the step that ends it)
        obs, rewards, terminated, truncated, info = self.env.step(actions)
        self._obs = self._tensordict(obs)
        extras: dict = {"time_outs": torch.as_tensor(truncated, device=self.device)}
        score = info.get("final_info", {})
        if np.all(terminated | truncated):  # the batch's episode ended (all envs share one clock)
            costs = score.get("relative_error", np.full(self.num_envs, np.nan)) * scale
            extras[EPISODE_COST_KEY] = torch.as_tensor(costs, dtype=torch.float64, device=self.device)
        scored = np.isfinite(score["relative_error"]) if "relative_error" in score else None
        if scored is not None and scored.any():  # a diverged env's NaN score is never averaged in
            extras["log"] = {
                FINAL_ERROR_KEY: self._tensor(score["relative_error"][scored]),
                "Cut/error_mm2": self._tensor(score["error_mm2"][scored]),
                "Cut/error_vertices": self._tensor(score["error_vertices"][scored]),
            }
        dones = torch.as_tensor(terminated | truncated, device=self.device).long()
        return self._obs, self._tensor(rewards), dones, extras

    def _tensor(self, values: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(values, dtype=torch.float32, device=self.device)

    def _tensordict(self, obs: np.ndarray) -> TensorDict:
        policy = torch.as_tensor(obs, device=self.device)
        return TensorDict({"policy": policy}, batch_size=[self.num_envs], device=self.device)
