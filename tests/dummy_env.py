"""A tiny rsl-rl env with the same contract as ``envs.rsl``: reach a target on a line in a fixed time.

Each env holds a gripper at 0 and a target ``d`` in {-reach, ..., reach}. Every step moves the gripper by
-1, 0 or +1 (discrete: choice index 0, 1, 2) or by the action clipped to [-1, 1] (continuous). After
``horizon`` steps the episode ends with the only reward, ``-|d - x| / reach``, and a fresh target. A random
discrete policy ends about 2 away from the target; a good one ends on it. Every env's episode ends on the same
step (one clock, as warpcut's envs share one), where ``extras["episode_cost"]`` holds each env's final error
over ``reach``: what es ranks its policies by.
"""

from __future__ import annotations

import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

FINAL_ERROR_KEY = "Episode/final_error"
EPISODE_COST_KEY = "episode_cost"


class ReachEnv(VecEnv):
    """Batched 1D reach task with a sparse final reward.

    Attributes:
        num_action_choices: Choices per action (steps -1, 0, +1) when ``discrete``, else None (continuous
            moves: the learner reads the action type from it).
        step_calls: Number of :meth:`step` calls so far.
        interrupt_after: Raise ``KeyboardInterrupt`` on this :meth:`step` call, like a Ctrl-C mid-rollout.
    """

    def __init__(
        self, num_envs: int = 16, discrete: bool = True, horizon: int = 6, reach: int = 4, seed: int = 0
    ) -> None:
        self.num_envs = num_envs
        self.num_actions = 1
        self.num_action_choices: int | None = 3 if discrete else None
        self.max_episode_length = horizon
        self.device = "cpu"
        self.cfg = {"discrete": discrete, "horizon": horizon, "reach": reach}
        self.discrete = discrete
        self.reach = reach
        self.step_calls = 0
        self.interrupt_after: int | None = None
        self.seed(seed)

    def seed(self, seed: int) -> None:
        """Reseed the target generator and reset every env."""
        self.generator = torch.Generator().manual_seed(seed)
        self.episode_length_buf = torch.zeros(self.num_envs, dtype=torch.long)
        self.position = torch.zeros(self.num_envs)
        self.target = self._sample_targets(self.num_envs)

    def get_observations(self) -> TensorDict:
        steps_left = 1.0 - self.episode_length_buf / self.max_episode_length
        policy = torch.stack([(self.target - self.position) / self.reach, steps_left], dim=-1)
        return TensorDict({"policy": policy}, batch_size=[self.num_envs])

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        self.step_calls += 1
        if self.step_calls == self.interrupt_after:
            raise KeyboardInterrupt
        if self.discrete:
            move = actions[:, 0].long().float() - 1.0
        else:
            move = actions[:, 0].clamp(-1.0, 1.0)
        self.position += move
        self.episode_length_buf += 1

        dones = self.episode_length_buf >= self.max_episode_length
        final_error = (self.target - self.position).abs()
        rewards = torch.where(dones, -final_error / self.reach, torch.zeros_like(final_error))
        extras = {"time_outs": torch.zeros_like(dones), "log": {}}
        if dones.any():
            extras["log"][FINAL_ERROR_KEY] = final_error[dones]
            if dones.all():
                extras[EPISODE_COST_KEY] = (final_error / self.reach).double()
            self._reset(dones)
        return self.get_observations(), rewards, dones.long(), extras

    def _reset(self, envs: torch.Tensor) -> None:
        self.episode_length_buf[envs] = 0
        self.position[envs] = 0.0
        self.target[envs] = self._sample_targets(int(envs.sum()))

    def _sample_targets(self, n: int) -> torch.Tensor:
        return torch.randint(-self.reach, self.reach + 1, (n,), generator=self.generator).float()
