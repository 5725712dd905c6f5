"""warpcut's rsl-rl runner (:class:`Runner`): rsl-rl's ``OnPolicyRunner``, whose learning loop drives every
rsl-rl learner (es, PPO, gps, dagger: their algorithms are named by ``class_name``), with atomic,
self-describing checkpoints, a ``latest.pt`` copy, model selection on held-out episodes and a quiet logger
that hands each iteration's metrics to a callback. :func:`agents.training.train` builds it from the
learner's registry entry (:mod:`agents.algorithms`); APG's and gps's runners are subclasses.
"""

from __future__ import annotations

import contextlib
import io
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils.logger import Logger

from agents.checkpoints import BEST_CHECKPOINT, LATEST_CHECKPOINT, layout_mismatch, read_checkpoint
from agents.models import torch_threads
from envs.rsl import FINAL_ERROR_KEY
from warpcut.io import WriteFailed, enclosing_run, note_written, read_run_marker, write_atomic, write_json


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
        self.guarded_episodes: int | None = None
        """The first this many episodes of each validation are the ones a policy must not do worse on, on
        average, than the initial policy to be kept (gps: the nominal sheet's, beside the randomised ones);
        None: no such episodes."""
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
            write_run_file(path, data, "no checkpoint was saved yet", resumable=False)
        else:
            write_run_file(path, data, f"the previous checkpoint {previous.name} is intact")
        self.checkpoint = path
        write_run_file(
            path.with_name(LATEST_CHECKPOINT), data, f"{path.name} (the newest checkpoint) is intact"
        )
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
        eligible = self._guarded_ok(errors)
        if not eligible:
            self.validation[-1]["guarded_worse"] = True
        if self.logger.writer is not None:
            self.logger.writer.add_scalar("Validation/error", error, self.iterations_done)
        if eligible and (self.best_score is None or score < self.best_score):
            previous = self.best_error, self.best_score, self.best_iterations
            self.best_error, self.best_score, self.best_iterations = error, score, self.iterations_done
            if self.logger.log_dir is not None:
                best = Path(self.logger.log_dir) / BEST_CHECKPOINT
                intact = "none was saved before"
                if best.is_file():
                    intact = f"the previous {BEST_CHECKPOINT} is intact"
                try:
                    write_run_file(best, self._state_bytes(), intact)
                except ValueError:  # a full disk: the summary keeps naming the best.pt on disk
                    self.best_error, self.best_score, self.best_iterations = previous
                    raise
        return error

    def _guarded_ok(self, errors: float | np.ndarray) -> bool:
        """Whether a validation's :attr:`guarded_episodes` are, on average, no worse than the initial policy's
        on the same episodes (a mean paired difference ≤ 0: no margin for noise, since the initial policy is
        the one optimised for those episodes' sheet); True for the initial validation itself, or without
        guarded episodes."""
        n = self.guarded_episodes
        values = np.asarray(errors, dtype=np.float64)
        if not n or values.ndim == 0 or self.validation_baseline is None or len(self.validation) <= 1:
            return True
        difference = values.reshape(len(values), -1)[:n] - np.asarray(self.validation_baseline)[:n]
        difference = difference.reshape(n, -1)
        return bool(np.any(difference.mean(axis=0) <= 0.0))

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
            with torch_threads(threads):
                return update(*args, **kwargs)

        self.alg.update = update_on_all_threads
        try:
            with torch_threads(1):
                return super().learn(num_learning_iterations, init_at_random_ep_len)
        finally:
            self.alg.update = update

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
                f"{path}: does not fit these settings ({one_line(exc)[:200]}); resume with the run's own "
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


def _mean_log_value(ep_extras: list[dict], key: str) -> float | None:
    """Mean of every value logged under ``key`` this iteration (scalars and tensors alike), or None."""
    values = [torch.as_tensor(e[key], dtype=torch.float).reshape(-1).cpu() for e in ep_extras if key in e]
    values = torch.cat(values) if values else torch.empty(0)
    return float(values.mean()) if values.numel() else None


def one_line(exc: BaseException) -> str:
    """What an exception says, on one line (its type when it says nothing)."""
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


def write_run_file(path: Path, data: bytes | dict, intact: str, resumable: bool = True) -> None:
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
