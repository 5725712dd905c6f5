"""PPO training on rsl-rl's ``OnPolicyRunner``, with a run directory that survives Ctrl-C; the same run
directory and loop for analytic policy gradients and evolution strategies (``TrainConfig.algorithm`` "apg",
"es": :mod:`agents.apg`, :mod:`agents.es`).

A run directory holds::

    config.json        TrainConfig, the rsl-rl config built from it, and the env's shapes (for export)
    model_K.pt         checkpoint after learning iteration K (0-based, rsl-rl's naming), every save_interval
    latest.pt          copy of the newest checkpoint; ``resume`` reads it (or, where it is missing, damaged
                       or older, the newest readable model_K.pt: :func:`resume_checkpoint`)
    best.pt            with a ``validate`` callback: the checkpoint whose deterministic policy scored the
                       lowest validation error so far (iteration 0, the initial policy, included);
                       ``policy_checkpoint`` (evaluation, export) prefers it
    events.out.tfevents.*   TensorBoard scalars written by rsl-rl's logger
    summary.json       status (completed, interrupted, failed), iterations, env steps, speed, last metrics,
                       ``checkpoint`` (the newest one written whole), ``error`` (why a failed run stopped),
                       ``resumed_from``, ``history`` (every iteration's metrics) and ``validation`` (the
                       validation scores); ``wall_time_s``: training seconds of the whole run, the runs
                       before a resume included (up to the checkpoint it resumed), ``run_wall_time_s``: this
                       run's alone (``steps_per_s`` is its rate), ``earlier_wall_time_s``: the earlier runs'
                       (None if the checkpoint predates the field: ``wall_time_s`` then counts this run only)

Every checkpoint is read through :func:`read_checkpoint`: a damaged, truncated or empty file, or one that is
not a checkpoint, is a ``ValueError`` naming the file and what to use instead. A full disk while writing one
is a ``ValueError`` naming the file; the previous checkpoint stays intact (files are written atomically).

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
import json
import random
import re
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import torch
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils.logger import Logger

from agents.config import TrainConfig, default_iterations
from agents.ppo_speed import speed_up
from agents.progress import training_progress
from envs.rsl import FINAL_ERROR_KEY
from warpcut.io import DiskFull, write_atomic, write_json

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
    label: str = "PPO",
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
        label: The progress bar's label (e.g. the contour and pinch candidate being trained).
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
    cfg.check_algorithm()
    if cfg.iterations is None:  # the algorithm's default for this env
        cfg = replace(cfg, iterations=default_iterations(cfg.algorithm, env))
    if not cfg.selection_margin >= 0:
        raise ValueError(f"selection_margin: must be >= 0 standard errors, got {cfg.selection_margin}")
    if env.num_envs != cfg.num_envs:
        raise ValueError(f"env has {env.num_envs} envs but the config asks for {cfg.num_envs}")
    out_dir = make_run_dir(out_dir)

    seed_everything(cfg.seed)
    if hasattr(env, "seed"):
        env.seed(cfg.seed)
    num_action_choices = getattr(env, "num_action_choices", None) if cfg.discrete else None
    feedback = None
    if cfg.actor_feedback:
        from agents.models import feedback_inputs

        feedback = feedback_inputs(env)
    runner = _runner_class(cfg)(env, cfg.to_rsl_rl(num_action_choices, feedback), out_dir, cfg.torch_device)
    runner.selection_margin = cfg.selection_margin
    checkpoint, note = None, None
    if resume is not None:
        checkpoint, state, note = resume_checkpoint(resume)
        if note is not None:
            print(f"warning: {note}", file=sys.stderr)
        runner.load_checkpoint(checkpoint, state)
        runner.checkpoint = checkpoint if checkpoint.parent.resolve() == out_dir.resolve() else None
    _write_config(out_dir, cfg, runner, env, num_action_choices, checkpoint)

    start_iterations, status, steps = runner.iterations_done, "failed", runner.steps_per_iteration
    runner.started = time.monotonic()
    try:
        with training_progress(bool(progress), cfg.iterations, start_iterations, steps, label) as report:
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
        ending = sys.exc_info()[1]  # the exception that ends the run, if any
        if runner.logger.writer is not None:
            _log_hparams(runner.logger.writer, cfg, runner)
            runner.logger.writer.close()
        wall_time = time.monotonic() - runner.started
        summary = {
            "status": status,
            "iterations": runner.iterations_done,
            "env_steps": runner.iterations_done * steps,
            "wall_time_s": wall_time + (runner.earlier_wall_time or 0.0),
            "run_wall_time_s": wall_time,
            "earlier_wall_time_s": runner.earlier_wall_time,
            "steps_per_s": (runner.iterations_done - start_iterations) * steps / max(wall_time, 1e-9),
            **runner.metrics,
            "checkpoint": None if runner.checkpoint is None else runner.checkpoint.name,
            "error": None if ending is None or isinstance(ending, KeyboardInterrupt) else _one_line(ending),
            "resumed_from": None if checkpoint is None else str(checkpoint),
            "resume_note": note,
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
        _write_summary(out_dir / "summary.json", summary, runner.checkpoint, ending)
    return summary


def _runner_class(cfg: TrainConfig) -> type[Runner]:
    """PPO's :class:`Runner`, APG's (:class:`agents.apg.ApgRunner`) or es's (:class:`agents.es.EsRunner`)."""
    if cfg.algorithm == "ppo":
        return Runner
    from agents.apg import ApgRunner
    from agents.es import EsRunner

    return {"apg": ApgRunner, "es": EsRunner}[cfg.algorithm]


def _write_config(
    out_dir: Path,
    cfg: TrainConfig,
    runner: Runner,
    env: VecEnv,
    num_action_choices: int | None,
    checkpoint: Path | None,
) -> None:
    """Write the run's ``config.json``: the settings, rsl-rl's config and the env's shapes (for export)."""
    obs = env.get_observations()
    _write(
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
            "resumed_from": None if checkpoint is None else str(checkpoint),
        },
        "nothing was trained yet" if checkpoint is None else f"{checkpoint.name} is intact",
        resumable=checkpoint is not None,
    )


def _log_hparams(writer, cfg: TrainConfig, runner: Runner) -> None:
    """Log the run's settings and outcome to TensorBoard's HPARAMS tab (in the run's own event file, so
    runs compare side by side): scalar settings of ``cfg`` (lists as text), the last iteration's final
    error and return, and the kept policy's validation error."""
    from torch.utils.tensorboard.summary import hparams

    settings = {
        k: v if isinstance(v, int | float | str | bool) else json.dumps(v) for k, v in asdict(cfg).items()
    }
    outcome = {
        "hparam/final_error": runner.metrics.get("final_error"),
        "hparam/mean_return": runner.metrics.get("mean_return"),
        "hparam/validation_error": runner.best_error,
    }
    outcome = {k: float(v) for k, v in outcome.items() if v is not None and np.isfinite(v)}
    file_writer = writer._get_file_writer()  # SummaryWriter.add_hparams would open another run directory
    for summary in hparams(settings, outcome):
        file_writer.add_summary(summary)
    for name, value in outcome.items():
        writer.add_scalar(name, value, runner.iterations_done)


def make_run_dir(path: str | Path) -> Path:
    """Create the output directory ``path`` (and its parents) if needed; a ``ValueError`` naming the file
    where ``path`` or a parent of it is a file."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ValueError(f"{path}: is a file, not a directory; choose another --out")
    for parent in path.parents:  # a file where a parent directory should be
        if parent.exists() and not parent.is_dir():
            raise ValueError(f"{parent}: is a file, not a directory; choose another --out")
    path.mkdir(parents=True, exist_ok=True)
    return path


def _one_line(exc: BaseException) -> str:
    """What an exception says, on one line (its type when it says nothing)."""
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


def _write(path: Path, data: bytes | dict, intact: str, resumable: bool = True) -> None:
    """Write a checkpoint (bytes) or a JSON file (dict) of a run atomically (the previous version stays
    until the new one is whole).

    Raises:
        ValueError: The disk is full (``OSError`` ENOSPC, its cause): the message names ``path``, what is
            ``intact`` (e.g. "the previous checkpoint model_4.pt is intact") and the run directory to resume
            from (``resumable``) or that the run must start again.
    """
    try:
        write_atomic(path, data) if isinstance(data, bytes) else write_json(path, data)
    except DiskFull as exc:
        then = f"resume from {path.parent}" if resumable else "start again"
        raise ValueError(
            f"{path}: not written, the disk is full; {intact}: free space, then {then}"
        ) from exc.__cause__


def _write_summary(path: Path, summary: dict, checkpoint: Path | None, ending: BaseException | None) -> None:
    """Write ``summary.json``; on a full disk, while an exception (``ending``) ends the run, keep that
    exception (the checkpoints on disk still say where to resume) and note on it that the summary was not
    updated."""
    intact = f"the newest checkpoint {checkpoint.name} is intact" if checkpoint else "no checkpoint was saved"
    try:
        _write(path, summary, intact, resumable=checkpoint is not None)
    except ValueError as exc:
        if ending is None or not isinstance(exc.__cause__, OSError):
            raise
        ending.add_note(str(exc))


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
        speed_up(self.alg)  # fused Adam, minibatches by index_select (agents.ppo_speed)
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
        self.steps_per_iteration = self.cfg["num_steps_per_env"] * self.env.num_envs
        """Env steps one learning iteration simulates."""
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
        self.earlier_wall_time: float | None = 0.0
        """Training seconds of the runs before this one, up to the checkpoint it resumed (0 for a new run;
        None if that checkpoint predates the field, so the run's total time is unknown)."""
        self.started = time.monotonic()
        """When this run's training started (:func:`train` sets it); checkpoints record the time since."""

    def wall_time(self) -> float:
        """Training seconds so far, the runs before a resume included (those unknown count 0)."""
        return (self.earlier_wall_time or 0.0) + time.monotonic() - self.started

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
            "wall_time_s": None if self.earlier_wall_time is None else self.wall_time(),
            **(infos or {}),
        }
        buffer = io.BytesIO()
        torch.save(state, buffer)
        return buffer.getvalue()

    def save(self, path: str, infos: dict | None = None) -> None:
        """Save models, optimizer and iteration count to ``path`` and to ``latest.pt``, each atomically.

        A full disk is a ``ValueError`` naming the file; :attr:`checkpoint` stays the newest checkpoint
        written whole (``path`` once it is written, even if ``latest.pt`` then is not)."""
        data = self._state_bytes(infos)
        path = Path(path)
        previous = self.checkpoint
        if previous is None:
            _write(path, data, "no checkpoint was saved yet", resumable=False)
        else:
            _write(path, data, f"the previous checkpoint {previous.name} is intact")
        self.checkpoint = path
        _write(path.with_name(LATEST_CHECKPOINT), data, f"{path.name} (the newest checkpoint) is intact")
        self.logger.save_model(str(path), self.current_learning_iteration)

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
            previous = self.best_error, self.best_score, self.best_iterations
            self.best_error, self.best_score, self.best_iterations = error, score, self.iterations_done
            if self.logger.log_dir is not None:
                try:
                    _write(
                        Path(self.logger.log_dir) / BEST_CHECKPOINT,
                        self._state_bytes(),
                        f"the previous {BEST_CHECKPOINT} is intact",
                    )
                except ValueError:  # a full disk: the summary keeps naming the best.pt on disk
                    self.best_error, self.best_score, self.best_iterations = previous
                    raise
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

    def learn(self, num_learning_iterations: int, init_at_random_ep_len: bool = False) -> None:
        """rsl-rl's learning loop, with torch on one thread while it collects rollouts and on all of its
        threads for the PPO update (on a CPU): the simulator steps the envs on threads of its own, and torch
        threads spinning beside them cost more than they gain (docs/performance.md, section 6)."""
        if self.device != "cpu":
            return super().learn(num_learning_iterations, init_at_random_ep_len)
        threads = torch.get_num_threads()
        update = self.alg.update

        def update_on_all_threads(*args, **kwargs):
            torch.set_num_threads(threads)
            try:
                return update(*args, **kwargs)
            finally:
                torch.set_num_threads(1)

        torch.set_num_threads(1)
        self.alg.update = update_on_all_threads
        try:
            return super().learn(num_learning_iterations, init_at_random_ep_len)
        finally:
            self.alg.update = update
            torch.set_num_threads(threads)

    def save_interrupted(self) -> None:
        """Save the current state after a Ctrl-C, as the checkpoint of the last completed iteration."""
        self.current_learning_iteration = self.iterations_done - 1
        name = f"model_{self.iterations_done - 1}.pt" if self.iterations_done else LATEST_CHECKPOINT
        self.save(str(Path(self.logger.log_dir) / name))  # type: ignore[arg-type]

    def load_checkpoint(self, path: str | Path, state: dict | None = None) -> None:
        """Load models, optimizer and learning rate; continue the iteration count after the checkpoint's.

        Args:
            path: The checkpoint (named in errors).
            state: Its contents, if already read (:func:`resume_checkpoint`); default: read ``path``.

        Raises:
            ValueError: ``path`` is not a readable checkpoint, or its policy does not fit this env (e.g.
                another number of observations) or network.
        """
        path = Path(path)
        state = read_checkpoint(path, map_location=self.device) if state is None else state
        mismatch = layout_mismatch(state["actor_state_dict"], self.alg.get_policy().state_dict(), "the env")
        if mismatch:
            raise ValueError(
                f"{path}: {mismatch}: the run was trained with other options; resume it with the options it "
                "was trained with, or start a new run"
            )
        try:
            self.alg.load(state, None, True)
        except (RuntimeError, ValueError, KeyError) as exc:  # another network or optimizer than this config's
            raise ValueError(
                f"{path}: does not fit these PPO settings ({_one_line(exc)[:200]}); resume with the run's "
                "own settings (its config.json), or start a new run"
            ) from None
        self.current_learning_iteration = state["iter"]
        infos = state.get("infos") or {}
        # rsl-rl would repeat the checkpoint's iteration; continue after it instead.
        self.iterations_done = infos.get("iterations_done", self.current_learning_iteration + 1)
        self.current_learning_iteration = self.iterations_done
        self.validation = list(infos.get("validation") or [])
        self.history = list(infos.get("history") or [])
        self.best_error = infos.get("best_error")
        self.best_score = infos.get("best_score", self.best_error)
        self.best_iterations = infos.get("best_iterations")
        self.validation_baseline = infos.get("validation_baseline")
        self.earlier_wall_time = infos.get("wall_time_s")

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
                "collection_steps_per_s": steps / collect_time,
            },
        )

    def _store_code_state(self) -> list[str]:
        return []


_MODEL_CHECKPOINT = re.compile(r"model_(\d+)\.pt")
"""rsl-rl's name of the checkpoint after learning iteration K (0-based): ``model_K.pt``."""

CHECKPOINT_KEYS = ("actor_state_dict", "critic_state_dict", "optimizer_state_dict", "iter")
"""What every checkpoint of a run holds."""


def model_checkpoints(run_dir: str | Path) -> list[Path]:
    """The run directory's ``model_K.pt`` files, newest (highest K) first."""
    found = [
        (int(match[1]), p)
        for p in Path(run_dir).glob("model_*.pt")
        if (match := _MODEL_CHECKPOINT.fullmatch(p.name)) and p.is_file()
    ]
    return [p for _, p in sorted(found, reverse=True)]


def read_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> dict:
    """A checkpoint's contents (weights only: nothing in it is executed).

    Raises:
        FileNotFoundError: There is no file at ``path``.
        ValueError: ``path`` is a directory, or not a readable checkpoint (empty, truncated, damaged, or
            another kind of file); the message names the file and what to use instead.
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(
            f"{path}: is a directory, not a checkpoint file; give a run directory or one of its .pt files"
        )
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such checkpoint; give a run directory or one of its .pt files")
    why = _load_or_why(path, map_location)
    if isinstance(why, dict):
        return why
    raise ValueError(f"{path}: not a readable checkpoint ({why}); {_instead(path)}")


def _load_or_why(path: Path, map_location: str | torch.device = "cpu") -> dict | str:
    """``path``'s checkpoint, or why it is not one (e.g. "truncated or damaged?")."""
    with open(path, "rb") as f:
        head = f.read(4)
    if not head:
        return "an empty file: its write was cut short"
    try:
        state = torch.load(path, map_location=map_location, weights_only=True)
    except PermissionError:
        raise
    except Exception:  # torch raises EOFError, OSError 22, UnpicklingError, RuntimeError, KeyError, ...
        return "truncated or damaged?" if head.startswith(b"PK") else "not a PyTorch checkpoint file"
    missing = [k for k in CHECKPOINT_KEYS if not isinstance(state, dict) or k not in state]
    if missing:
        return f"not a checkpoint of 'warpcut train': no {', '.join(missing)}"
    return state


def _readable(path: Path) -> bool:
    return path.is_file() and isinstance(_load_or_why(path), dict)


def _instead(path: Path) -> str:
    """What to do about the unreadable checkpoint ``path``: which checkpoint of its run to use instead."""
    run = path.parent
    if path.suffix != ".pt":
        where = f" (such as {run})" if (run / "config.json").is_file() else ""
        return f"give a run directory written by 'warpcut train'{where}, or one of its .pt checkpoints"
    others = [p for p in (run / LATEST_CHECKPOINT, *model_checkpoints(run)) if p != path]
    fallback = next((p for p in others if _readable(p)), None)
    if fallback is None:
        return "the run has no other readable checkpoint: retrain it"
    if path.name == BEST_CHECKPOINT:
        return f"delete it to use the run's last policy ({fallback.name}), not the validated best, or retrain"
    if path.name == LATEST_CHECKPOINT:
        return f"delete it to fall back to {fallback.name} (the newest readable checkpoint), or retrain"
    return f"use another checkpoint (e.g. {fallback.name}, the newest readable one), or retrain"


def resume_checkpoint(path: str | Path) -> tuple[Path, dict, str | None]:
    """The checkpoint to continue ``path`` from, its contents, and a note when it is not the run's
    ``latest.pt``.

    A checkpoint file is read as it is. A run directory resumes from ``latest.pt``, unless it is missing or
    unreadable (a run that never wrote one, or a damaged file) or older than the newest ``model_K.pt`` (its
    write failed): then from the newest readable ``model_K.pt``, and the note says so.

    Raises:
        FileNotFoundError: ``path`` does not exist, or the run directory holds no checkpoint.
        ValueError: A checkpoint file that cannot be read, or a run directory with no readable checkpoint.
    """
    path = Path(path)
    if not path.is_dir():
        return path, read_checkpoint(path), None
    latest = path / LATEST_CHECKPOINT
    models = model_checkpoints(path)
    if not latest.exists() and not models:
        raise FileNotFoundError(
            f"{path}: no checkpoint to resume from (no {LATEST_CHECKPOINT} or model_K.pt): start it again "
            "without resuming"
        )
    state, why = None, "missing"
    if latest.exists():
        found = _load_or_why(latest) if latest.is_file() else "not a file"
        state, why = (found, None) if isinstance(found, dict) else (None, found)
    done = (state.get("infos") or {}).get("iterations_done", state["iter"] + 1) if state is not None else -1
    skipped = []
    for model in models:
        if int(_MODEL_CHECKPOINT.fullmatch(model.name)[1]) + 1 <= done:
            break  # latest.pt is at least as new
        found = _load_or_why(model)
        if not isinstance(found, dict):
            skipped.append(model.name)
            continue
        why = why or f"older than {model.name} (its last write failed?)"
        unread = f" ({', '.join(skipped)} unreadable)" if skipped else ""
        return model, found, f"{path}: {LATEST_CHECKPOINT} {why}; resuming from {model.name}{unread}"
    if state is None:
        raise ValueError(
            f"{path}: no readable checkpoint to resume from ({LATEST_CHECKPOINT}: {why}"
            + (f"; unreadable: {', '.join(skipped)}" if skipped else "")
            + "); delete the run directory and retrain"
        )
    unread = f"{path}: newer checkpoints unreadable ({', '.join(skipped)}); resuming from {LATEST_CHECKPOINT}"
    return latest, state, unread if skipped else None


def latest_checkpoint(path: str | Path) -> Path:
    """``path`` if it is a file, else the run directory's ``latest.pt``, or its newest ``model_K.pt`` where
    it never wrote one (unread: see :func:`resume_checkpoint` for the checkpoint a resume reads)."""
    path = Path(path)
    if not path.is_dir():
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such checkpoint or run directory")
        return path
    if (path / LATEST_CHECKPOINT).exists():
        return path / LATEST_CHECKPOINT
    models = model_checkpoints(path)
    if not models:
        raise FileNotFoundError(
            f"{path}: no checkpoint ({LATEST_CHECKPOINT} or model_K.pt); give a run directory that "
            "'warpcut train' wrote"
        )
    return models[0]


def policy_checkpoint(path: str | Path) -> Path:
    """The checkpoint whose policy a run stands for: ``path`` if it is a file, else the run directory's
    ``best.pt`` (the validated best, when training validated) or its newest (:func:`latest_checkpoint`)."""
    path = Path(path)
    if path.is_dir() and (path / BEST_CHECKPOINT).exists():
        return path / BEST_CHECKPOINT
    return latest_checkpoint(path)


def policy_layout(actor_state: dict) -> tuple[int, int]:
    """``(observations, outputs)`` of an actor's state dict: the inputs of its MLP's first layer and the
    outputs of its last (discrete: actions times choices; continuous: the actions)."""
    layers = sorted(
        (int(match[1]), value)
        for key, value in actor_state.items()
        if (match := re.fullmatch(r"mlp\.(?:body\.)?(\d+)\.weight", key)) and value.ndim == 2
    )
    if not layers:
        raise ValueError("actor state: no MLP layers (mlp.K.weight); not an rsl-rl MLP actor")
    return int(layers[0][1].shape[1]), int(layers[-1][1].shape[0])


def layout_difference(saved: tuple[int, int], expected: tuple[int, int], source: str) -> str | None:
    """How a policy of layout ``saved`` (``(observations, outputs)``, :func:`policy_layout`) does not fit
    the ``expected`` one of ``source`` (e.g. "the env"), in words; None when they are the same."""
    if saved[0] != expected[0]:
        return f"policy expects {saved[0]} observations, {source} gives {expected[0]}"
    if saved[1] != expected[1]:
        return f"policy has {saved[1]} action outputs, {source} needs {expected[1]}"
    return None


def layout_mismatch(saved: dict, expected: dict, source: str) -> str | None:
    """How the actor state ``saved`` (a checkpoint's) does not fit the actor state ``expected`` (built for
    ``source``, e.g. "the env"), in words; None when every tensor has the shape expected."""
    difference = layout_difference(policy_layout(saved), policy_layout(expected), source)
    if difference:
        return difference
    if set(saved) != set(expected):
        keys = sorted(set(saved) ^ set(expected))
        return f"policy network differs from {source}'s ({', '.join(keys[:4])})"
    for key, value in expected.items():
        if tuple(saved[key].shape) != tuple(value.shape):
            shapes = f"{tuple(saved[key].shape)}, {source}'s {tuple(value.shape)}"
            return f"policy network differs from {source}'s ({key}: {shapes})"
    return None


def seed_everything(seed: int) -> None:
    """Seed Python's, NumPy's and torch's global generators."""
    random.seed(seed)
    np.random.seed(seed)  # noqa: NPY002 -- for any third-party code drawing from the global generator
    torch.manual_seed(seed)


def _mean_log_value(ep_extras: list[dict], key: str) -> float | None:
    """Mean of every value logged under ``key`` this iteration (scalars and tensors alike), or None."""
    values = [torch.as_tensor(e[key], dtype=torch.float).reshape(-1).cpu() for e in ep_extras if key in e]
    values = torch.cat(values) if values else torch.empty(0)
    return float(values.mean()) if values.numel() else None
