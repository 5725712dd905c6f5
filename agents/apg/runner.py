"""Analytic policy gradients (APG): the tensioning policy trained by backpropagating the path surrogate
through the differentiable simulator (:mod:`warpcut.gradients`), an alternative to PPO
(``warpcut train --algo apg``).

Each iteration runs one episode in every env with the policy's deterministic action (its Gaussian's mean),
replays it backward for the surrogate's gradient with respect to every step's grasp move, and chains that
through the policy's moves into its weights (Adam, gradient-norm clipping). The observations are taken as
given: the gradient does not flow from a move through the sheet into later observations (the usual
truncation of APG through a non-differentiable observer; the fiducials' tracking is not differentiable).
With ``accept`` (:attr:`agents.apg.config.ApgConfig.accept`) a step is kept only if the iteration's
episodes, cut again with the new weights, come out better.

The policy is rsl-rl's actor, as PPO's (an MLP with observation normalisation and a Gaussian head over
continuous moves): :class:`ApgRunner` is warpcut's rsl-rl runner with its learning loop replaced
(:class:`EpisodeRunner`: whole episodes through the differentiable simulator instead of the env's steps),
so checkpoints, validation, model selection, resume, evaluation and export are the same; the critic and the
action noise are not trained.
"""

from __future__ import annotations

import copy
import os
import time
from pathlib import Path

import numpy as np
import torch
from rsl_rl.env import VecEnv

from agents.algorithms import algorithm
from agents.checkpoints import read_checkpoint
from agents.models import torch_threads
from agents.runner import Runner


class EpisodeRunner(Runner):
    """:class:`~agents.runner.Runner` whose learning iteration is :meth:`_iteration`. Subclasses set
    :attr:`name` (the ``--algo``) and :attr:`scalars` (metrics logged to TensorBoard under ``Name/``), and
    keep their own state in :meth:`_extra_state` / :meth:`_load_extra`."""

    name = ""
    scalars: tuple[str, ...] = ()

    def __init__(self, env: VecEnv, train_cfg: dict, log_dir: str | Path | None, device: str = "cpu") -> None:
        super().__init__(env, train_cfg, log_dir, device)
        vector = getattr(env, "env", None)
        self.scene = getattr(vector, "scene", None)
        if self.scene is None:
            raise ValueError(
                f"env: {self.name} needs warpcut's env (envs.rsl.PatternCutRslEnv over PatternCutVecEnv)"
            )
        if self.scene.options.action_type != "continuous":
            raise ValueError(f"env.action_type: {self.name} plays continuous moves; set it to continuous")
        if self.scene.episode_steps < self.scene.task.num_steps:
            raise ValueError(
                f"env.max_episode_steps: {self.name} runs whole cuts ({self.scene.task.num_steps} steps), "
                "not "
                f"{self.scene.episode_steps}; leave max_episode_steps unset"
            )
        self.steps_per_iteration = env.num_envs * self.scene.task.num_steps  # one whole cut per env
        self.episode_rng = vector.np_random  # seeded by train() (env.seed): episodes follow the run's seed
        # Start from holding still (fixed tensioning), as PPO's recipe does with its stay prior: the output
        # layer is zeroed, so the initial mean move is 0 everywhere (a resume loads its own weights).
        with torch.no_grad():
            self.output_layer.weight.zero_()
            self.output_layer.bias.zero_()

    @property
    def body(self) -> torch.nn.Sequential:
        """The actor's MLP (rsl-rl's), without the feedback path where it has one."""
        mlp = self.alg.actor.mlp
        return getattr(mlp, "body", mlp)

    @property
    def output_layer(self) -> torch.nn.Linear:
        """The actor MLP's last linear layer."""
        return [m for m in self.body.modules() if isinstance(m, torch.nn.Linear)][-1]

    @property
    def feedback_layer(self) -> torch.nn.Linear | None:
        """The actor's linear feedback path (:class:`agents.models.FeedbackMLP`), or None."""
        return getattr(self.alg.actor.mlp, "feedback", None)

    def _extra_state(self) -> dict:
        """What the subclass keeps in a checkpoint (besides the episode stream's state)."""
        return {}

    def _load_extra(self, infos: dict) -> None:
        """Restore :meth:`_extra_state`'s ``infos``."""

    def _state_bytes(self, infos: dict | None = None) -> bytes:
        extra = {f"{self.name}_rng": self.episode_rng.bit_generator.state, **self._extra_state()}
        return super()._state_bytes({**extra, **(infos or {})})

    def load_checkpoint(self, path: str | Path, state: dict | None = None) -> None:
        state = read_checkpoint(path, map_location=self.device) if state is None else state
        super().load_checkpoint(path, state)
        infos = state.get("infos") or {}
        if f"{self.name}_rng" not in infos:
            raise ValueError(
                f"{path}: not an {self.name.upper()} run's checkpoint; resume it with its own algo"
            )
        self.episode_rng.bit_generator.state = infos[f"{self.name}_rng"]
        self._load_extra(infos)

    def learn(self, num_learning_iterations: int, init_at_random_ep_len: bool = False) -> None:
        """``num_learning_iterations`` iterations, saving checkpoints as PPO's loop does."""
        self.logger.init_logging_writer()
        self.alg.train_mode()
        start = self.current_learning_iteration
        with torch_threads(1):
            for it in range(start, start + num_learning_iterations):
                metrics = self._iteration()
                self.current_learning_iteration = it
                if self.logger.writer is not None:
                    for key in self.scalars:
                        self.logger.writer.add_scalar(f"{self.name.capitalize()}/{key}", metrics[key], it)
                self._end_iteration(it, metrics)
                if self.logger.writer is not None and it % self.cfg["save_interval"] == 0:
                    self.save(os.path.join(self.logger.log_dir, f"model_{it}.pt"))
        if self.logger.writer is not None:
            self.save(os.path.join(self.logger.log_dir, f"model_{self.current_learning_iteration}.pt"))
            self.logger.stop_logging_writer()

    def _iteration(self) -> dict:
        """One learning iteration; its metrics (``final_error``, ``mean_return``, ``mean_episode_length``,
        ``iteration_steps_per_s``, ``collection_steps_per_s`` and :attr:`scalars`)."""
        raise NotImplementedError


class ApgRunner(EpisodeRunner):
    """:class:`EpisodeRunner` whose learning iteration is an APG step (see the module)."""

    name = "apg"
    scalars = ("final_error", "surrogate", "grad_norm")

    def __init__(self, env: VecEnv, train_cfg: dict, log_dir: str | Path | None, device: str = "cpu") -> None:
        from warpcut.gradients import DifferentiableRollout

        super().__init__(env, train_cfg, log_dir, device)
        options = self.scene.options
        if options.randomize or options.relative_reward:
            raise ValueError(algorithm("apg").fixed_sheet)
        self.engine = DifferentiableRollout(self.scene.task)
        settings = train_cfg["apg"]
        self.apg_optimizer = torch.optim.Adam(self.alg.actor.parameters(), lr=settings["learning_rate"])
        self.max_grad_norm = settings["max_grad_norm"]
        self.window = settings["window"]
        self.accept = bool(settings["accept"])
        self.max_learning_rate = settings["learning_rate"]

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
        relative = float(np.nanmean(rollout.score.error_mm2 / scene.area_mm2))
        if self.accept:
            accepted = self._step(error, episodes)
        else:
            self.apg_optimizer.step()
        if observations:  # with accept, the normaliser learns after the step (see TrainConfig.apg_accept)
            actor.update_normalization(torch.cat(observations))
        elapsed = time.perf_counter() - start
        steps = self.env.num_envs * len(moves)
        metrics = {
            "final_error": relative,
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
        """The policy the differentiable rollout calls before each step: the actor's clamped mean move, as
        the env plays it. ``moves`` collects the moves with their graph (None: no graph, a replay);
        ``observations`` collects each step's observations for the normaliser to learn
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
