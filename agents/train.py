"""PPO training on rsl-rl's ``OnPolicyRunner``, with a run directory that survives Ctrl-C.

A run directory holds::

    config.json        TrainConfig, the rsl-rl config built from it, and the env's shapes (for export)
    model_K.pt         checkpoint after learning iteration K (0-based, rsl-rl's naming), every save_interval
    latest.pt          copy of the newest checkpoint; ``resume`` reads it
    best.pt            with a ``validate`` callback: the checkpoint whose deterministic policy scored the
                       lowest validation error so far (iteration 0, the initial policy, included);
                       ``policy_checkpoint`` (evaluation, export) prefers it
    events.out.tfevents.*   TensorBoard scalars written by rsl-rl's logger
    summary.json       status (completed, interrupted, failed), iterations, env steps, speed, last metrics,
                       ``history`` (every iteration's metrics) and ``validation`` (the validation scores)

The env is any :class:`rsl_rl.env.VecEnv` (``envs.rsl`` for warpcut). Beyond that contract, train() relies on:

- ``get_observations()`` / ``step()`` return a TensorDict with the group ``"policy"`` (actor and critic input;
  change ``TrainConfig.obs_groups`` to give the critic another group).
- Discrete control: ``num_actions`` actions per env (1 for one choice per step), each an index into
  ``num_action_choices`` options. ``step()`` receives the indices as a float tensor of shape
  ``(num_envs, num_actions)`` and casts them with ``.long()``. Continuous control: unbounded Gaussian
  samples; the env clips them.
- ``step()`` resets finished envs itself; ``dones`` (num_envs,) is 1 where an episode ended.
  ``extras["time_outs"]`` (num_envs,) bool is True only where an episode was cut short by a limit the
  observation does not show (PPO then bootstraps the value); a finished cut is a termination, not a time-out.
- ``extras["log"]`` maps names to a scalar or a 1D tensor; rsl-rl logs the mean over the iteration under the
  name (names with a "/" as is, others as ``Episode/<name>``). Put each finished episode's final error in
  ``extras["log"][FINAL_ERROR_KEY]`` as a tensor holding one value per env that finished on this step, and
  leave the key out on steps where none finished. The progress display shows its iteration mean. Do not set
  ``extras["episode"]``: rsl-rl 5.5.1 then ignores ``extras["log"]``.
- Optional ``seed(seed)``: reseed the env's randomness and reset every env; train() calls it first.
"""

from __future__ import annotations

import contextlib
import io
import random
import statistics
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils.logger import Logger

from agents.config import TrainConfig
from envs.rsl import FINAL_ERROR_KEY
from warpcut.io import write_atomic, write_json

LATEST_CHECKPOINT = "latest.pt"
"""File name of the copy of the newest checkpoint in a run directory."""
BEST_CHECKPOINT = "best.pt"
"""File name of the checkpoint with the lowest validation error in a run directory."""


def train(
    env: VecEnv,
    cfg: TrainConfig | dict,
    out_dir: str | Path,
    resume: str | Path | None = None,
    progress: bool = True,
    validate: Callable[[torch.nn.Module], float | np.ndarray] | None = None,
) -> dict:
    """Train a PPO policy on ``env`` and write the run directory ``out_dir``.

    Ctrl-C saves a checkpoint and an "interrupted" summary, then re-raises the ``KeyboardInterrupt``.

    Args:
        env: The vectorized env, seeded and reset by this function (see the module docstring's contract).
        cfg: Settings, or a dict of :class:`TrainConfig` fields.
        out_dir: Run directory; created if needed.
        resume: Run directory or checkpoint to continue from: loads the model, optimizer and iteration count
            and trains until ``cfg.iterations`` in total.
        progress: Show a progress bar (on stderr). rsl-rl's per-iteration console report is never printed;
            its scalars go to TensorBoard.
        validate: Scores an actor (called with the live actor; use its deterministic output) on episodes
            that are not the evaluation's: the error of each episode, an array ``(episodes,)`` or
            ``(episodes, columns)`` (e.g. one column per pinch candidate), the same episodes every call; or
            one error. Called before training and every ``cfg.validation_interval`` iterations; the policy
            with the lowest selection score is saved as ``best.pt``, which evaluation and export then use
            (model selection on held-out episodes). The score is the mean error plus
            ``cfg.selection_margin`` standard errors of its paired difference from the first validation
            (the initial policy), so a trained policy must beat the initial one by more than validation
            noise to replace it. Errors and scores are in the summary's ``validation`` list and in
            TensorBoard (``Validation/error``).

    Returns:
        The summary also written to ``out_dir/summary.json``.
    """
    cfg = cfg if isinstance(cfg, TrainConfig) else TrainConfig(**cfg)
    if not cfg.selection_margin >= 0:
        raise ValueError(f"selection_margin: must be >= 0 standard errors, got {cfg.selection_margin}")
    if env.num_envs != cfg.num_envs:
        raise ValueError(f"env has {env.num_envs} envs but the config asks for {cfg.num_envs}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)

    seed_everything(cfg.seed)
    if hasattr(env, "seed"):
        env.seed(cfg.seed)
    num_action_choices = getattr(env, "num_action_choices", None) if cfg.discrete else None
    runner = Runner(env, cfg.to_rsl_rl(num_action_choices), out_dir, cfg.torch_device)
    runner.selection_margin = cfg.selection_margin
    if resume is not None:
        runner.load_checkpoint(latest_checkpoint(resume))
    obs = env.get_observations()
    write_json(
        out_dir / "config.json",
        {
            "train": asdict(cfg),
            "rsl_rl": runner.cfg,
            "env": {
                "num_envs": env.num_envs,
                "num_actions": env.num_actions,
                "num_action_choices": num_action_choices,
                "obs_shapes": {group: list(obs[group].shape[1:]) for group in obs.keys()},
            },
            "resumed_from": None if resume is None else str(resume),
        },
    )

    start_iterations, start_time, status = runner.iterations_done, time.monotonic(), "failed"
    try:
        with _progress_display(progress, cfg.iterations, start_iterations) as report:
            if validate is None:
                runner.on_iteration = report
            else:
                if resume is None or runner.best_error is None:
                    runner.validate(validate)

                def on_iteration(iterations_done: int, metrics: dict) -> None:
                    if iterations_done % cfg.validation_interval == 0 or iterations_done == cfg.iterations:
                        runner.validate(validate)
                    report(iterations_done, metrics)

                runner.on_iteration = on_iteration
            if cfg.iterations > start_iterations:
                runner.learn(cfg.iterations - start_iterations)
        status = "completed"
    except KeyboardInterrupt:
        status = "interrupted"
        runner.save_interrupted()
        raise
    finally:
        if runner.logger.writer is not None:
            runner.logger.writer.close()
        wall_time = time.monotonic() - start_time
        steps_per_iteration = cfg.num_steps_per_env * cfg.num_envs
        new_steps = (runner.iterations_done - start_iterations) * steps_per_iteration
        summary = {
            "status": status,
            "iterations": runner.iterations_done,
            "env_steps": runner.iterations_done * steps_per_iteration,
            "wall_time_s": wall_time,
            "steps_per_s": new_steps / max(wall_time, 1e-9),
            **runner.metrics,
            "checkpoint": None if runner.checkpoint is None else runner.checkpoint.name,
            "validation": runner.validation,
            "history": runner.history,
            "best": None
            if runner.best_error is None
            else {
                "iterations": runner.best_iterations,
                "validation_error": runner.best_error,
                "validation_score": runner.best_score,
            },
        }
        write_json(out_dir / "summary.json", summary)
    return summary


class Runner(OnPolicyRunner):
    """rsl-rl's on-policy runner with atomic checkpoints, a ``latest.pt`` copy and a per-iteration callback.

    Attributes:
        iterations_done: Learning iterations completed, including those before a resume.
        metrics: Last iteration's ``final_error``, ``mean_return``, ``mean_episode_length`` (None until an
            episode ends) and ``iteration_steps_per_s``.
        checkpoint: Newest checkpoint written, or None.
        on_iteration: Called with ``(iterations_done, metrics)`` after each iteration.
    """

    def __init__(self, env: VecEnv, train_cfg: dict, log_dir: str | Path | None, device: str = "cpu") -> None:
        log_dir = None if log_dir is None else str(log_dir)
        # rsl-rl prints the models and observation sets; config.json records them instead.
        with contextlib.redirect_stdout(io.StringIO()):
            super().__init__(env, train_cfg, log_dir, device)
        self.logger = _QuietLogger(
            self._end_iteration,
            log_dir=log_dir,
            cfg=self.cfg,
            env_cfg=self.env.cfg,
            num_envs=self.env.num_envs,
            is_distributed=self.is_distributed,
            gpu_world_size=self.gpu_world_size,
            gpu_global_rank=self.gpu_global_rank,
            device=self.device,
        )
        self.iterations_done = 0
        self.metrics: dict[str, float | None] = dict.fromkeys(
            ("final_error", "mean_return", "mean_episode_length", "iteration_steps_per_s")
        )
        self.checkpoint: Path | None = None
        self.on_iteration: Callable[[int, dict], None] = lambda iterations_done, metrics: None
        self.validation: list[dict] = []
        self.history: list[dict] = []
        self.best_error: float | None = None
        self.best_score: float | None = None
        self.best_iterations: int | None = None
        self.validation_baseline: list | None = None
        self.selection_margin = 0.0

    def _state_bytes(self, infos: dict | None = None) -> bytes:
        state = self.alg.save()
        state["iter"] = self.current_learning_iteration
        state["infos"] = {
            "iterations_done": self.iterations_done,
            "validation": self.validation,
            "history": self.history,
            "best_error": self.best_error,
            "best_score": self.best_score,
            "best_iterations": self.best_iterations,
            "validation_baseline": self.validation_baseline,
            **(infos or {}),
        }
        buffer = io.BytesIO()
        torch.save(state, buffer)
        return buffer.getvalue()

    def save(self, path: str, infos: dict | None = None) -> None:
        """Save models, optimizer and iteration count to ``path`` and to ``latest.pt``, each atomically."""
        data = self._state_bytes(infos)
        write_atomic(path, data)
        write_atomic(Path(path).with_name(LATEST_CHECKPOINT), data)
        self.checkpoint = Path(path)
        self.logger.save_model(path, self.current_learning_iteration)

    def validate(self, validate: Callable[[torch.nn.Module], float | np.ndarray]) -> float:
        """Score the deterministic policy with ``validate``; save ``best.pt`` if its selection score (see
        :meth:`_selection_score`) is the lowest yet. Returns the validation error."""
        was_training = self.alg.actor.training
        self.alg.actor.eval()
        try:
            with torch.inference_mode():
                errors = validate(self.alg.actor)
        finally:
            self.alg.actor.train(was_training)
        error, score = self._selection_score(errors)
        self.validation.append({"iterations": self.iterations_done, "error": error, "score": score})
        if self.logger.writer is not None:
            self.logger.writer.add_scalar("Validation/error", error, self.iterations_done)
        if self.best_score is None or score < self.best_score:
            self.best_error, self.best_score, self.best_iterations = error, score, self.iterations_done
            if self.logger.log_dir is not None:
                write_atomic(Path(self.logger.log_dir) / BEST_CHECKPOINT, self._state_bytes())
        return error

    def _selection_score(self, errors: float | np.ndarray) -> tuple[float, float]:
        """``(error, score)`` of one validation: the mean error of its best column, and the score model
        selection minimises. The first per-episode validation is the baseline (the initial policy); a later
        one scores ``mean + selection_margin * SE`` of its episodes' paired differences from the baseline's
        (per column; the lowest column). A scalar validation scores its value."""
        values = np.asarray(errors, dtype=np.float64)
        if values.ndim == 0:
            return float(values), float(values)
        values = values.reshape(len(values), -1)
        if not np.all(np.isfinite(values)):
            raise ValueError(f"validation errors must be finite, got {values.ravel().tolist()}")
        means = values.mean(axis=0)
        if self.validation_baseline is None:
            self.validation_baseline = values.tolist()
        baseline = np.asarray(self.validation_baseline, dtype=np.float64)
        if baseline.shape != values.shape:
            raise ValueError(
                f"validation errors have shape {values.shape}, the baseline's {baseline.shape}: "
                "validate on the same episodes every time"
            )
        se = (values - baseline).std(axis=0, ddof=1) / np.sqrt(len(values)) if len(values) > 1 else 0.0
        scores = means + self.selection_margin * se
        return float(means.min()), float(scores.min())

    def save_interrupted(self) -> None:
        """Save the current state after a Ctrl-C, as the checkpoint of the last completed iteration."""
        self.current_learning_iteration = self.iterations_done - 1
        name = f"model_{self.iterations_done - 1}.pt" if self.iterations_done else LATEST_CHECKPOINT
        self.save(str(Path(self.logger.log_dir) / name))  # type: ignore[arg-type]

    def load_checkpoint(self, path: str | Path) -> None:
        """Load models, optimizer and learning rate; continue the iteration count after the checkpoint's."""
        infos = self.load(str(path), map_location=self.device) or {}
        # rsl-rl would repeat the checkpoint's iteration; continue after it instead.
        self.iterations_done = infos.get("iterations_done", self.current_learning_iteration + 1)
        self.current_learning_iteration = self.iterations_done
        self.validation = list(infos.get("validation") or [])
        self.history = list(infos.get("history") or [])
        self.best_error = infos.get("best_error")
        self.best_score = infos.get("best_score", self.best_error)
        self.best_iterations = infos.get("best_iterations")
        self.validation_baseline = infos.get("validation_baseline")

    def _end_iteration(self, it: int, metrics: dict) -> None:
        self.iterations_done = it + 1
        self.metrics = metrics
        self.history.append({"iteration": self.iterations_done, **metrics})
        self.on_iteration(self.iterations_done, metrics)


class _QuietLogger(Logger):
    """rsl-rl's logger that hands each iteration's metrics to a callback instead of printing a report.

    It also skips rsl-rl's code-state snapshot, which runs ``git status`` on the repository around rsl-rl.
    """

    def __init__(self, on_iteration: Callable[[int, dict], None], **kwargs) -> None:
        super().__init__(**kwargs)
        self.on_iteration = on_iteration

    def log(
        self, it: int, start_it: int, total_it: int, collect_time: float, learn_time: float, **kwargs
    ) -> None:
        final_error = _mean_log_value(self.ep_extras, FINAL_ERROR_KEY)
        with contextlib.redirect_stdout(io.StringIO()):
            super().log(it, start_it, total_it, collect_time, learn_time, **kwargs)
        steps = self.cfg["num_steps_per_env"] * self.num_envs * self.gpu_world_size
        self.on_iteration(
            it,
            {
                "final_error": final_error,
                "mean_return": statistics.mean(self.rewbuffer) if self.rewbuffer else None,
                "mean_episode_length": statistics.mean(self.lenbuffer) if self.lenbuffer else None,
                "iteration_steps_per_s": steps / (collect_time + learn_time),
            },
        )

    def _store_code_state(self) -> list[str]:
        return []


def latest_checkpoint(path: str | Path) -> Path:
    """Return ``path`` if it is a checkpoint file, else the run directory's ``latest.pt``."""
    path = Path(path)
    checkpoint = path / LATEST_CHECKPOINT if path.is_dir() else path
    if not checkpoint.is_file():
        raise FileNotFoundError(f"no checkpoint at {checkpoint}")
    return checkpoint


def policy_checkpoint(path: str | Path) -> Path:
    """The checkpoint whose policy a run stands for: ``path`` if it is a file, else the run directory's
    ``best.pt`` (the validated best, when training validated) or its ``latest.pt``."""
    path = Path(path)
    if path.is_dir() and (path / BEST_CHECKPOINT).is_file():
        return path / BEST_CHECKPOINT
    return latest_checkpoint(path)


def seed_everything(seed: int) -> None:
    """Seed Python's, NumPy's and torch's global generators."""
    random.seed(seed)
    np.random.seed(seed)  # noqa: NPY002 -- for any third-party code drawing from the global generator
    torch.manual_seed(seed)


def _mean_log_value(ep_extras: list[dict], key: str) -> float | None:
    """Mean of every value logged under ``key`` this iteration (scalars and tensors alike), or None."""
    values = [
        torch.as_tensor(extras[key], dtype=torch.float).reshape(-1).cpu()
        for extras in ep_extras
        if key in extras
    ]
    values = torch.cat(values) if values else torch.empty(0)
    return float(values.mean()) if values.numel() else None


@contextlib.contextmanager
def _progress_display(enabled: bool, total: int, completed: int) -> Iterator[Callable[[int, dict], None]]:
    """Yield a callback ``(iterations_done, metrics)`` that advances a progress bar, or does nothing."""
    if not enabled:
        yield lambda iterations_done, metrics: None
        return
    columns = (
        TextColumn("PPO"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[steps_per_s]} steps/s"),
        TextColumn("final error {task.fields[final_error]}"),
        TextColumn("return {task.fields[mean_return]}"),
        TimeRemainingColumn(),
    )
    # stderr: rsl-rl's report is swallowed by redirecting stdout, which must not catch the bar's redraws.
    with Progress(*columns, console=Console(stderr=True)) as bar:
        task = bar.add_task(
            "train", total=total, completed=completed, steps_per_s="-", final_error="-", mean_return="-"
        )

        def report(iterations_done: int, metrics: dict) -> None:
            # Keep the last known episode metrics through iterations in which no episode ended.
            known = {
                key: f"{metrics[key]:.3f}"
                for key in ("final_error", "mean_return")
                if metrics[key] is not None
            }
            bar.update(
                task,
                completed=iterations_done,
                steps_per_s=f"{metrics['iteration_steps_per_s']:.0f}",
                **known,
            )

        yield report
