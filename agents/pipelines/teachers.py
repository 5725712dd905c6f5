"""Teachers at scale (:func:`make_teachers`, ``warpcut teachers``): the dataset a generalist learns from by
supervised learning (guided policy search; :mod:`agents.dagger`).

For each of ``count`` generated contours (the ``train`` split, every kind in turn, the suite-like ones too:
:data:`warpcut.planning.generate.EXTRA_KINDS`) it plans the cut as ``warpcut evaluate`` plans it (pinch point,
segments and order: :func:`warpcut.planning.plan_cut`) and optimises the teacher there, the open-loop plan
``warpcut optimize --estimator es`` finds (:func:`agents.plan_optimizer.optimizer.cached_plan`). A contour is
a unit of work: on ``--ray`` the units run on the cluster's workers.

A dataset directory holds ``config.json`` (the job), ``teachers/NAME/`` per contour (``cut.json``: the
contour's points, pinch point and ordered segments; ``NAME.json``: the teacher's plan, its optimiser's history
and settings) and, once every unit is done, ``teachers.json``: the index, one row per contour with its kind,
its teacher's and the still grasp's validation errors (vertices, on the optimiser's held-out episodes) and the
seconds it took. An interrupted dataset resumes where it stopped (``--resume``): finished contours are read
back, a teacher stopped mid-optimisation continues from its state file; a resume with a larger ``count``
grows the dataset (the first contours are the same).
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from agents.cluster import Done, Executor, Serial
from agents.config_io import to_plain
from agents.jobs import CONFIG_FILE
from agents.teachers import CUT_FILE, FORMAT, INDEX_FILE, UNITS
from warpcut.contours import Contour
from warpcut.io import claim_run_dir, read_json, safe_name, write_json

if TYPE_CHECKING:
    from agents.jobs import TeachersJob


def make_teachers(
    job: TeachersJob,
    out: str | Path,
    *,
    resume: bool = False,
    device: str | None = None,
    log: Callable[[str], None] = lambda _: None,
    cluster: Executor | None = None,
) -> dict:
    """Build ``job``'s dataset into ``out`` (module docstring; claimed: :func:`warpcut.io.claim_run_dir`).

    Returns:
        The index (``teachers.json``).
    """
    with claim_run_dir(out, command="teachers", resume=resume):
        return _make_teachers(job.check(), Path(out), resume, device, log, cluster or Serial())


def _make_teachers(
    job: TeachersJob,
    out: Path,
    resume: bool,
    device: str | None,
    log: Callable[[str], None],
    cluster: Executor,
) -> dict:
    from agents.training import check_resumed_job
    from warpcut.planning.generate import generate_contours

    if resume and (out / CONFIG_FILE).is_file():  # its settings, but a dataset may grow (count)
        check_resumed_job(out, dataclasses.replace(job, count=read_json(out / CONFIG_FILE).get("count")))
    config = job.sim.validated()
    if job.near is not None:  # a student that cannot be played is refused before any work
        from agents.generalist import load_generalist

        load_generalist(job.near)
    write_json(out / CONFIG_FILE, to_plain(job))
    started = time.perf_counter()
    contours = generate_contours(job.count, "train", job.seed, config, job.kinds)
    dirs = [out / UNITS / safe_name(c.name) for c in contours]
    for folder in dirs:
        folder.mkdir(parents=True, exist_ok=True)
    unit = functools.partial(
        _teacher_unit, config=config, candidates=job.candidates, seed=job.seed, arm=job.arm, grad=job.grad,
        device=device, near=job.near, tether=job.tether,
    )  # fmt: skip
    count, finished = len(contours), iter(range(1, len(contours) + 1))
    if cluster.address is not None:
        log(f"  {count} teacher(s) on {cluster.workers} worker(s)")

    def start(k: int) -> None:
        log(f"  [{k + 1}/{count}] {contours[k].name}")

    def done(k: int, result: Done) -> None:
        row = result.value
        log(
            f"  [{next(finished)}/{count}] {row['contour']}: teacher {row['error_vertices']:.1f} vertices, "
            f"still grasp {row['still_error_vertices']:.1f} ({result.seconds:.0f} s on {result.ran_on})"
        )

    made = cluster.map(unit, contours, dirs=dirs, done=done, start=start)
    rows = [{**m.value, "ran_on": m.ran_on, "unit_seconds": round(m.seconds, 2)} for m in made]
    index = {
        "format": FORMAT,
        "count": count,
        "seconds": round(time.perf_counter() - started, 1),
        "teacher_seconds": round(sum(r["seconds"] for r in rows), 1),
        "mean_error_vertices": float(np.mean([r["error_vertices"] for r in rows])),
        "mean_still_error_vertices": float(np.mean([r["still_error_vertices"] for r in rows])),
        **(
            {"mean_start_error_vertices": float(np.mean([r["start_error_vertices"] for r in rows]))}
            if job.near is not None
            else {}
        ),
        "contours": rows,
    }
    write_json(out / INDEX_FILE, index)
    return index


def _teacher_unit(
    contour: Contour,
    folder: Path | None,
    *,
    config,
    candidates: int,
    seed: int,
    arm,
    grad,
    device,
    near: str | None = None,
    tether: float = 0.0,
) -> dict:
    """One contour's cut and teacher, kept in ``folder`` (a unit of :func:`make_teachers`): its index row.
    With ``near``, the teacher starts from that generalist's moves on the cut, tethered to them by
    ``tether`` (:class:`agents.jobs.TeachersJob`)."""
    from agents.plan_optimizer.config import GRAD_SEED_OFFSET
    from agents.plan_optimizer.optimizer import cached_plan
    from warpcut.planning import plan_cut

    cut_file = folder / CUT_FILE
    if cut_file.is_file():
        cut = read_json(cut_file)
    else:
        plan = plan_cut(contour, config, num_candidates=candidates, seed=seed, device=device, arm=arm)
        cut = {
            "contour": {
                "name": contour.name, "closed": bool(contour.closed),
                "points": np.asarray(contour.points).tolist(),
            },
            "pinch": [float(v) for v in plan.chosen["pinch"]],
            "segments": [np.asarray(s).tolist() for s in plan.ordered_segments()],
        }  # fmt: skip
        write_json(cut_file, cut)
    segments = [np.asarray(s, dtype=np.float64) for s in cut["segments"]]
    anchor = None
    if near is not None:
        from agents.generalist import load_generalist, student_moves

        student = load_generalist(near)
        anchor = student_moves(
            student, contour, np.asarray(cut["pinch"]), segments, config, seed + GRAD_SEED_OFFSET, device
        )
    result = cached_plan(
        contour, np.asarray(cut["pinch"]), segments, config, grad, device, seed, folder, arm=arm,
        anchor=anchor, tether=tether,
    )  # fmt: skip
    history = result.history
    start = {} if near is None else {"start_error_vertices": float(history[0]["validation_error_vertices"])}
    return {
        "contour": contour.name,
        "kind": contour.name.rsplit("-", 1)[-1],
        "pinch": cut["pinch"],
        "segments": len(segments),
        "steps": len(result.plan),
        "error_vertices": float(history[result.best_iteration]["validation_error_vertices"]),
        "still_error_vertices": float(
            history[0].get("still_error_vertices", history[0]["validation_error_vertices"])
        ),
        **start,
        "best_iteration": result.best_iteration,
        "seconds": round(result.seconds, 2),
    }


__all__ = ["make_teachers"]
