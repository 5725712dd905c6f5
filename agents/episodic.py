"""The loop shared by the learners that replace PPO's iteration with whole cuts (APG, :mod:`agents.apg`;
evolution strategies, :mod:`agents.es`): PPO's :class:`~agents.train.Runner` (checkpoints, validation, model
selection, resume, evaluation and export are the same), its learning iteration one subclass's
:meth:`EpisodeRunner._iteration`, the actor started at "hold still"."""

from __future__ import annotations

import os
from pathlib import Path

import torch
from rsl_rl.env import VecEnv

from agents.train import Runner


class EpisodeRunner(Runner):
    """:class:`~agents.train.Runner` whose learning iteration is :meth:`_iteration`. Subclasses set
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
            raise ValueError(f"action_type: {self.name} plays continuous moves; use --actions continuous")
        if self.scene.episode_steps < self.scene.task.num_steps:
            raise ValueError(
                f"max_episode_steps: {self.name} runs whole cuts ({self.scene.task.num_steps} steps), not "
                f"{self.scene.episode_steps}; leave max_episode_steps unset"
            )
        self.steps_per_iteration = env.num_envs * self.scene.task.num_steps  # one whole cut per env
        self.episode_rng = vector.np_random  # seeded by train() (env.seed): episodes follow the run's seed
        # Start from holding still (fixed tensioning), as PPO's recipe does with its stay prior: the output
        # layer is zeroed, so the initial mean move is 0 everywhere (a resume loads its own weights).
        # A feedback path (actor_feedback) starts at zero by construction (agents.models.FeedbackMLP).
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
        """The actor's linear feedback path (``actor_feedback``, :class:`agents.models.FeedbackMLP`), or
        None."""
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
        from agents.train import read_checkpoint

        state = read_checkpoint(path, map_location=self.device) if state is None else state
        super().load_checkpoint(path, state)
        infos = state.get("infos") or {}
        if f"{self.name}_rng" not in infos:
            raise ValueError(
                f"{path}: not an {self.name.upper()} run's checkpoint; resume it with its own --algo"
            )
        self.episode_rng.bit_generator.state = infos[f"{self.name}_rng"]
        self._load_extra(infos)

    def learn(self, num_learning_iterations: int, init_at_random_ep_len: bool = False) -> None:
        """``num_learning_iterations`` iterations, saving checkpoints as PPO's loop does."""
        self.logger.init_logging_writer()
        self.alg.train_mode()
        start = self.current_learning_iteration
        threads = torch.get_num_threads()
        torch.set_num_threads(1)  # a 2 x 32 MLP gains nothing from threads; the simulator uses them
        try:
            for it in range(start, start + num_learning_iterations):
                metrics = self._iteration()
                self.current_learning_iteration = it
                if self.logger.writer is not None:
                    for key in self.scalars:
                        self.logger.writer.add_scalar(f"{self.name.capitalize()}/{key}", metrics[key], it)
                self._end_iteration(it, metrics)
                if self.logger.writer is not None and it % self.cfg["save_interval"] == 0:
                    self.save(os.path.join(self.logger.log_dir, f"model_{it}.pt"))
        finally:
            torch.set_num_threads(threads)
        if self.logger.writer is not None:
            self.save(os.path.join(self.logger.log_dir, f"model_{self.current_learning_iteration}.pt"))
            self.logger.stop_logging_writer()

    def _iteration(self) -> dict:
        """One learning iteration; its metrics (``final_error``, ``mean_return``, ``mean_episode_length``,
        ``iteration_steps_per_s``, ``collection_steps_per_s`` and :attr:`scalars`)."""
        raise NotImplementedError
