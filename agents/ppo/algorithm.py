"""PPO: rsl-rl's PPO with warpcut's changes for speed on a CPU (its ``class_name`` in the runner's config is
``agents.ppo.algorithm:PPO``).

Each change computes what rsl-rl computes:

- **Adam, fused** (``torch.optim.Adam(fused=True)``): one kernel per step instead of ~12 ops per tensor (not
  bit-identical to the unfused step: last-bit differences).
- **Minibatches gathered with ``index_select``**: rsl-rl's generator indexes every stored field with a
  tensor of indices (``x[idx]``, advanced indexing: ~55 µs for 2,048 x 47 floats on the development
  machine); ``index_select`` on the first dimension gathers the same rows bit for bit in a quarter of the
  time. The permutation is drawn as rsl-rl draws it (one ``torch.randperm`` per update), so training's
  random stream is unchanged.
"""

from __future__ import annotations

import types
from collections.abc import Generator

import torch
from rsl_rl.algorithms import PPO as RslPPO
from rsl_rl.env import VecEnv
from rsl_rl.storage import RolloutStorage
from tensordict import TensorDict


class PPO(RslPPO):
    """rsl-rl's PPO, built as rsl-rl builds it, with :func:`speed_up` applied."""

    @staticmethod
    def construct_algorithm(obs: TensorDict, env: VecEnv, cfg: dict, device: str) -> PPO:
        alg = RslPPO.construct_algorithm(obs, env, cfg, device)
        speed_up(alg)
        return alg


def speed_up(alg: RslPPO) -> None:
    """Apply this module's changes to ``alg``, an rsl-rl PPO (before any update)."""
    if type(alg.optimizer) is torch.optim.Adam:
        (group,) = alg.optimizer.param_groups  # rsl-rl's one group: the actor's and critic's
        alg.optimizer = torch.optim.Adam(group["params"], lr=group["lr"], fused=True)
    storage = alg.storage
    if storage.training_type == "rl" and not (alg.actor.is_recurrent or alg.critic.is_recurrent):
        storage.mini_batch_generator = types.MethodType(mini_batches, storage)


def _rows(x: torch.Tensor | TensorDict, idx: torch.Tensor) -> torch.Tensor | TensorDict:
    """``x[idx]`` for a 1-D index tensor, through ``index_select`` (the same rows, bit for bit)."""
    if isinstance(x, TensorDict):
        return x.apply(lambda t: t.index_select(0, idx), batch_size=[idx.numel()])
    return x.index_select(0, idx)


def mini_batches(
    storage: RolloutStorage, num_mini_batches: int, num_epochs: int = 8
) -> Generator[RolloutStorage.Batch, None, None]:
    """rsl-rl's ``RolloutStorage.mini_batch_generator`` (5.5.1) with its gathers done by ``index_select``:
    the same permutation from the same random stream, the same batches."""
    batch_size = storage.num_envs * storage.num_transitions_per_env
    mini_batch_size = batch_size // num_mini_batches
    indices = torch.randperm(num_mini_batches * mini_batch_size, requires_grad=False, device=storage.device)
    observations = storage.observations.flatten(0, 1)
    actions = storage.actions.flatten(0, 1)
    values = storage.values.flatten(0, 1)
    returns = storage.returns.flatten(0, 1)
    old_actions_log_prob = storage.actions_log_prob.flatten(0, 1)
    advantages = storage.advantages.flatten(0, 1)
    old_distribution_params = tuple(p.flatten(0, 1) for p in storage.distribution_params)
    for _ in range(num_epochs):
        for i in range(num_mini_batches):
            idx = indices[i * mini_batch_size : (i + 1) * mini_batch_size]
            yield RolloutStorage.Batch(
                observations=_rows(observations, idx),
                actions=_rows(actions, idx),
                values=_rows(values, idx),
                advantages=_rows(advantages, idx),
                returns=_rows(returns, idx),
                old_actions_log_prob=_rows(old_actions_log_prob, idx),
                old_distribution_params=tuple(_rows(p, idx) for p in old_distribution_params),
            )
