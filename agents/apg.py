"""Analytic policy gradients (APG): the tensioning policy trained by backpropagating the path surrogate
through the differentiable simulator (:mod:`warpcut.gradients`), an alternative to PPO
(``warpcut train --algo apg``).

Each iteration runs one episode in every env with the policy's deterministic action (its Gaussian's mean),
replays it backward for the surrogate's gradient with respect to every step's grasp move, and chains that
through the policy's moves into its weights (Adam, gradient-norm clipping). The observations are taken as
given: the gradient does not flow from a move through the sheet into later observations (the usual
truncation of APG through a non-differentiable observer; the fiducials' tracking is not differentiable).
On a base plan (``PatternCutOptions.base_plan``, ``--recipe apg-residual``) the policy's move is added to
the plan's, as the env adds them, and the gradient reaches the policy through the clipped sum: APG then
refines the open-loop plan with a closed-loop residual, starting from the plan itself. With ``accept``
(``TrainConfig.apg_accept``) a step is kept only if the iteration's episodes, cut again with the new weights,
come out better (docs/learning.md: it stops the drift, and the surrogate's roughness explains why it learns
nothing).

The policy is rsl-rl's actor, as PPO's (an MLP with observation normalisation and a Gaussian head over
continuous moves): :class:`ApgRunner` is PPO's runner with the learning iteration replaced
(:class:`agents.episodic.EpisodeRunner`, shared with evolution strategies), so checkpoints, validation,
model selection, resume, evaluation and export are the same; its critic and the action noise are not
trained.
"""

from __future__ import annotations

import copy
import time
from pathlib import Path

import numpy as np
import torch
from rsl_rl.env import VecEnv

from agents.config import APG_FIXED_SHEET
from agents.episodic import EpisodeRunner


class ApgRunner(EpisodeRunner):
    """:class:`~agents.episodic.EpisodeRunner` whose learning iteration is an APG step (see the module)."""

    name = "apg"
    scalars = ("final_error", "surrogate", "grad_norm")

    def __init__(self, env: VecEnv, train_cfg: dict, log_dir: str | Path | None, device: str = "cpu") -> None:
        from warpcut.gradients import DifferentiableRollout

        super().__init__(env, train_cfg, log_dir, device)
        options = self.scene.options
        if options.randomize or options.relative_reward:
            raise ValueError(APG_FIXED_SHEET)
        self.engine = DifferentiableRollout(self.scene.task)
        algorithm = train_cfg["algorithm"]
        self.apg_optimizer = torch.optim.Adam(self.alg.actor.parameters(), lr=algorithm["learning_rate"])
        self.max_grad_norm = algorithm["max_grad_norm"]
        self.window = train_cfg.get("apg", {}).get("window")
        self.accept = bool(train_cfg.get("apg", {}).get("accept", False))
        self.max_learning_rate = algorithm["learning_rate"]

    def _extra_state(self) -> dict:
        return {"apg_optimizer": self.apg_optimizer.state_dict()}

    def _load_extra(self, infos: dict) -> None:
        self.apg_optimizer.load_state_dict(infos["apg_optimizer"])

    def _iteration(self) -> dict:
        """One episode per env, its backward pass, one Adam step (kept only if it helps, with ``accept``);
        the iteration's metrics."""
        scene, actor = self.scene, self.alg.actor
        start = time.perf_counter()
        episodes = self.episode_rng.bit_generator.state
        scene.reset(self.episode_rng, resample_fiducials=scene.options.resample_fiducials)
        moves: list[torch.Tensor] = []
        observations: list | None = [] if self.accept else None
        rollout = self.engine.forward(self._policy(moves, observations), reset=False)
        collected = time.perf_counter()
        grads = self.engine.backward(rollout, self.window)
        g = torch.as_tensor(grads.actions, dtype=torch.float32, device=self.device)
        proxy = sum((g[:, t] * move).sum() for t, move in enumerate(moves)) / len(g)
        self.apg_optimizer.zero_grad()
        proxy.backward()
        norm = torch.nn.utils.clip_grad_norm_(actor.parameters(), self.max_grad_norm)
        error = float(np.nanmean(rollout.score.error_vertices))
        if self.accept:
            accepted = self._step(error, episodes)
        else:
            self.apg_optimizer.step()
        if observations:  # with accept, the normaliser learns after the step (see TrainConfig.apg_accept)
            actor.update_normalization(torch.cat(observations))
        elapsed = time.perf_counter() - start
        steps = self.env.num_envs * len(moves)
        metrics = {
            "final_error": error,
            "surrogate": float(np.nanmean(rollout.surrogate)),
            "grad_norm": float(norm),
            "mean_return": None,
            "mean_episode_length": float(len(moves)),
            "iteration_steps_per_s": steps / elapsed,
            "collection_steps_per_s": steps / (collected - start),
        }
        if self.accept:
            metrics |= {"accepted": float(accepted), "step_size": self.apg_optimizer.param_groups[0]["lr"]}
        return metrics

    def _policy(self, moves: list | None, observations: list | None):
        """The policy the differentiable rollout calls before each step: the actor's clamped mean move plus
        what the env adds (analytic share, base plan). ``moves`` collects the moves with their graph (None:
        no graph, a replay); ``observations`` collects each step's observations for the normaliser to learn
        from after the step (with ``accept``; None: it learns from them as they come, except in a replay)."""
        from tensordict import TensorDict

        scene, actor = self.scene, self.alg.actor
        b, axes = self.env.num_envs, self.env.num_actions
        max_step = scene.config.max_step_mm

        def policy(task) -> np.ndarray:
            obs = TensorDict({"policy": torch.as_tensor(scene.observe(), device=self.device)}, batch_size=[b])
            if observations is not None:
                observations.append(obs)
            elif moves is not None:
                actor.update_normalization(obs)
            with torch.set_grad_enabled(moves is not None):
                move = torch.zeros((b, 3), device=self.device)
                move[:, :axes] = torch.clamp(actor(obs), -1.0, 1.0) * max_step
                # The parts that do not depend on the policy, added as the env adds them
                # (envs.core.PatternCut.step): the analytic controller's (residual_gain), then the base
                # plan's with the sum clipped per axis (no gradient where the clip binds).
                fixed = np.zeros((b, 3), dtype=np.float32)
                if scene.options.residual_gain:
                    tracking = np.nan_to_num(scene.tracking_error()[:, :2], nan=0.0)
                    fixed[:, :2] -= scene.options.residual_gain * tracking
                move = move + torch.as_tensor(fixed, device=self.device)
                if scene.base_plan is not None and task.step_index < len(scene.base_plan):
                    plan = torch.as_tensor(scene.plan_move(), dtype=torch.float32, device=self.device)
                    move = torch.clamp(move + plan, -max_step, max_step)
            if moves is not None:
                moves.append(move)
            return move.detach().cpu().numpy()

        return policy

    def _step(self, error: float, episodes: dict) -> bool:
        """Adam's step, kept only if the same episodes (``episodes``: the episode generator's state before
        their reset) cut with the new weights have a lower mean path error than ``error``, the old weights';
        otherwise the weights and Adam's state go back. The step size halves on a rejection and grows by
        1.5 on an acceptance, up to the run's learning rate. True if kept."""
        actor, scene = self.alg.actor, self.scene
        weights = [p.detach().clone() for p in actor.parameters()]
        adam = copy.deepcopy(self.apg_optimizer.state_dict())
        self.apg_optimizer.step()
        after = self.episode_rng.bit_generator.state
        self.episode_rng.bit_generator.state = episodes
        scene.reset(self.episode_rng, resample_fiducials=scene.options.resample_fiducials)
        self.episode_rng.bit_generator.state = after
        replay = self.engine.forward(self._policy(None, None), reset=False)
        kept = bool(np.nanmean(replay.score.error_vertices) < error)
        if not kept:
            with torch.no_grad():
                for p, w in zip(actor.parameters(), weights, strict=True):
                    p.copy_(w)
            self.apg_optimizer.load_state_dict(adam)
        group = self.apg_optimizer.param_groups[0]
        group["lr"] = min(group["lr"] * 1.5, self.max_learning_rate) if kept else group["lr"] * 0.5
        return kept
