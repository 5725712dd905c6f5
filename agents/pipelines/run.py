"""The main job, :func:`run_pipeline` (``warpcut run``): plan one contour (segments, order, pinch candidates
scored with fixed tension), let a tensioner choose the candidate (rl: a policy per candidate, the one that
validates best wins), then compare none / fixed / analytic / rl over seeded trials."""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from agents.baselines import AnalyticTension
from agents.cluster import Done, Executor, Serial, ran_here
from agents.config import VALIDATION_TRIALS
from agents.evaluation import Method, MethodResult, evaluate_suite, run_method
from agents.generalist import Generalist, guarded_result, load_generalist
from agents.jobs import RunJob
from agents.methods import StepCallbacks, point_text
from agents.pipelines.common import (
    analytic_pinches,
    claims_out,
    policy_job,
    policy_kept,
    record_job,
    train_policy,
)
from agents.policies import nominal_validation_error, rollout_errors
from envs.options import ENV_FIELDS, PatternCutOptions
from warpcut.contours import Contour
from warpcut.io import write_json
from warpcut.planning import ArmModel, Plan, plan_cut, resolve_contour
from warpcut.sim.config import SimConfig


@dataclass
class RunReport:
    """What :func:`run_pipeline` found; :meth:`to_json` is the run directory's ``results.json``."""

    contour: Contour
    config: SimConfig
    plan: Plan
    selector: str
    """The tensioner that chose the pinch candidate."""
    methods: list[str]
    table: dict
    """:func:`agents.evaluation.evaluate_suite`'s report for the contour (one row)."""
    candidates: list[dict]
    """The candidates the selector scored, best fixed-tension rank first, with each one's scores."""
    chosen_candidate: int
    budget: str
    analytic_pinch: str
    seconds: float
    policy_runs: list[Path] = field(default_factory=list)
    """The run directories of the policies trained (empty unless the selector is rl)."""

    @property
    def row(self) -> dict:
        return self.table["rows"][0]

    def to_json(self) -> dict:
        return {
            **self.table,
            "plan": self.plan.to_json()["chosen"],
            "policy": self.selector,
            "candidates": self.candidates,
            "chosen_candidate": self.chosen_candidate,
            "budget": self.budget,
            "analytic_pinch": self.analytic_pinch,
            "seconds": self.seconds,
        }


@claims_out("run")
def run_pipeline(
    job: RunJob,
    out: str | Path,
    *,
    resume: bool = False,
    overwrite: bool = False,
    device: str | None = None,
    log: Callable[[str], None] = lambda _: None,
    progress: bool = True,
    step_callbacks: StepCallbacks | None = None,
    cluster: Executor | None = None,
) -> RunReport:
    """Plan ``job.contour``, choose the pinch candidate with ``job.policy``, evaluate every method.

    Args:
        job: The contour, budget, selector, physics, env and learner (:class:`agents.jobs.RunJob`).
        out: Run directory: ``config.json`` (the job), ``plan.json``, ``results.json`` and the policies
            (``rl/candidate-K/``). Locked while the pipeline runs; refused if it holds another run (see
            :func:`warpcut.io.claim_run_dir`).
        resume: Continue the run in ``out`` (started with the same job): policies trained to the end are
            kept, interrupted ones continue from their checkpoints.
        overwrite: Delete what ``out`` holds first.
        device: Warp device.
        log: Called with each progress line.
        progress: Show the training progress bars.
        step_callbacks: Step callbacks of the evaluation's batches (:data:`agents.methods.StepCallbacks`).
        cluster: Where rl's pinch candidates train (:mod:`agents.cluster`, a unit each); default: here, one
            after another. The results are the same either way.
    """
    cluster = cluster or Serial()
    job.check()  # before any work
    settings = job.settings()
    generalist = load_generalist(job.generalist) if job.policy == "generalist" else None  # before any work
    out = Path(out)
    loaded = resolve_contour(job.contour, job.sim)
    record_job(out, job, resume)
    start = time.perf_counter()

    sampled = f"{settings['candidates']} sampled pinch candidates (+ the centroid if feasible)"
    log(f"[1/3] planning {loaded.name}: {sampled}")
    plan = plan_cut(
        loaded, job.sim, num_candidates=settings["candidates"], seed=job.seed, device=device, arm=job.arm
    )
    write_json(out / "plan.json", plan.to_json())
    pinch = plan.chosen["pinch"]
    log(
        f"      {len(plan.segments)} segment(s), order {list(plan.order)}, pinch "
        f"{point_text(pinch)} with fixed tension: {plan.chosen['error_vertices']:.1f} vertices"
    )
    listed = plan.ranked(settings["rl_candidates"] if job.policy == "rl" else None)
    runs: list[Path] = []
    rl_dir = None
    if job.policy == "fixed":
        chosen = 0  # the plan's choice: the best candidate by fixed tension
        log("[2/3] --policy fixed: the plan's pinch and order")
    elif job.policy == "generalist":
        log(f"[2/3] scoring the generalist at {len(listed)} pinch candidate(s), zero-shot")
        on_step = None if step_callbacks is None else step_callbacks("generalist", 0)
        chosen, plays, played, confirmed = _choose_by_generalist(
            generalist, job, loaded, plan, listed, settings["trials"], device, on_step
        )
    elif job.policy == "analytic":
        log(f"[2/3] scoring the analytic policy at {len(listed)} pinch candidate(s)")
        chosen = _choose_by_analytic(loaded, plan, listed, job.sim, device, job.seed, job.arm)
    else:
        rl_dir, chosen, runs = _train_candidates(
            job, loaded, plan, listed, settings["trials"], out, device, resume, log, progress, cluster
        )
    log(f"      chosen by {job.policy}: {_candidate_text(listed[chosen])}")
    if job.policy == "generalist":
        log(f"      {confirmed}")

    methods = ["none", "fixed", "analytic"] + ([job.policy] if job.policy in ("rl", "generalist") else [])
    log(f"[3/3] evaluating {', '.join(methods)}: {settings['trials']} trials each")
    if job.policy == "analytic":  # at the candidate it chose, in that candidate's best order
        best = listed[chosen]
        analytic = Method(
            "analytic", pinches=[np.asarray(best["pinch"])], segments=[plan.ordered_segments(best["order"])]
        )
    else:  # at job.analytic_pinch; "centroid", the paper's literal point, feasible or not: its row says which
        centroid = job.analytic_pinch == "centroid"
        pinches = analytic_pinches(job.analytic_pinch, [loaded], [plan])
        analytic = Method("analytic", pinches=pinches, allow_infeasible_pinch=centroid)
    specs = [Method("none"), Method("fixed", pinches=[pinch]), analytic]
    if rl_dir is not None:
        on_step = None if step_callbacks is None else step_callbacks("rl", 0)
        # Paired: the noise of the baselines' trials (evaluate_suite below, same seed).
        rl = rollout_errors(
            rl_dir, settings["trials"], job.seed + 1, device, on_step, paired_noise=(job.seed, 0)
        )
        specs.append(Method("rl", result=MethodResult.from_rollouts([rl])))
    if job.policy == "generalist":
        specs.append(played)
    table = evaluate_suite(
        [loaded],
        specs,
        trials=settings["trials"],
        config=job.sim,
        device=device,
        seed=job.seed,
        segments=[plan.ordered_segments()],
        step_callbacks=step_callbacks,
        arm=job.arm,
    )
    if job.policy == "generalist":
        table["generalist_holds_still"] = not plays
    here = ran_here()  # where each unit of the row ran: rl's, the chosen candidate's
    rl = {} if rl_dir is None else {"rl": listed[chosen].get("ran_on", here)}
    table["rows"][0]["ran_on"] = {"planning": here, **rl, "evaluation": here}
    report = RunReport(
        loaded, job.sim, plan, job.policy, methods, table, listed, chosen, job.budget, job.analytic_pinch,
        time.perf_counter() - start, runs,
    )  # fmt: skip
    write_json(out / "results.json", report.to_json())
    return report


def _candidate_text(candidate: dict) -> str:
    """A candidate's pinch, order and scores, as the progress lines show them."""
    scores = (
        "fixed_error_vertices", "analytic_error_vertices", "generalist_error_vertices",
        "rl_validation_error_vertices",
    )  # fmt: skip
    gain, member = candidate.get("generalist_gain", 1.0), candidate.get("generalist_member")
    return (
        f"pinch {point_text(candidate['pinch'])}, order {candidate['order']}"
        + "".join(f", {k.split('_')[0]} {candidate[k]:.1f}" for k in scores if k in candidate)
        + " vertices"
        + (f", its moves x{gain:g}" if gain != 1 else "")
        + (f", member {member}" if member else "")
    )


def _choose_by_analytic(
    contour: Contour,
    plan: Plan,
    listed: list[dict],
    config: SimConfig,
    device: str | None,
    seed: int,
    arm: ArmModel,
) -> int:
    """Score the analytic policy at every candidate (noise-free, one batch); the index of the best."""
    scores = run_method(
        [contour] * len(listed),
        [np.asarray(c["pinch"]) for c in listed],
        AnalyticTension(),
        1,
        config.replace(noise_std=0.0),
        device,
        seed,
        segments=[plan.ordered_segments(c["order"]) for c in listed],
        arm=arm,
    ).error_vertices[:, 0]
    for c, e in zip(listed, scores, strict=True):
        c["analytic_error_vertices"] = float(e)
    return int(np.argmin(scores))


def _choose_by_generalist(
    generalist: Generalist,
    job: RunJob,
    contour: Contour,
    plan: Plan,
    listed: list[dict],
    trials: int,
    device: str | None,
    on_step,
) -> tuple[int, bool, Method, str]:
    """The generalist at the candidate (each in its best order) and gain where it validates best, or holding
    still at the plan's (index 0) where that cuts no better on fresh episodes
    (:func:`agents.generalist.guarded_result`), as rl's model selection keeps its initial, still policy;
    records in ``listed`` each candidate's validation error, and the chosen one's gain and its error on the
    fresh episodes (holding still's: at the first). Returns the candidate played, whether the generalist
    plays, its row of the evaluation (paired with the baselines' trials) and what the fresh episodes said."""
    candidates = [(np.asarray(c["pinch"]), plan.ordered_segments(c["order"])) for c in listed]
    guarded = guarded_result(
        generalist, [contour], [candidates], trials, job.sim, device, job.seed, on_step, job.arm,
    )  # fmt: skip
    for c, e in zip(listed, guarded.validation[0], strict=True):
        c["generalist_error_vertices"] = float(e)
    listed[0]["still_error_vertices"] = float(guarded.still[0])
    best = listed[guarded.chosen[0]]
    best["generalist_gain"] = float(guarded.gain[0])
    if generalist.members:
        best["generalist_member"] = int(guarded.member[0])
    best["generalist_confirmed_error_vertices"] = float(guarded.best[0])
    plays = bool(guarded.plays[0])
    confirmed = (
        f"on fresh episodes its choice cut {guarded.best[0]:.1f} vertices, holding still "
        f"{guarded.still[0]:.1f}" + ("" if plays else ": it holds still (fixed tension)")
    )
    return (guarded.chosen[0] if plays else 0), plays, Method("generalist", result=guarded.result), confirmed


def _train_candidates(
    job: RunJob,
    contour: Contour,
    plan: Plan,
    listed: list[dict],
    trials: int,
    out: Path,
    device: str | None,
    resume: bool,
    log: Callable[[str], None],
    progress: bool,
    cluster: Executor,
) -> tuple[Path, int, list[Path]]:
    """The rl selector: a policy per candidate in ``listed``, each candidate cut in its best order, a unit
    each on ``cluster``; records each candidate's validation error (and where it trained, ``ran_on``) in
    ``listed``. Returns the winner's run directory, its index (the first, i.e. the better fixed rank, among
    ties) and every run directory."""
    options = PatternCutOptions(
        contour=contour,
        sim_config=job.sim,
        arm=job.arm,
        **{name: getattr(job.env, name) for name in ENV_FIELDS},
    )
    article = "an" if job.train.algo[0] in "aeiou" else "a"
    where = (
        "at the best pinch candidate"
        if len(listed) == 1
        else f"for each of the best {len(listed)} candidates"
    )
    log(f"[2/3] training {article} {job.train.algo} policy {where} ({job.train.batch_size} envs)")
    units, runs = [], [out / "rl" / f"candidate-{k}" for k in range(len(listed))]
    for k, candidate in enumerate(listed):
        segments = [s.tolist() for s in plan.ordered_segments(candidate["order"])]
        train_job = policy_job(
            options, job, job.seed, trials, pinch_point=candidate["pinch"], segments=segments
        )
        where = f"candidate {k + 1}/{len(listed)} {point_text(candidate['pinch'])}"
        label = f"{job.train.algo.upper()} {contour.name}, {where}"
        # no validation, or one off the nominal sheet: the candidates are compared on the nominal sheet
        nominal = options.randomize or options.relative_reward
        units.append(
            {"train": train_job, "device": device, "resume": resume, "label": label, "nominal": nominal,
             "progress": progress and cluster.address is None, "trials": job.train.validation_trials}
        )  # fmt: skip

    def done(k: int, unit: Done) -> None:
        candidate = listed[k]
        candidate.update(unit.value)
        candidate["run"] = str(runs[k].relative_to(out))
        candidate["ran_on"], candidate["unit_seconds"] = unit.ran_on, round(unit.seconds, 3)
        nominal = ", nominal sheet" if "rl_training_validation_error" in candidate else ""
        kept = KEPT_WORDS.get(candidate.get("rl_kept"), "")
        log(
            f"      candidate {point_text(candidate['pinch'])}: "
            f"fixed {candidate['fixed_error_vertices']:.1f}, "
            f"rl {candidate['rl_validation_error_vertices']:.1f} vertices (validation{nominal}){kept}"
        )

    cluster.map(functools.partial(_candidate_unit, seed=job.seed), units, dirs=runs, done=done)
    chosen = min(range(len(listed)), key=lambda k: (listed[k]["rl_validation_error_vertices"], k))
    return out / listed[chosen]["run"], chosen, runs


KEPT_WORDS = {
    "still": "; rl kept the still grasp (fixed tension): no trained policy validated better",
    "plan": "; rl kept its teacher's plan, played open loop: no correction validated better",
}
"""What a candidate's progress line adds where model selection kept no trained policy."""


def _candidate_unit(unit: dict, run_dir: Path, seed: int) -> dict:
    """One pinch candidate's policy trained into ``run_dir``; its scores: the iteration it kept and its
    validation error (on the nominal sheet where its own validation was not)."""
    summary = train_policy(
        unit["train"], run_dir, device=unit["device"], progress=unit["progress"], resume=unit["resume"],
        label=unit["label"],
    )  # fmt: skip
    best, scores = summary["best"], {"rl_kept": policy_kept(run_dir)}
    scores["rl_best_iteration"] = best["iterations"] if best else summary["iterations"]
    if best is not None:
        scores["rl_validation_error_vertices"] = best["validation_error"]
    if best is None or unit["nominal"]:
        if best is not None:
            scores["rl_training_validation_error"] = best["validation_error"]
        scores["rl_validation_error_vertices"] = nominal_validation_error(
            run_dir, unit["trials"] or VALIDATION_TRIALS, seed, unit["device"]
        )
    return scores
