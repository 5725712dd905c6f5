"""One contour's optimised plan, :func:`optimize_contour` (``warpcut optimize``): plan the cut, optimise
a plan of grasp moves at the chosen pinch point through the simulator
(:func:`agents.plan_optimizer.optimizer.optimize_plan`), and evaluate it against no tension and fixed tension
there."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from agents.evaluation import Method, evaluate_suite
from agents.jobs import OptimizeJob
from agents.pipelines.common import claims_out, record_job
from agents.plan_optimizer.optimizer import grad_result
from warpcut.io import write_json
from warpcut.planning import check_pinch, plan_cut, resolve_contour

RESULTS_FILE = "results.json"
"""The run directory's report (:func:`optimize_contour`'s)."""


@claims_out("optimize")
def optimize_contour(
    job: OptimizeJob,
    out: str | Path,
    *,
    resume: bool = False,
    overwrite: bool = False,
    device: str | None = None,
    log: Callable[[str], None] = lambda _: None,
) -> dict:
    """Plan ``job.contour``'s cut (segments, order and, unless ``job.pinch`` is given, the pinch point: fixed
    tension's best of ``job.candidates``), optimise a plan there with ``job.grad``, and evaluate it against
    no tension and fixed tension at the same pinch point over ``job.trials`` seeded noisy trials (paired).

    Args:
        job: The contour, pinch point, physics, optimiser and evaluation (:class:`agents.jobs.OptimizeJob`).
        out: Run directory: ``config.json`` (the job), the plan (``NAME.json``), the optimiser's state while
            it runs (``NAME.state.json``: an interrupted optimisation continues from it) and
            ``results.json``. Locked while it runs; refused if it holds another run
            (:func:`warpcut.io.claim_run_dir`).
        resume: Continue the run in ``out`` (started with the same job): a finished plan is kept, an
            interrupted optimisation continues from its state.
        overwrite: Delete what ``out`` holds first.
        device: Warp device.
        log: Called with each progress line.

    Returns:
        ``{"contour", "pinch", "pinch_feasible", "pinch_problem" (why the gripper could not hold it, or
        null), "settings" (the optimiser's), "trials", "optimized": PlanResult.to_json(), "evaluation":
        {METHOD: {"error_vertices", "improvement_pct", "ci95_pct", "pinch_feasible"}}, "seconds"}``, also
        written to ``out/results.json``.

    Raises:
        InfeasiblePinch: ``job.pinch`` is not a grasp the gripper could make (on or near the cut line,
            under the cutting arm: :func:`warpcut.planning.pinch_problems`), unless
            ``job.allow_infeasible_pinch``; before any work.
    """
    job = job.check()
    out = Path(out)
    config = job.sim.validated()
    contour = resolve_contour(job.contour, job.sim)
    if job.pinch is not None:  # the arm sweeps the same footprint however the plan splits the cut
        check_pinch(job.pinch, contour, config, None, job.arm, allow=job.allow_infeasible_pinch)
    record_job(out, job, resume)
    start = time.perf_counter()
    log(f"  planning {contour.name} ({job.candidates} candidates)")
    plan = plan_cut(
        contour, config.replace(noise_std=0.0), num_candidates=job.candidates, seed=job.seed, device=device,
        arm=job.arm,
    )  # fmt: skip
    point = np.asarray(plan.chosen["pinch"] if job.pinch is None else job.pinch, dtype=np.float64)
    segments = plan.ordered_segments()
    allow = job.allow_infeasible_pinch
    method, (result,) = grad_result(
        [contour], [point], [segments], job.trials, config, job.grad, device, job.seed, out, log, job.arm,
        allow_infeasible_pinch=allow,
    )  # fmt: skip
    table = evaluate_suite(
        [contour], [Method("fixed", pinches=[point]), Method("grad", result=method)], job.trials, config,
        device, job.seed, segments=[segments], arm=job.arm, allow_infeasible_pinch=allow,
    )  # fmt: skip
    row = table["rows"][0]
    evaluation = {
        m: {
            "error_vertices": row[f"{m}_error_vertices"],
            "improvement_pct": row.get(f"{m}_improvement_pct", 0.0),
            "ci95_pct": row.get(f"{m}_ci95", 0.0),
            "pinch_feasible": row.get(f"{m}_pinch_feasible"),
        }
        for m in ("none", "fixed", "grad")
    }
    report = {
        "contour": contour.name,
        "pinch": [float(v) for v in point],
        "pinch_feasible": row["fixed_pinch_feasible"],
        "pinch_problem": row["fixed_pinch_problem"],
        "settings": dataclasses.asdict(job.grad),
        "trials": job.trials,
        "optimized": result.to_json(),
        "evaluation": evaluation,
        "seconds": time.perf_counter() - start,
    }
    write_json(out / RESULTS_FILE, report)
    return report
