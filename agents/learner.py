"""What the rsl-rl algorithms that train an actor alone share (:class:`ActorOnly`): es
(:mod:`agents.es.algorithm`, and gps on top of it) and dagger (:mod:`agents.dagger.algorithm`). They have no
critic and no rollout storage; rsl-rl's runner drives them through ``act`` / ``process_env_step`` /
``compute_returns`` / ``update`` as it drives PPO."""

from __future__ import annotations

import torch
from rsl_rl.env import VecEnv
from rsl_rl.models import MLPModel
from rsl_rl.utils import resolve_class, resolve_obs_groups
from tensordict import TensorDict


class ActorOnly:
    """The actor, its device and env, and what rsl-rl's runner and logger read of an algorithm.

    Args:
        actor: The policy (rsl-rl's ``MLPModel`` or :class:`agents.models.FeedbackMLPModel`).
        env: The env it trains on.
        learning_rate: What rsl-rl's logger reports as the learning rate.
        name: The learner's name, for errors.
        device: Torch device of the actor.
        multi_gpu_cfg: rsl-rl's multi-GPU settings: refused (one process).
    """

    def __init__(
        self,
        actor: MLPModel,
        env: VecEnv,
        learning_rate: float,
        name: str,
        device: str = "cpu",
        multi_gpu_cfg: dict | None = None,
    ) -> None:
        if multi_gpu_cfg is not None:
            raise ValueError(f"{name}: multi-GPU training is not supported; run it in one process")
        self.device = device
        self.actor = actor.to(device)
        self.env = env
        self.learning_rate = learning_rate  # what rsl-rl's logger reads
        self.rnd = None
        if actor.distribution is not None:  # rsl-rl's logger reads the policy's std every iteration
            actor.distribution.update(torch.zeros(1, actor.distribution.input_dim, device=device))

    @staticmethod
    def construct_algorithm(obs: TensorDict, env: VecEnv, cfg: dict, device: str) -> ActorOnly:
        """Build the actor and the algorithm ``cfg["algorithm"]`` names as rsl-rl's runner asks (the
        algorithm's seed is drawn from torch's generator, which the training seeds)."""
        alg_class, alg_cfg = resolve_class(cfg["algorithm"])
        actor_class, actor_cfg = resolve_class(cfg["actor"])
        cfg["obs_groups"] = resolve_obs_groups(obs, cfg["obs_groups"], ["actor", "critic"])
        actor = actor_class(obs, cfg["obs_groups"], "actor", env.num_actions, **actor_cfg).to(device)
        seed = int(torch.randint(0, 2**31 - 1, (1,)).item())
        return alg_class(actor, env, **alg_cfg, seed=seed, device=device, multi_gpu_cfg=cfg.get("multi_gpu"))

    def train_mode(self) -> None:
        self.actor.train()

    def eval_mode(self) -> None:
        self.actor.eval()

    def get_policy(self) -> MLPModel:
        return self.actor

    def broadcast_parameters(self) -> None:
        """Nothing to do: one process."""
