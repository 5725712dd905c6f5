"""Training a tensioning policy: :func:`train` on any rsl-rl ``VecEnv`` (rsl-rl's ``OnPolicyRunner`` drives
es and PPO, :mod:`agents.apg.runner` APG), and :func:`train_contour`, which trains one on a warpcut scenario,
writes its run directory and evaluates it.

A run directory holds::

    config.json        the job (:class:`agents.jobs.TrainJob`: contour, pinch, seed, sim, env, train): give it
                       back to ``warpcut train --config`` to run it again
    options.json       the env's :class:`~envs.options.PatternCutOptions`, resolved (the pinch point, the
                       contour's points): what the policy acts in
    model_K.pt         checkpoint after learning iteration K (0-based, rsl-rl's naming), every save_interval;
                       each describes its policy (:mod:`agents.checkpoints`)
    latest.pt          copy of the newest checkpoint; a resume reads it (or, where it is missing, damaged or
                       older, the newest readable model_K.pt)
    best.pt            with validation: the checkpoint whose deterministic policy scored the lowest selection
                       score so far (the initial policy included); evaluation and export use it
    events.out.tfevents.*   TensorBoard scalars written by rsl-rl's logger
    summary.json       status (completed, interrupted, failed), iterations, env steps, speed, last metrics,
                       ``checkpoint`` (the newest one written whole), ``error`` (why a failed run stopped),
                       ``resumed_from``, ``history`` (every iteration's metrics), ``validation`` (the
                       validation scores) and ``best``; ``wall_time_s``: training seconds of the whole run,
                       the
                       runs before a resume included, ``run_wall_time_s``: this run's alone
    evaluation.json    the trained policy against no tension (:func:`agents.policies.evaluate_run`)

Checkpoints and JSON files are written atomically: a full disk is a ``ValueError`` naming the file, and the
previous file stays intact. Ctrl-C saves a checkpoint and an "interrupted" summary. A resumed run restarts the
episode it stopped in as that episode began, so an es run resumed at a checkpoint goes on exactly as one that
was never stopped.

The env is any :class:`rsl_rl.env.VecEnv` (``envs.rsl`` for warpcut). Beyond that contract, train() relies on:

- ``get_observations()`` / ``step()`` return a TensorDict with the group ``"policy"``.
- Discrete control: ``num_action_choices`` options per action (``num_actions`` actions per env, 1 for one
  choice per step); ``step()`` receives the indices as a float tensor ``(num_envs, num_actions)``.
  Continuous control: the env clips the actions.
- ``step()`` resets finished envs itself; ``dones`` (num_envs,) is 1 where an episode ended;
  ``extras["time_outs"]`` marks the episodes cut short by a limit the observation does not show.
- ``extras["log"]`` maps names to a scalar or a 1D tensor (rsl-rl logs the iteration's mean); each finished
  episode's final error goes under ``extras["log"][FINAL_ERROR_KEY]``, one value per env that finished.
- es also needs ``extras[EPISODE_COST_KEY]`` on the step where the batch's episode ends (:mod:`envs.rsl`).
- Optional: ``seed(seed)`` (reseed and reset every env), ``episode_start()`` / ``restart_episode(start)``
  (resume where the run stopped), ``common_sheets`` (es's common random numbers).
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import random
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils import resolve_callable
from rsl_rl.utils.logger import Logger

from agents.algorithms import ALGORITHMS, algorithm
from agents.checkpoints import (
    BEST_CHECKPOINT,
    LATEST_CHECKPOINT,
    layout_mismatch,
    read_checkpoint,
    resume_checkpoint,
    saved_nothing,
    start_from,
)
from agents.config import TrainConfig
from agents.config_io import flatten, to_plain
from agents.jobs import CONFIG_FILE
from agents.policies import (
    OPTIONS_FILE,
    RESUME_FIX,
    VALIDATION_SEED_OFFSET,
    check_layout,
    evaluate_run,
    policy_errors,
    same_contour,
)
from agents.progress import training_progress
from envs.options import PatternCutOptions
from envs.rsl import FINAL_ERROR_KEY, PatternCutRslEnv
from envs.vector import PatternCutVecEnv
from warpcut.io import (
    WriteFailed,
    claim_run_dir,
    enclosing_run,
    note_written,
    read_json,
    read_run_marker,
    write_atomic,
    write_json,
)
from warpcut.planning import check_pinch
from warpcut.sim.memory import batch_named

if TYPE_CHECKING:
    from agents.jobs import GeneralistJob, TrainJob
    from agents.methods import StepCallbacks


def train(
    env: VecEnv,
    cfg: TrainConfig,
    out_dir: str | Path,
    *,
    seed: int = 0,
    resume: str | Path | None = None,
    progress: bool = True,
    validate: Callable[[torch.nn.Module], float | np.ndarray] | None = None,
    label: str | None = None,
    marks: dict | None = None,
    init: str | Path | None = None,
) -> dict:
    """Train a policy on ``env`` with ``cfg``'s learner; write its checkpoints and summary into ``out_dir``.

    Ctrl-C saves a checkpoint and an "interrupted" summary, then re-raises the ``KeyboardInterrupt``.

    Args:
        env: The vectorized env (the module docstring's contract); seeded and reset here.
        cfg: The learner and its settings.
        out_dir: Run directory; created if needed.
        seed: Seed of Python, NumPy, torch and the env.
        resume: Run directory or checkpoint to continue from: loads the model, the optimiser, the iteration
            count and the episode stream, and trains until ``cfg``'s iterations in total.
        progress: Show a progress bar (on stderr).
        validate: Scores an actor (called with the live actor; use its deterministic output) on episodes
            that are not the evaluation's: the error of each episode, an array ``(episodes,)``, the same
            episodes every call. Called before training and every ``cfg.validation_interval`` iterations; the
            policy with the lowest selection score is saved as ``best.pt`` (model selection on held-out
            episodes; :attr:`TrainConfig.selection_margin`).
        label: The progress bar's label (default: the learner's name).
        marks: Fields the summary records as they are (e.g. whether the pinch point is feasible).
        init: A run or checkpoint whose policy the training starts from (fine-tuning; es; not on resume).

    Returns:
        The summary also written to ``out_dir/summary.json``.
    """
    discrete = getattr(env, "num_action_choices", None) is not None
    cfg.check(discrete)
    if env.num_envs != cfg.batch_size:
        raise ValueError(
            f"num_envs: the env has {env.num_envs} envs but the config asks for {cfg.batch_size}"
        )
    episode_steps = int(env.max_episode_length)
    iterations = cfg.total_iterations(episode_steps)
    out_dir = make_run_dir(out_dir)
    seed_everything(seed)
    from agents.models import feedback_inputs

    feedback = feedback_inputs(env) if cfg.feedback else None
    rsl_cfg = cfg.to_rsl_rl(getattr(env, "num_action_choices", None), feedback, episode_steps)
    runner_class = resolve_callable(algorithm(cfg.algo).runner)
    runner: Runner = runner_class(env, rsl_cfg, out_dir, cfg.torch_device)
    runner.selection_margin = cfg.selection_margin
    runner.algo, runner.seed = cfg.algo, seed
    if hasattr(env, "seed"):  # once the learner has set the env up (es: its common sheets)
        env.seed(seed)
    checkpoint, note = None, None
    if resume is not None:
        checkpoint, state, note = resume_checkpoint(resume)
        if note is not None:
            print(f"warning: {note}", file=sys.stderr)
        runner.load_checkpoint(checkpoint, state)
        runner.checkpoint = checkpoint if checkpoint.parent.resolve() == out_dir.resolve() else None
    elif init is not None:  # fine-tuning: es from another policy
        start_from(runner, init)
    start_iterations, status, steps = runner.iterations_done, "failed", runner.steps_per_iteration
    runner.started = time.monotonic()
    try:
        label = label or cfg.algo.upper()
        with training_progress(bool(progress), iterations, start_iterations, steps, label) as report:
            if validate is None:
                runner.on_iteration = report
            else:
                if resume is None or runner.best_error is None:
                    runner.validate(validate)

                def on_iteration(iterations_done: int, metrics: dict) -> None:
                    if iterations_done % cfg.validation_interval == 0 or iterations_done == iterations:
                        runner.validate(validate)
                    report(iterations_done, metrics)

                runner.on_iteration = on_iteration
            if iterations > start_iterations:
                runner.learn(iterations - start_iterations)
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
            "algo": cfg.algo,
            "iterations": runner.iterations_done,
            "target_iterations": iterations,
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
            **(marks or {}),
            **runner.own_summary,
            "validation": runner.validation,
            "history": runner.history,
            "best": _best(runner),
        }
        _write_summary(out_dir / "summary.json", summary, runner.checkpoint, ending)
    return summary


def _best(runner: Runner) -> dict | None:
    """The summary's ``best``: the iteration, validation error and score of the policy model selection
    kept; None without validation."""
    if runner.best_error is None:
        return None
    return {
        "iterations": runner.best_iterations,
        "validation_error": runner.best_error,
        "validation_score": runner.best_score,
    }


def _log_hparams(writer, cfg: TrainConfig, runner: Runner) -> None:
    """Log the run's settings and outcome to TensorBoard's HPARAMS tab (in the run's own event file, so
    runs compare side by side): scalar settings of ``cfg`` (lists as text), the last iteration's final
    error and return, and the kept policy's validation error."""
    from torch.utils.tensorboard.summary import hparams

    settings = {
        k: v if isinstance(v, int | float | str | bool) else json.dumps(v)
        for k, v in _flat(asdict(cfg)).items()
        if not (k.split(".")[0] in ALGORITHMS and k.split(".")[0] != cfg.algo)
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


def _flat(settings: dict, prefix: str = "") -> dict:
    """Nested settings as one level of dotted keys."""
    flat = {}
    for key, value in settings.items():
        if isinstance(value, dict):
            flat.update(_flat(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


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
        ValueError: The OS refused the write (a full disk, a quota, a file-size limit, a read-only or
            unwritable folder, an I/O error; the ``OSError`` is its cause): the message names ``path``, why,
            what is ``intact`` (e.g. "the previous checkpoint model_4.pt is intact") and the run directory to
            resume from (``resumable``) or that the run must start again.
    """
    try:
        write_atomic(path, data) if isinstance(data, bytes) else write_json(path, data)
    except WriteFailed as exc:
        root = enclosing_run(path) or path.parent
        then = "start again" if not resumable else f"resume from {path.parent}"
        if resumable and Path(root).resolve() != path.parent.resolve():  # a policy of a run's: resume the run
            command = (read_run_marker(root) or {}).get("command") or "COMMAND"
            then = f"resume the run: warpcut {command} ... --out {root} --resume"
        raise ValueError(
            f"{path}: not written, {exc.reason}; {intact}: {exc.fix}, then {then}"
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
    """rsl-rl's on-policy runner with atomic, self-describing checkpoints, a ``latest.pt`` copy, model
    selection on held-out episodes and a per-iteration callback.

    Attributes:
        algo: The learner's name (:data:`agents.algorithms.ALGORITHMS`), recorded in checkpoints.
        iterations_done: Learning iterations completed, including those before a resume.
        metrics: Last iteration's ``final_error`` (the mean over the cuts that ended of their path error over
            the intended area), ``mean_return``, ``mean_episode_length`` (None until an episode ends),
            ``iteration_steps_per_s`` and the learner's own, every metric its update returns (e.g. es's
            ``population_cost``, dagger's ``imitation_loss``).
        checkpoint: Newest checkpoint written, or None.
        on_iteration: Called with ``(iterations_done, metrics)`` after each iteration.
    """

    def __init__(self, env: VecEnv, train_cfg: dict, log_dir: str | Path | None, device: str = "cpu") -> None:
        log_dir = None if log_dir is None else str(log_dir)
        # rsl-rl prints the models and observation sets; the checkpoints record them instead.
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
        self.algo = ""
        self.seed = 0
        """The run's seed (:func:`train` sets it), for a learner that draws episodes of its own."""
        self.own_summary: dict = {}
        """Fields of the learner's own that the run's summary records (e.g. gps's teacher)."""
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
        """Training seconds of the runs before this one, up to the checkpoint it resumed (0 for a new run)."""
        self.started = time.monotonic()
        """When this run's training started (:func:`train` sets it); checkpoints record the time since."""
        obs = self.env.get_observations()
        self.policy_description = {
            "actor": self.cfg["actor"],
            "obs_groups": self.cfg["obs_groups"],
            "obs_shapes": {group: list(obs[group].shape[1:]) for group in obs.keys()},
            "num_actions": int(self.env.num_actions),
            "num_action_choices": getattr(self.env, "num_action_choices", None),
        }
        """What a checkpoint's ``policy`` holds: enough to rebuild the actor (:func:`agents.policies.
        load_policy`)."""

    def wall_time(self) -> float:
        """Training seconds so far, the runs before a resume included."""
        return (self.earlier_wall_time or 0.0) + time.monotonic() - self.started

    def _state_bytes(self, infos: dict | None = None) -> bytes:
        state = self.alg.save()
        state["iter"] = self.current_learning_iteration
        state["algo"] = self.algo
        state["policy"] = self.policy_description
        state["infos"] = {
            "iterations_done": self.iterations_done,
            "validation": self.validation,
            "history": self.history,
            "best_error": self.best_error,
            "best_score": self.best_score,
            "best_iterations": self.best_iterations,
            "validation_baseline": self.validation_baseline,
            "wall_time_s": None if self.earlier_wall_time is None else self.wall_time(),
            "episode_start": self.env.episode_start() if hasattr(self.env, "episode_start") else None,
            "own_summary": self.own_summary,
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
        for events in path.parent.glob("events.out.tfevents.*"):  # rsl-rl's TensorBoard writer's files
            note_written(events, written=True)

    def validate(self, validate: Callable[[torch.nn.Module], float | np.ndarray]) -> float:
        """Score the deterministic policy with ``validate``; save ``best.pt`` if its selection score (see
        :meth:`_selection_score`) is the lowest yet. Returns the validation error."""
        actor = self.alg.get_policy()
        was_training = actor.training
        actor.eval()
        try:
            with torch.inference_mode():
                errors = validate(actor)
        finally:
            actor.train(was_training)
        error, score = self._selection_score(errors)
        self.validation.append({"iterations": self.iterations_done, "error": error, "score": score})
        if self.logger.writer is not None:
            self.logger.writer.add_scalar("Validation/error", error, self.iterations_done)
        if self.best_score is None or score < self.best_score:
            previous = self.best_error, self.best_score, self.best_iterations
            self.best_error, self.best_score, self.best_iterations = error, score, self.iterations_done
            if self.logger.log_dir is not None:
                best = Path(self.logger.log_dir) / BEST_CHECKPOINT
                intact = "none was saved before"
                if best.is_file():
                    intact = f"the previous {BEST_CHECKPOINT} is intact"
                try:
                    _write(best, self._state_bytes(), intact)
                except ValueError:  # a full disk: the summary keeps naming the best.pt on disk
                    self.best_error, self.best_score, self.best_iterations = previous
                    raise
        return error

    def _selection_score(self, errors: float | np.ndarray) -> tuple[float, float]:
        """``(error, score)`` of one validation: the mean error, and the score model selection minimises. The
        first per-episode validation is the baseline (the initial policy); a later one scores ``mean +
        selection_margin * SE`` of its episodes' paired differences from the baseline's. A scalar validation
        scores its value."""
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
        threads for the update (on a CPU): the simulator steps the envs on threads of its own, and torch
        threads spinning beside them cost more than they gain (docs/performance.md)."""
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
        """Load models, optimizer and learning rate; continue the iteration count after the checkpoint's and
        the episode stream where it stopped (the env restarts the episode the checkpoint was saved in).

        Args:
            path: The checkpoint (named in errors).
            state: Its contents, if already read (:func:`~agents.checkpoints.resume_checkpoint`); default:
                read ``path``.

        Raises:
            ValueError: ``path`` is not a readable checkpoint, or of another learner, or its policy does not
                fit this env (e.g. another number of observations) or network.
        """
        path = Path(path)
        state = read_checkpoint(path, map_location=self.device) if state is None else state
        if state.get("algo") != self.algo:
            raise ValueError(
                f"{path}: a checkpoint of {state.get('algo')!r}, not of {self.algo!r}; resume it with its "
                "own "
                f"algo (train.algo={state.get('algo')}), or start a new run"
            )
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
                f"{path}: does not fit these settings ({_one_line(exc)[:200]}); resume with the run's own "
                "settings (its config.json), or start a new run"
            ) from None
        infos = state.get("infos") or {}
        # rsl-rl would repeat the checkpoint's iteration; continue after it instead.
        self.iterations_done = infos.get("iterations_done", state["iter"] + 1)
        self.current_learning_iteration = self.iterations_done
        self.validation = list(infos.get("validation") or [])
        self.history = list(infos.get("history") or [])
        self.best_error = infos.get("best_error")
        self.best_score = infos.get("best_score", self.best_error)
        self.best_iterations = infos.get("best_iterations")
        self.validation_baseline = infos.get("validation_baseline")
        self.earlier_wall_time = infos.get("wall_time_s")
        self.own_summary = dict(infos.get("own_summary") or {})
        start = infos.get("episode_start")
        if start is not None and hasattr(self.env, "restart_episode"):
            self.env.restart_episode(start)

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
        own = {k: float(v) for k, v in (kwargs.get("loss_dict") or {}).items()}  # the learner's own
        self.on_iteration(
            it,
            {
                "final_error": final_error,
                "mean_return": statistics.mean(self.rewbuffer) if self.rewbuffer else None,
                "mean_episode_length": statistics.mean(self.lenbuffer) if self.lenbuffer else None,
                "iteration_steps_per_s": steps / (collect_time + learn_time),
                "collection_steps_per_s": steps / collect_time,
                **own,
            },
        )

    def _store_code_state(self) -> list[str]:
        return []


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


def train_contour(
    job: TrainJob,
    out_dir: str | Path,
    *,
    resume: str | Path | None = None,
    device: str | None = None,
    progress: bool = True,
    step_callbacks: StepCallbacks | None = None,
    label: str | None = None,
) -> dict:
    """Train ``job``'s policy for its contour into ``out_dir``, then evaluate it against no tension.

    With ``job.train.validation_trials > 0`` the deterministic policy is scored on that many held-out
    episodes (seed ``job.seed + VALIDATION_SEED_OFFSET``) before training and every ``validation_interval``
    iterations, and the best one is the run's policy (``best.pt``; see :func:`train`).

    Args:
        job: The contour, pinch point, segments, physics, env and learner (:class:`agents.jobs.TrainJob`).
        out_dir: Run directory: ``config.json`` (the job, the pinch point resolved), ``options.json``, the
            checkpoints, ``summary.json`` and ``evaluation.json``.
        resume: Run directory or checkpoint to continue from; the job must be the run's own (its
            ``config.json``), but for ``train.iterations`` (train for longer) and the outputs.
        device: The simulator's Warp device (not saved: a run evaluates on any device).
        progress: Show the progress bar.
        step_callbacks: Step callbacks of the final evaluation's batches (see
            :func:`agents.policies.evaluate_run`).
        label: The progress bar's label (default: "ALGO CONTOUR", e.g. "ES fls-circle").

    Returns:
        ``{"summary": training summary, "evaluation": evaluation of the run's policy}``.

    Raises:
        ValueError: A setting out of range (named), ``resume`` holds no readable checkpoint, or the job is
            not the resumed run's.
    """
    with claim_run_dir(out_dir, command="train", resume=resume is not None):
        return _train_contour(job, Path(out_dir), resume, device, progress, step_callbacks, label)


def _train_contour(
    job: TrainJob,
    out_dir: Path,
    resume: str | Path | None,
    device: str | None,
    progress: bool,
    step_callbacks: StepCallbacks | None,
    label: str | None,
) -> dict:
    options = job.options(device)
    cfg = job.train.check(options.action_type == "discrete")
    if job.init is not None and not algorithm(cfg.algo).fine_tunes:
        which = ", ".join(name for name, entry in ALGORITHMS.items() if entry.fine_tunes)
        raise ValueError(f"init: fine-tuning starts {which} from a generalist; train.algo is {cfg.algo}")
    if resume is not None:  # before anything is written: a resume with other settings changes nothing
        check_resumed_job(resume, job)
    if resume is not None and saved_nothing(resume):
        resume = None  # stopped before its first checkpoint: it starts again, with its own settings
    if resume is not None:
        checkpoint, state, _ = resume_checkpoint(resume)
        check_layout(state["actor_state_dict"], checkpoint, options, "the env", RESUME_FIX)
    contours, points, cuts = options.per_env(1)  # an infeasible pinch point, unless allowed: refused now
    pinch = [float(v) for v in points[0]]
    options = dataclasses.replace(options, pinch_point=pinch)
    problem = check_pinch(points[0], contours[0], options.config(), cuts and cuts[0], options.arm, allow=True)
    env = training_env(options, cfg, job.seed)  # before anything is written: options the env refuses
    resolved = dataclasses.replace(job, contour=options.to_dict()["contour"], pinch=pinch)
    write_json(out_dir / CONFIG_FILE, to_plain(resolved))
    write_json(out_dir / OPTIONS_FILE, dataclasses.replace(options, device=None).to_dict())
    validate = None
    if cfg.validation_trials > 0:
        fix = "set train.validation_trials to at most {fits} (0: none)"
        with batch_named("train.validation_trials", fix):
            validation_env = PatternCutVecEnv(cfg.validation_trials, options)

        def validate(actor: torch.nn.Module) -> np.ndarray:
            """Validation errors (vertices), one per episode; weighed by the reward's scale with
            ``relative_reward`` (a flat sheet's error counts as the reward counts it)."""
            errors = policy_errors(actor, validation_env, job.seed + VALIDATION_SEED_OFFSET)["error_vertices"]
            return errors * validation_env.scene.reward_scale if options.relative_reward else errors

    label = label or f"{cfg.algo.upper()} {options.contours(1)[0].name}"
    marks = {"pinch_feasible": problem is None, "pinch_problem": problem}
    init = None
    if job.init is not None:
        from agents.generalist import generalist_dir

        init = generalist_dir(job.init)
        marks["init"] = job.init
    summary = train(
        env, cfg, out_dir, seed=job.seed, resume=resume, progress=progress, validate=validate, label=label,
        marks=marks, init=init,
    )  # fmt: skip
    evaluation = evaluate_run(
        out_dir, trials=job.eval_trials, seed=job.seed + 1, device=device, step_callbacks=step_callbacks
    )
    write_json(out_dir / "evaluation.json", evaluation)
    return {"summary": summary, "evaluation": evaluation}


RESUMABLE_CHANGES = ("train.iterations", "record", "colour_by", "video", "plots")
"""The settings of a job that a resume may change (train for longer; what the run writes besides); the rest
must be the run's own."""


def check_resumed_job(resume: str | Path, job: TrainJob | GeneralistJob) -> None:
    """A ``ValueError`` naming the first setting in which ``job`` (train's or a generalist's) differs from the
    run ``resume`` (a run
    directory or one of its checkpoints) was started with (its ``config.json``), but for
    :data:`RESUMABLE_CHANGES`; nothing for a run without a ``config.json`` of a job. A setting its
    ``config.json`` lacks (one added since) counts as the default."""
    run = Path(resume) if Path(resume).is_dir() else Path(resume).parent
    path = run / CONFIG_FILE
    if not path.is_file():
        return
    saved = flatten(read_json(path))
    given = flatten(to_plain(job))
    if "pinch" in saved and job.pinch is None:  # the run's own pinch point, found when it started
        given["pinch"] = saved["pinch"]
    if isinstance(saved.get("contour"), dict) or isinstance(given.get("contour"), dict):
        from warpcut.planning import resolve_contour

        saved_contour = None if saved.get("contour") is None else resolve_contour(saved["contour"])
        if None not in (saved_contour, job.contour) and same_contour(
            saved_contour, resolve_contour(job.contour)
        ):
            given["contour"] = saved.get("contour")
    defaults = flatten(to_plain(type(job)()))
    for key in sorted(set(saved) | set(given)):
        if key in RESUMABLE_CHANGES or saved.get(key, defaults.get(key)) == given.get(key):
            continue
        raise ValueError(
            f"{key}: the resumed run {run} has {saved.get(key)!r} (its {CONFIG_FILE}), this job "
            f"{given.get(key)!r}; a resumed run keeps its settings: drop the change, or start a new run"
        )


TRAIN_BATCH_FIX = "set train.num_envs (train: --num-envs) to at most {fits}"
"""What shrinks a training batch too big for memory, as :func:`warpcut.sim.memory.batch_named` says it."""


def training_env(
    options: PatternCutOptions,
    cfg: TrainConfig,
    seed: int = 0,
    batch: tuple[str, str | None] = ("train.num_envs", TRAIN_BATCH_FIX),
) -> PatternCutRslEnv:
    """The rsl-rl env a learner trains in: ``cfg``'s batch of envs of ``options``, seeded with ``seed``;
    ``batch``: the batch's name and fix where it does not fit in memory (:func:`warpcut.sim.memory.
    batch_named`)."""
    with batch_named(*batch):  # rsl-rl resets inside step
        env = PatternCutVecEnv(cfg.batch_size, options, autoreset_mode="same_step")
    return PatternCutRslEnv(env, torch_device=cfg.torch_device, seed=seed)
