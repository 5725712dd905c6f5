"""Training a tensioning policy: :func:`train` on any rsl-rl ``VecEnv`` (warpcut's rsl-rl runner,
:class:`agents.runner.Runner`, drives es and PPO, :mod:`agents.apg.runner` APG), and :func:`train_contour`,
which trains one on a warpcut scenario, writes its run directory and evaluates it.

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

import dataclasses
import json
import random
import sys
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch
from rsl_rl.env import VecEnv
from rsl_rl.utils import resolve_callable

from agents.algorithms import ALGORITHMS, algorithm
from agents.checkpoints import (
    resume_checkpoint,
    saved_nothing,
    start_from,
)
from agents.config import TrainConfig
from agents.config_io import flatten, to_plain
from agents.jobs import CONFIG_FILE
from agents.models import feedback_inputs
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
from agents.runner import Runner, one_line, write_run_file
from envs.options import PatternCutOptions
from envs.rsl import PatternCutRslEnv
from envs.vector import PatternCutVecEnv
from warpcut.io import (
    claim_run_dir,
    read_json,
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
    init_gain: float = 1.0,
    guarded_episodes: int | None = None,
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
            episodes every call, before training and every ``cfg.validation_interval`` iterations; the policy
            with the lowest selection score is ``best.pt`` (:attr:`TrainConfig.selection_margin`).
        label: The progress bar's label (default: the learner's name).
        marks: Fields the summary records as they are (e.g. whether the pinch point is feasible).
        init, init_gain: A run or checkpoint whose policy, its moves times ``init_gain``, the training starts
            from (fine-tuning; es; not on resume).
        guarded_episodes: :attr:`agents.runner.Runner.guarded_episodes` (the nominal sheet's, first).

    Returns:
        The summary also written to ``out_dir/summary.json``.
    """
    cfg.check(getattr(env, "num_action_choices", None) is not None)  # discrete moves
    if env.num_envs != cfg.batch_size:
        raise ValueError(
            f"num_envs: the env has {env.num_envs} envs but the config asks for {cfg.batch_size}"
        )
    episode_steps = int(env.max_episode_length)
    iterations = cfg.total_iterations(episode_steps)
    out_dir = make_run_dir(out_dir)
    seed_everything(seed)
    feedback = feedback_inputs(env) if cfg.feedback else None
    rsl_cfg = cfg.to_rsl_rl(getattr(env, "num_action_choices", None), feedback, episode_steps)
    runner_class = resolve_callable(algorithm(cfg.algo).runner)
    runner: Runner = runner_class(env, rsl_cfg, out_dir, cfg.torch_device)
    runner.selection_margin, runner.guarded_episodes = cfg.selection_margin, guarded_episodes
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
        start_from(runner, init, init_gain)
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
            "error": None if ending is None or isinstance(ending, KeyboardInterrupt) else one_line(ending),
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


def _write_summary(path: Path, summary: dict, checkpoint: Path | None, ending: BaseException | None) -> None:
    """Write ``summary.json``; on a full disk, while an exception (``ending``) ends the run, keep that
    exception (the checkpoints on disk still say where to resume) and note on it that the summary was not
    updated."""
    intact = f"the newest checkpoint {checkpoint.name} is intact" if checkpoint else "no checkpoint was saved"
    try:
        write_run_file(path, summary, intact, resumable=checkpoint is not None)
    except ValueError as exc:
        if ending is None or not isinstance(exc.__cause__, OSError):
            raise
        ending.add_note(str(exc))


def seed_everything(seed: int) -> None:
    """Seed Python's, NumPy's and torch's global generators."""
    random.seed(seed)
    np.random.seed(seed)  # noqa: NPY002 -- for any third-party code drawing from the global generator
    torch.manual_seed(seed)


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
    if job.at_generalists_cut and resume is None:
        job, options = _where_the_generalist_plays(job, options, device)
    if resume is not None:
        checkpoint, state, _ = resume_checkpoint(resume)
        check_layout(state["actor_state_dict"], checkpoint, options, "the env", RESUME_FIX)
    contours, points, cuts = options.per_env(1)  # an infeasible pinch point, unless allowed: refused now
    pinch = [float(v) for v in points[0]]
    options = dataclasses.replace(options, pinch_point=pinch)
    problem = check_pinch(points[0], contours[0], options.config(), cuts and cuts[0], options.arm, allow=True)
    trained_on, validated_on = learner_sheets(cfg, options)
    env = training_env(trained_on, cfg, job.seed)  # before anything is written: options the env refuses
    resolved = dataclasses.replace(job, contour=options.to_dict()["contour"], pinch=pinch)
    write_json(out_dir / CONFIG_FILE, to_plain(resolved))
    write_json(out_dir / OPTIONS_FILE, dataclasses.replace(options, device=None).to_dict())
    validate = None
    # beside randomised sheets, the nominal sheet's episodes (the first set) are guarded: a policy that does
    # worse there than the initial one is not kept, whatever it gains on the randomised ones
    guarded = cfg.validation_trials if len(validated_on) > 1 else None
    if cfg.validation_trials > 0:
        fix = "set train.validation_trials to at most {fits} (0: none)"
        with batch_named("train.validation_trials", fix):
            validation_envs = [PatternCutVecEnv(cfg.validation_trials, sheet) for sheet in validated_on]

        def validate(actor: torch.nn.Module) -> np.ndarray:
            """Validation errors (vertices), one per episode (of each set of held-out episodes in turn);
            weighed by the reward's scale with ``relative_reward`` (a flat sheet's error counts as the reward
            counts it)."""
            errors = []
            for validation_env in validation_envs:
                seed = job.seed + VALIDATION_SEED_OFFSET
                error = policy_errors(actor, validation_env, seed)["error_vertices"]
                errors.append(error * validation_env.scene.reward_scale if options.relative_reward else error)
            return np.concatenate(errors)

    label = label or f"{cfg.algo.upper()} {options.contours(1)[0].name}"
    marks = {"pinch_feasible": problem is None, "pinch_problem": problem}
    init = None
    if job.init is not None:
        from agents.generalist import generalist_dir

        init = generalist_dir(job.init)
        marks["init"], marks["init_gain"] = job.init, job.init_gain
    summary = train(
        env, cfg, out_dir, seed=job.seed, resume=resume, progress=progress, validate=validate, label=label,
        marks=marks, init=init, init_gain=job.init_gain, guarded_episodes=guarded,
    )  # fmt: skip
    evaluation = evaluate_run(
        out_dir, trials=job.eval_trials, seed=job.seed + 1, device=device, step_callbacks=step_callbacks
    )
    write_json(out_dir / "evaluation.json", evaluation)
    return {"summary": summary, "evaluation": evaluation}


def _where_the_generalist_plays(
    job: TrainJob, options: PatternCutOptions, device: str | None
) -> tuple[TrainJob, PatternCutOptions]:
    """``job`` (fine-tuning, with no pinch point or segments given) at the cut where its generalist plays
    the contour (:func:`agents.generalist.generalist_cut`), and its options."""
    from agents.generalist import generalist_cut, load_generalist

    contour = options.contours(1)[0]
    pinch, segments = generalist_cut(
        load_generalist(job.init), contour, job.sim.validated(), job.seed, device, job.arm
    )
    cut = [np.asarray(s).tolist() for s in segments]
    job = dataclasses.replace(job, pinch=[float(v) for v in pinch], segments=cut)
    return job, job.options(device)


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


def learner_sheets(cfg: TrainConfig, options: PatternCutOptions):
    """``(training, validation)``: the options of the env ``cfg``'s learner trains on and of each set of
    held-out episodes it is validated on: the learner's own (its settings' ``sheets``, :mod:`agents.
    algorithms`), else ``options`` for both."""
    sheets = getattr(cfg.learner, "sheets", None)
    return sheets(options) if sheets is not None else (options, [options])


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
