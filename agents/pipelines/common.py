"""What the pipelines share: their run directory's claim and settings (``config.json``, checked on resume),
the policies they train (:func:`train_policy`, a training run per contour or pinch candidate, kept when a
resumed pipeline finds it finished), and the analytic controller's pinch points."""

from __future__ import annotations

import dataclasses
import functools
import inspect
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.config import ANALYTIC_PINCHES
from agents.config_io import flatten, to_plain
from agents.jobs import CONFIG_FILE, OUTPUT_KEYS, TrainJob
from envs.options import PatternCutOptions
from warpcut.contours import Contour
from warpcut.io import claim_run_dir, read_json, write_json
from warpcut.planning import Plan


class TrainingInterrupted(KeyboardInterrupt):
    """Ctrl-C while a pipeline trained a policy: the checkpoint is saved in ``run_dir``."""

    def __init__(self, run_dir: Path):
        super().__init__(str(run_dir))
        self.run_dir = run_dir


def train_policy(
    job: TrainJob,
    run_dir: Path,
    *,
    device: str | None,
    progress: bool,
    resume: bool = False,
    label: str | None = None,
) -> dict:
    """Train ``job``'s policy into ``run_dir`` (:func:`agents.training.train_contour`); Ctrl-C (or SIGTERM,
    SIGHUP: see the CLI) raises :class:`TrainingInterrupted` naming the run directory. Returns the training
    summary.

    With ``resume`` a run already completed in ``run_dir`` is kept (its summary returned), and one that was
    interrupted continues from its checkpoint; without a checkpoint it starts again."""
    from agents.training import train_contour

    if resume and finished_run(run_dir):
        return read_json(Path(run_dir) / "summary.json")
    checkpoint = resume and any(Path(run_dir).glob("*.pt"))
    try:
        result = train_contour(
            job,
            run_dir,
            resume=run_dir if checkpoint else None,
            device=device,
            progress=progress,
            label=label,
        )
        return result["summary"]
    except KeyboardInterrupt as interrupt:
        raise TrainingInterrupted(run_dir) from interrupt


def policy_job(
    options: PatternCutOptions, job: Any, seed: int, eval_trials: int, **scenario: Any
) -> TrainJob:
    """The training job of a pipeline's policy: ``job``'s learner and env on ``options`` with the
    ``scenario`` fields (``contour``, ``pinch_point``, ``segments``) replaced."""
    options = dataclasses.replace(options, **scenario)
    return TrainJob.for_options(options, job.train, seed=seed, eval_trials=eval_trials)


def finished_run(run_dir: str | Path) -> bool:
    """Whether ``run_dir`` holds a training run that completed and was evaluated (a pipeline's ``resume``
    keeps it)."""
    run_dir = Path(run_dir)
    summary, evaluation = run_dir / "summary.json", run_dir / "evaluation.json"
    if not (summary.is_file() and evaluation.is_file()):
        return False
    return read_json(summary).get("status") == "completed"


def claims_out(command: str) -> Callable[[Callable], Callable]:
    """Run the pipeline it decorates with its run directory ``out`` claimed for ``command``
    (:func:`warpcut.io.claim_run_dir` with its ``resume`` and ``overwrite`` arguments): marked as a run of
    ``command``, locked against a second process, and refused if it holds another run or files warpcut
    did not write."""

    def decorate(pipeline: Callable) -> Callable:
        signature = inspect.signature(pipeline)

        @functools.wraps(pipeline)
        def claimed(*args, **kwargs):
            bound = signature.bind(*args, **kwargs)
            bound.apply_defaults()
            given = bound.arguments
            with claim_run_dir(
                given["out"], command=command, resume=given["resume"], overwrite=given["overwrite"]
            ):
                return pipeline(*args, **kwargs)

        return claimed

    return decorate


def record_job(out: Path, job: Any, resume: bool) -> None:
    """Write ``out/config.json`` (the job); with ``resume``, first check that ``job`` is the one the run was
    started with, but for what it writes besides its results (:data:`agents.jobs.OUTPUT_KEYS`): a
    ``ValueError`` names each difference."""
    path = out / CONFIG_FILE
    plain = to_plain(job)
    if resume and path.is_file():
        before, now = flatten(read_json(path)), flatten(plain)
        changed = [
            k for k in sorted(set(before) | set(now)) if before.get(k) != now.get(k) and k not in OUTPUT_KEYS
        ]
        if changed:
            shown = "; ".join(f"{k}: {before.get(k)!r} then, {now.get(k)!r} now" for k in changed[:6])
            raise ValueError(
                f"--resume: {out} was started with other settings ({shown}); repeat the run's settings "
                f"(--config {path}), or start a new run (another --out, or --overwrite)"
            )
    write_json(path, plain)


def analytic_pinches(mode: str, contours: Sequence[Contour], plans: Sequence[Plan] | None) -> list | None:
    """Per contour, the analytic policy's pinch point for ``mode`` (:data:`ANALYTIC_PINCHES`); None: its own
    default, the feasible centroid without an arm footprint."""
    if mode not in ANALYTIC_PINCHES:
        raise ValueError(f"analytic_pinch: choose one of {', '.join(ANALYTIC_PINCHES)} (got {mode!r})")
    if mode == "centroid":
        return [np.asarray(c.centroid, dtype=np.float64) for c in contours]
    return None if plans is None else [p.analytic_pinch for p in plans]


def policy_kept(run_dir: Path) -> str | None:
    """What a training run's model selection kept: ``"still"`` (the still grasp: fixed tension), ``"plan"``
    (gps's teacher played open loop) or ``"trained"`` (a policy its learner moved); None where the run has
    no summary."""
    path = Path(run_dir) / "summary.json"
    if not path.is_file():
        return None
    kept = read_json(path).get("kept")  # gps names it; the others start from the still grasp
    if kept in ("still", "plan"):
        return kept
    if kept == "student":
        return "trained"
    return "still" if policy_iteration(run_dir) == 0 else "trained"


def policy_iteration(run_dir: Path) -> int | None:
    """The iteration whose policy a training run kept (0: the initial policy): the validated best, or the
    last without validation; None where the run has no summary."""
    path = Path(run_dir) / "summary.json"
    if not path.is_file():
        return None
    summary = read_json(path)
    return int(summary["best"]["iterations"] if summary.get("best") else summary["iterations"])
