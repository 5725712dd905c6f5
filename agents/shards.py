"""A training batch split over Ray actors (:class:`ShardedEnv`): each actor steps a part of the envs
(:class:`envs.core.PatternCut`'s ``part``: the same noise, fiducials and randomised sheets as those envs of
the whole batch), and the learner in this process sees the one batch, observation for observation, as a
:class:`envs.rsl.PatternCutRslEnv` of all of them would give it. ``warpcut generalist --ray`` trains on it:
es's perturbed policies, each cutting every training contour, are spread over the workers, a whole number
of policies each.

An actor that dies is made again and brought to where it was: its episode restarted as it began and this
episode's moves played again (the env is deterministic), so the run goes on as if it had not died.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from agents.cluster import RETRIES, UNIT_CPUS, RayCluster, ran_here
from envs.options import PatternCutOptions


class EnvShard:
    """A Ray actor holding envs ``first .. first + count - 1`` of a batch of ``total`` (``options``: theirs,
    :meth:`~envs.options.PatternCutOptions.part`), as a :class:`envs.rsl.PatternCutRslEnv` on the CPU."""

    def __init__(self, options: PatternCutOptions, first: int, count: int, total: int, seed: int | None):
        from envs.rsl import PatternCutRslEnv
        from envs.vector import PatternCutVecEnv

        torch.set_num_threads(UNIT_CPUS)
        batch = PatternCutVecEnv(count, options, autoreset_mode="same_step", part=(first, total))
        self.env = PatternCutRslEnv(batch, torch_device="cpu", seed=seed)

    def describe(self) -> dict:
        env = self.env
        return {
            "max_episode_length": env.max_episode_length,
            "num_actions": env.num_actions,
            "num_action_choices": env.num_action_choices,
            "start": env.episode_start(),
            "ran_on": ran_here(),
        }

    def observations(self) -> torch.Tensor:
        return self.env.get_observations()["policy"]

    def set_common_sheets(self, copies: int) -> None:
        self.env.common_sheets = copies

    def seed(self, seed: int | None) -> tuple[torch.Tensor, dict]:
        self.env.seed(seed)
        return self.observations(), self.env.episode_start()

    def restart(self, start: dict) -> torch.Tensor:
        self.env.restart_episode(start)
        return self.observations()

    def step(self, actions: torch.Tensor) -> tuple:
        """:meth:`PatternCutRslEnv.step`'s results, and the new episode's start where this step ended one."""
        from envs.rsl import EPISODE_COST_KEY

        obs, rewards, dones, extras = self.env.step(actions)
        start = self.env.episode_start() if EPISODE_COST_KEY in extras else None
        return obs["policy"], rewards, dones, extras, start


class ShardedEnv(VecEnv):
    """``num_envs`` envs of ``options`` split over actors of ``cluster`` (module docstring), in groups of
    ``group`` consecutive envs that stay together (es: one perturbed policy's envs); rsl-rl's ``VecEnv``
    as :func:`agents.training.train` uses it.

    Args:
        options: The whole batch's scenario (per-env contours, pinch points, segments).
        num_envs: Batch size B, a multiple of ``group``.
        cluster: The Ray cluster; one actor per worker, at most one per group.
        group: Envs that one actor keeps together.
        torch_device: Torch device of the tensors returned.
        seed: Seed of the first reset (as :class:`envs.rsl.PatternCutRslEnv`'s).
    """

    def __init__(
        self,
        options: PatternCutOptions,
        num_envs: int,
        cluster: RayCluster,
        group: int = 1,
        torch_device: str = "cpu",
        seed: int | None = 0,
    ):
        if group < 1 or num_envs % group:
            raise ValueError(f"group: {group} must divide the {num_envs} envs")
        self.ray = cluster.ray
        self.num_envs, self.cfg, self.device = num_envs, options, torch.device(torch_device)
        groups = np.array_split(np.arange(num_envs // group), min(cluster.workers, num_envs // group))
        self.parts = [(int(g[0]) * group, len(g) * group) for g in groups]
        self._options = [options.part(first, count, num_envs) for first, count in self.parts]
        gpus = (
            1 if str(options.device or "").startswith("cuda") else 0
        )  # an actor steps where the batch would
        self._actor = self.ray.remote(num_cpus=UNIT_CPUS, num_gpus=gpus)(EnvShard)
        self._seed, self._common = seed, 1
        self.shards = [self._make(k) for k in range(len(self.parts))]
        described = self.ray.get([s.describe.remote() for s in self.shards])
        lengths = {d["max_episode_length"] for d in described}
        if len(lengths) != 1:
            raise ValueError(
                f"the parts' episodes differ in length ({sorted(lengths)} steps): give each part whole "
                "groups of the batch's contours (group)"
            )
        first = described[0]
        self.max_episode_length = first["max_episode_length"]
        self.num_actions, self.num_action_choices = first["num_actions"], first["num_action_choices"]
        self.ran_on = [d["ran_on"] for d in described]
        self._start, self._moves, self._step_index = first["start"], [], 0
        self._obs = self._tensordict(torch.cat(self.ray.get([s.observations.remote() for s in self.shards])))
        self.revived = 0

    def _make(self, k: int):
        first, count = self.parts[k]
        return self._actor.remote(self._options[k], first, count, self.num_envs, self._seed)

    def _revive(self, k: int) -> None:
        """Make shard ``k``'s actor again and bring it to this step: its episode restarted as it began, this
        episode's moves played again."""
        if self.revived >= RETRIES * len(self.shards):
            raise ValueError(f"--ray: the env actors died {self.revived} times; see the worker logs for why")
        self.revived += 1
        shard = self._make(k)
        self.ray.get(shard.set_common_sheets.remote(self._common))
        self.ray.get(shard.restart.remote(self._start))
        for moves in self._moves:
            self.ray.get(shard.step.remote(moves[k]))
        self.shards[k] = shard

    def _all(self, call: str, args: Sequence[tuple] | None = None) -> list:
        """``call`` on every shard (shard k with ``args[k]``), reviving one that died."""
        from ray.exceptions import RayActorError

        args = args or [()] * len(self.shards)
        refs = [getattr(s, call).remote(*a) for s, a in zip(self.shards, args, strict=True)]
        out = []
        for k, ref in enumerate(refs):
            try:
                out.append(self.ray.get(ref))
            except RayActorError:
                self._revive(k)
                out.append(self.ray.get(getattr(self.shards[k], call).remote(*args[k])))
        return out

    # rsl-rl's VecEnv, as agents.training uses it ---------------------------------------------------------

    @property
    def episode_length_buf(self) -> torch.Tensor:
        return torch.full((self.num_envs,), self._step_index, dtype=torch.long, device=self.device)

    @episode_length_buf.setter
    def episode_length_buf(self, value: torch.Tensor) -> None:
        raise ValueError(
            "episode_length_buf: the envs share one episode clock; train with init_at_random_ep_len=False"
        )

    @property
    def common_sheets(self) -> int:
        return self._common

    @common_sheets.setter
    def common_sheets(self, copies: int) -> None:
        self._common = int(copies)
        self._all("set_common_sheets", [(copies,)] * len(self.shards))

    def seed(self, seed: int | None) -> None:
        self._seed = seed
        parts = self._all("seed", [(seed,)] * len(self.shards))
        self._begin(parts[0][1])
        self._obs = self._tensordict(torch.cat([obs for obs, _ in parts]))

    def episode_start(self) -> dict:
        return dict(self._start)

    def restart_episode(self, start: dict) -> None:
        self._begin(start)
        self._obs = self._tensordict(torch.cat(self._all("restart", [(start,)] * len(self.shards))))

    def get_observations(self) -> TensorDict:
        return self._obs

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        from envs.rsl import EPISODE_COST_KEY

        moves = [actions[first : first + count].detach().cpu().clone() for first, count in self.parts]
        parts = self._all("step", [(m,) for m in moves])
        self._moves.append(moves)
        ended = [extras.get(EPISODE_COST_KEY) is not None for _, _, _, extras, _ in parts]
        if any(ended) and not all(ended):
            raise ValueError(
                "a part of the batch ended its episode alone (every env of it diverged); lower the noise, or "
                "train without --ray"
            )
        extras: dict[str, Any] = {"time_outs": torch.cat([p[3]["time_outs"] for p in parts]).to(self.device)}
        if all(ended):
            extras[EPISODE_COST_KEY] = torch.cat([p[3][EPISODE_COST_KEY] for p in parts]).to(self.device)
            self._begin(parts[0][4])
        else:
            self._step_index += 1
        logs = [p[3]["log"] for p in parts if "log" in p[3]]
        if logs:  # each part's scored envs, in order: the whole batch's
            extras["log"] = {key: torch.cat([log[key] for log in logs]).to(self.device) for key in logs[0]}
        self._obs = self._tensordict(torch.cat([p[0] for p in parts]))
        rewards = torch.cat([p[1] for p in parts]).to(self.device)
        return self._obs, rewards, torch.cat([p[2] for p in parts]).to(self.device), extras

    def close(self) -> None:
        for shard in self.shards:
            self.ray.kill(shard)

    def _begin(self, start: dict) -> None:
        self._start, self._moves, self._step_index = dict(start), [], 0

    def _tensordict(self, obs: torch.Tensor) -> TensorDict:
        obs = obs.to(self.device)
        return TensorDict({"policy": obs}, batch_size=[self.num_envs], device=self.device)
