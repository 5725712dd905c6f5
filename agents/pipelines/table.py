"""The paper's Table I protocol over a suite of contours, :func:`evaluate_table` (``warpcut evaluate``): per
contour the no-tension error and each method's paired improvement with its 95% CI, and the mean row."""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from agents.cluster import Done, Executor, Serial, ran_here
from agents.evaluation import Method, MethodResult, evaluate_suite
from agents.generalist import Generalist, guarded_result, load_generalist
from agents.jobs import EvaluateJob
from agents.methods import StepCallbacks
from agents.pipelines.common import (
    analytic_pinches,
    claims_out,
    finished_run,
    policy_iteration,
    policy_job,
    policy_kept,
    record_job,
    train_policy,
)
from agents.plan_optimizer.optimizer import grad_column
from agents.policies import check_policy_run, is_run, rollout_errors
from envs.options import ENV_FIELDS, PatternCutOptions
from warpcut.contours import Contour
from warpcut.io import read_json, safe_name, write_json
from warpcut.planning import InfeasiblePinch, Plan, check_pinch, plan_cut
from warpcut.planning.generate import GENERATED_SPEC, resolve_specs
from warpcut.sim.config import SimConfig
from warpcut.stats import mean_ci95, paired_improvement


@dataclass
class TableReport:
    """What :func:`evaluate_table` measured; :meth:`to_json` is the run directory's ``results.json``."""

    contours: list[Contour]
    methods: list[str]
    config: SimConfig
    table: dict
    """:func:`agents.evaluation.evaluate_suite`'s report: ``rows``, ``mean``, ``score``, ``trials``."""
    plans: list[Plan] | None
    analytic_pinch: str
    seconds: float
    policy_runs: list[Path] = field(default_factory=list)
    """The run directories of the policies trained here (empty with checkpoints, or without rl)."""

    def to_json(self) -> dict:
        return {
            **self.table,
            "planned": self.plans is not None,
            "analytic_pinch": self.analytic_pinch,
            "seconds": self.seconds,
        }

    def markdown(self) -> str:
        """The table as Markdown: per contour the no-tension error and each method's improvement ± CI (a
        cell at a pinch point the gripper could not hold says so). A CI is shown only over two or more
        values (trials, or contours for the mean), and an improvement over an error that is zero within
        float precision is ``n/a``."""
        shown, rows = [m for m in self.methods if m != "none"], self.table["rows"]
        columns = ["contour", "no tension (vertices)", *(f"{m} (%)" for m in shown)]
        lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
        trials = self.table.get("trials", 0)
        for row in rows:
            cells = [
                _percent(row[f"{m}_improvement_pct"], row[f"{m}_ci95"], trials)
                + (" (infeasible pinch)" if row.get(f"{m}_pinch_feasible") is False else "")
                for m in shown
            ]
            lines.append(
                "| " + " | ".join([row["contour"], f"{row['none_error_vertices']:.1f}", *cells]) + " |"
            )
        mean = self.table["mean"]
        cells = [
            _percent(mean[f"{m}_improvement_pct"], mean[f"{m}_ci95"], len(rows))
            + (
                " (infeasible pinches in it)"
                if any(r.get(f"{m}_pinch_feasible") is False for r in rows)
                else ""
            )
            for m in shown
        ]
        lines.append("| " + " | ".join(["**mean**", "", *cells]) + " |")
        return "\n".join(lines)


def _percent(value: float, ci: float, count: int) -> str:
    """An improvement cell: ``+x.x ± c.c``; without a CI over fewer than two values (one sample has
    none); ``n/a`` where the improvement is undefined (no tension's error zero within float precision)."""
    if value is None or not np.isfinite(value):
        return "n/a"
    return f"{value:+.1f} ± {ci:.1f}" if count >= 2 else f"{value:+.1f}"


@claims_out("evaluate")
def evaluate_table(
    job: EvaluateJob,
    out: str | Path,
    *,
    resume: bool = False,
    overwrite: bool = False,
    plans: Sequence[Plan] | None = None,
    device: str | None = None,
    log: Callable[[str], None] = lambda _: None,
    stages: Stages = lambda stage, done, total: None,
    step_callbacks: StepCallbacks | None = None,
    cluster: Executor | None = None,
) -> TableReport:
    """The paper's Table I protocol on ``job.contours``.

    Every contour is cut as planned (``job.plan``: segments and order; fixed and rl pinch at the planned
    point, analytic per ``job.analytic_pinch``), or without a plan as one loop (fixed by random search, rl and
    analytic at the feasible centroid). The rl column is a policy per contour: ``job.checkpoints/NAME`` when
    given (runs ``warpcut train`` wrote), else trained now with ``job.train`` into ``out/policies/NAME``. Its
    trials draw the baselines' noise (paired).

    Args:
        job: The contours, methods, trials, physics, env and learners (:class:`agents.jobs.EvaluateJob`).
        out: Run directory: ``config.json`` (the job), ``plans.json``, ``results.json``, ``results.md``,
            ``policies/`` (a run per contour, named by ``safe_name``). Locked while it runs; refused if it
            holds another run (``claim_run_dir``).
        resume: Continue the run in ``out`` (started with the same job): its plans and the policies trained
            to the end are kept, interrupted ones continue from their checkpoints.
        overwrite: Delete what ``out`` holds first.
        plans: The plans themselves, one per contour (e.g. to compare learners on the same plans), instead
            of planning now.
        device: Warp device.
        log: Called with each progress line.
        stages: Called as each stage advances (:data:`Stages`: planning, training rl, evaluating).
        step_callbacks: Step callbacks of the batches (``("rl", k)``: contour k's rollout).
        cluster: Where the units run (:mod:`agents.cluster`: each contour's plan, each rl policy's training
            and rollouts); default: here, one after another. The rows are the same either way; each says
            where its units ran (``ran_on``).
    """
    job = job.check()
    methods, config, trials, seed = list(job.methods), job.sim.validated(), job.trials, job.seed
    out = Path(out)
    named = resolve_specs(job.contours, job.sim.validated())
    loaded = [c for _, c in named]
    if job.checkpoints is not None and "rl" in methods:
        _check_checkpoints(Path(job.checkpoints), loaded, job)
    elif "rl" in methods:  # before any work: the learner can train in the env
        job.train.check(job.env.action_type == "discrete")
    generalist = load_generalist(job.generalist) if "generalist" in methods else None  # before any work
    record_job(out, job, resume)
    start = time.perf_counter()
    settings = dict(num_candidates=job.candidates, seed=seed, device=device, arm=job.arm)
    cluster = cluster or Serial()
    plans, ran_on = _table_plans(
        plans if plans is not None else job.plan, loaded, config, settings, out, log, stages, resume, cluster
    )
    clock = {"planning": time.perf_counter() - start}  # each stage's seconds, the driver's view
    specs, runs, notes = [Method(m) for m in methods], [], []  # notes: add a column's own fields to the table
    for spec in sorted(specs, key=lambda s: s.name == "grad"):  # grad last: it reads rl's teachers
        if spec.name == "fixed" and plans is not None:
            spec.pinches = [p.chosen["pinch"] for p in plans]
        elif spec.name == "analytic":
            spec.pinches = analytic_pinches(job.analytic_pinch, loaded, plans)
            spec.allow_infeasible_pinch = job.analytic_pinch == "centroid"  # the paper's, feasible or not
        elif spec.name == "rl":
            started = time.perf_counter()
            spec.result, runs, kept, ran_on["rl"] = _rl_result(
                job, named, plans, out, device, resume, log, step_callbacks, stages, cluster
            )
            clock["rl"] = time.perf_counter() - started
            notes.append(functools.partial(_note_rl_iterations, kept, runs))
        elif spec.name == "generalist":
            spec.result, note = _generalist_result(
                generalist, job, loaded, plans, device, step_callbacks, log
            )
            notes.append(note)
        elif spec.name == "grad":
            _share_teachers(job, runs, loaded, plans, out)
            spec.result, note = grad_column(
                loaded, plans, out, trials, config, (job.grad, job.arm), device, seed, log, step_callbacks
            )
            notes.append(note)
    batches = len({spec.name for spec in specs} | {"none"})  # evaluate_suite also runs none, the baseline
    running, started = iter(range(batches)), time.perf_counter()
    table = evaluate_suite(
        loaded,
        specs,
        trials=trials,
        config=config,
        device=device,
        seed=seed,
        segments=None if plans is None else [p.ordered_segments() for p in plans],
        progress=lambda what: (log(f"  running {what}"), stages("evaluating", next(running, 0), batches)),
        step_callbacks=step_callbacks,
        arm=job.arm,
    )
    stages("evaluating", batches, batches)
    table["stage_seconds"] = clock | {"evaluating": time.perf_counter() - started}
    log(f"  evaluated {len(methods)} method(s) x {len(loaded)} contour(s) x {trials} trials")
    for note in notes:
        note(table)
    for k, row in enumerate(table["rows"]):  # where each unit of the row ran, and its seconds there
        done = {unit: units[k] for unit, units in ran_on.items() if units[k] is not None}
        row["ran_on"] = {unit: d.ran_on for unit, d in done.items()} | {"evaluation": ran_here()}
        row["unit_seconds"] = {unit: round(d.seconds, 3) for unit, d in done.items()}
    report = TableReport(
        loaded, methods, config, table, plans, job.analytic_pinch, time.perf_counter() - start, runs
    )
    write_json(out / "results.json", report.to_json())
    from warpcut.io import write_atomic

    write_atomic(out / "results.md", (report.markdown() + "\n").encode())
    return report


Stages = Callable[[str, int, int], None]
"""``stages(stage, done, total)``: a pipeline's stage (e.g. "planning") has ``done`` of ``total`` steps
done (a progress bar per stage; ``warpcut evaluate`` draws them)."""


def _share_teachers(
    job: EvaluateJob, runs: list[Path], contours: list[Contour], plans: list[Plan] | None, out: Path
) -> None:
    """The grad column's plans that the rl column's runs already optimised as their teachers (gps: the same
    optimiser, settings, sheet, pinch point, order and seed as the grad column's), copied into ``out/grad``
    where the grad column reads a plan found there instead of optimising it again; only where the
    teacher's settings and pinch point are the column's, and the policies trained on the nominal sheet."""
    from agents.gps.runner import TEACHER_DIR
    from agents.plan_optimizer.optimizer import plan_settings

    env = {name: getattr(job.env, name) for name in ENV_FIELDS}
    options = PatternCutOptions(sim_config=job.sim, arm=job.arm, **env)
    if not runs or plans is None or options.config() != job.sim.validated() or options.randomize:
        return
    wanted = dataclasses.asdict(job.grad)
    for run, contour, plan in zip(runs, contours, plans, strict=True):
        name = f"{safe_name(contour.name)}.json"
        teacher, kept = Path(run) / TEACHER_DIR / name, out / "grad" / name
        if not teacher.is_file() or kept.exists():
            continue
        data = read_json(teacher)
        started = data["history"][0]["pinch"] if data.get("history") else data["pinch"]
        if plan_settings(data.get("settings")) == wanted and np.allclose(started, plan.chosen["pinch"]):
            write_json(kept, data)


def _note_rl_iterations(kept: list[int | None], runs: list[Path], table: dict) -> None:
    """Which iteration each contour's policy kept (``rl_policy_iteration``) and what it is (``rl_kept``:
    :func:`~agents.pipelines.common.policy_kept`), and on how many contours model selection kept the still
    grasp (``rl_initial_policy_contours``) or a teacher's plan (``rl_plan_contours``)."""
    kinds = [policy_kept(run) for run in runs]
    for row, iteration, kind in zip(table["rows"], kept, kinds, strict=False):
        row["rl_policy_iteration"], row["rl_kept"] = iteration, kind
    if kept:
        table["rl_initial_policy_contours"] = sum(1 for kind in kinds if kind == "still")
        if "plan" in kinds:
            table["rl_plan_contours"] = kinds.count("plan")


def _table_plans(
    plan: bool | Sequence[Plan],
    contours: list[Contour],
    config: SimConfig,
    settings: dict,
    out: Path,
    log: Callable[[str], None],
    stages: Stages,
    resume: bool = False,
    cluster: Executor | None = None,
) -> tuple[list[Plan] | None, dict[str, list[Done | None]]]:
    """:func:`evaluate_table`'s plans: the ones given (checked against the contours), or made now with the
    plan search's ``settings`` (noise-free; written to ``out/plans.json``) on ``cluster``, or None (``plan``
    False). With ``resume``, the plans ``out/plans.json`` holds are read back instead of searched again: the
    request (checked already) names the same contours, points and settings, and the search is
    deterministic. Also returns each plan's unit (``{"planning": [Done]}``; none where given or kept)."""
    if isinstance(plan, list | tuple):  # plans made already, one per contour
        plans = list(plan)
        if [p.contour.name for p in plans] != [c.name for c in contours]:
            raise ValueError("plan: give one Plan per contour, in the contours' order (or True / False)")
        return plans, {}
    if not plan:
        return None, {}
    config, path = config.replace(noise_std=0.0), out / "plans.json"
    if resume and path.is_file():
        try:
            saved = read_json(path)
            plans = [Plan.from_json(saved[c.name], c, config) for c in contours]
        except (OSError, KeyError, TypeError, ValueError) as exc:
            why = f"no plan for {exc.args[0]!r}" if isinstance(exc, KeyError) else " ".join(str(exc).split())
            log(f"  planning again: {path} cannot be kept ({why})")
        else:
            stages("planning", len(contours), len(contours))
            log(f"  kept the {len(plans)} plan(s) in {path}")
            return plans, {"planning": [None] * len(plans)}
    plans, where = plan_all(contours, config, settings, log, stages, cluster or Serial())
    write_json(path, {p.contour.name: p.to_json() for p in plans})
    return plans, {"planning": where}


def plan_all(
    contours: list[Contour],
    config: SimConfig,
    settings: dict,
    log: Callable[[str], None],
    stages: Stages,
    cluster: Executor,
) -> tuple[list[Plan], list[Done]]:
    """Plan every contour (:func:`~warpcut.planning.plan_cut` with ``settings``), a unit each on
    ``cluster``, saying how far it got; returns the plans and their units (where and how long)."""
    started, count, candidates = time.perf_counter(), len(contours), settings["num_candidates"]
    if cluster.address is not None:
        log(f"  planning {count} contour(s) ({candidates} candidates each) on {cluster.workers} worker(s)")
    stages("planning", 0, count)
    finished = iter(range(1, count + 1))

    def start(k: int) -> None:  # here, one after another
        log(f"  [{k + 1}/{count}] planning {contours[k].name} ({candidates} candidates)")

    def done(k: int, unit: Done) -> None:
        n = next(finished)
        if cluster.address is not None:
            log(f"  [{n}/{count}] planned {unit.value.contour.name} on {unit.ran_on} ({unit.seconds:.0f} s)")
        stages("planning", n, count)

    unit = functools.partial(_plan_unit, config=config, settings=settings)
    made = cluster.map(unit, contours, done=done, start=start)
    log(f"  planned {count} contour(s) in {time.perf_counter() - started:.0f} s")
    return [unit.value for unit in made], made


def _plan_unit(contour: Contour, config: SimConfig, settings: dict) -> Plan:
    """One contour's plan (a unit of :func:`plan_all`)."""
    return plan_cut(contour, config, **settings)


def _rl_result(
    job: EvaluateJob,
    named: list[tuple[str, Contour]],
    plans: list[Plan] | None,
    out: Path,
    device: str | None,
    resume: bool,
    log: Callable[[str], None],
    step_callbacks: StepCallbacks | None,
    stages: Stages,
    cluster: Executor | None = None,
) -> tuple[MethodResult, list[Path], list[int | None], list[Done]]:
    """The rl column: per contour a run (from ``job.checkpoints``, or trained now with ``job.train``, at the
    planned pinch and segments when planned) rolled out for ``job.trials``, paired with the baselines'
    noise. A contour's training and rollouts are a unit on ``cluster`` (its rollouts here where a step
    callback watches them). Also returns each contour's unit (where and how long)."""
    trials, seed, checkpoints, cluster = job.trials, job.seed, job.checkpoints, cluster or Serial()
    env = {name: getattr(job.env, name) for name in ENV_FIELDS}
    options = PatternCutOptions(sim_config=job.sim, arm=job.arm, **env)
    # checkpoints at infeasible pinch points were refused before any work (_check_checkpoints) unless allowed
    allowed = {}
    if checkpoints is not None and job.allow_infeasible_pinch:
        allowed = {"allow_infeasible_pinch": True}
    started, units, runs = time.perf_counter(), [], []
    watched = [None if step_callbacks is None else step_callbacks("rl", k) for k in range(len(named))]
    for k, (spec, contour) in enumerate(named):
        train_job = None
        if checkpoints is None:
            planned = {}
            if plans is not None:
                planned = {
                    "pinch_point": [float(v) for v in plans[k].chosen["pinch"]],
                    "segments": [s.tolist() for s in plans[k].ordered_segments()],
                }
            named_by = contour if GENERATED_SPEC.fullmatch(spec) else spec  # a generated one: stored inline
            train_job = policy_job(options, job, seed, trials, contour=named_by, **planned)
        rollout = None
        if (
            watched[k] is None
        ):  # trial t sees the noise of the baselines' trial t of contour k (env k*trials+t)
            rollout = dict(trials=trials, seed=seed + 1, device=device, paired_noise=(seed, k * trials))
            rollout["overrides"] = allowed
        units.append({"train": train_job, "device": device, "resume": resume, "rollout": rollout})
        runs.append(
            Path(checkpoints) / safe_name(contour.name)
            if checkpoints
            else out / "policies" / safe_name(contour.name)
        )
    stage = "training rl" if checkpoints is None else "rolling out rl"
    if cluster.address is not None and checkpoints is None:
        log(f"  training {job.train.algo} for {len(named)} contour(s) on {cluster.workers} worker(s)")
    finished = iter(range(1, len(named) + 1))

    def start(k: int) -> None:  # here, one after another
        if checkpoints is None:
            verb = "kept" if resume and finished_run(runs[k]) else "training"
            log(f"  [{k + 1}/{len(named)}] {verb} {job.train.algo} for {named[k][1].name}")

    def done(k: int, unit: Done) -> None:
        n = next(finished)
        if cluster.address is not None:
            log(f"  [{n}/{len(named)}] {named[k][1].name} on {unit.ran_on} ({unit.seconds:.0f} s)")
        stages(stage, n, len(named))

    stages(stage, 0, len(named))
    if checkpoints is None:
        made = cluster.map(_rl_unit, units, dirs=runs, done=done, gpu=_cuda(device), start=start)
    else:  # trained already: rolled out here
        made = Serial().map(lambda pair: _rl_unit(*pair), list(zip(units, runs, strict=True)), done=done)
    rollouts, iterations = [], []
    for k, (unit, run) in enumerate(zip(made, runs, strict=True)):
        iterations.append(unit.value["iteration"])
        rollouts.append(unit.value["rollouts"])
        if rollouts[-1] is None:  # watched: rolled out here, paired as the unit would have
            rollouts[-1] = rollout_errors(
                run, trials, seed=seed + 1, device=device, on_step=watched[k],
                paired_noise=(seed, k * trials), overrides=allowed,
            )  # fmt: skip
    what = "trained" if checkpoints is None else "rolled out"
    log(f"  rl: {what} {len(named)} policy(ies) in {time.perf_counter() - started:.0f} s")
    trained = runs if checkpoints is None else []
    return MethodResult.from_rollouts(rollouts), trained, iterations, made


def _rl_unit(unit: dict, run: Path) -> dict:
    """One contour's rl unit: its policy trained into ``run`` (unless given), the iteration it kept and,
    unless watched, its paired rollouts."""
    if unit["train"] is not None:
        train_policy(unit["train"], run, device=unit["device"], progress=False, resume=unit["resume"])
    rollouts = None if unit["rollout"] is None else rollout_errors(run, **unit["rollout"])
    return {"iteration": policy_iteration(run), "rollouts": rollouts}


def _cuda(device: str | None) -> bool:
    """Whether ``device`` is a GPU (a unit there declares one)."""
    from warpcut.sim.devices import resolve_device

    return resolve_device(device).startswith("cuda")


def _generalist_result(
    generalist: Generalist,
    job: EvaluateJob,
    contours: list[Contour],
    plans: list[Plan] | None,
    device: str | None,
    step_callbacks: StepCallbacks | None,
    log: Callable[[str], None],
) -> tuple[MethodResult, Callable[[dict], None]]:
    """The generalist column: ``generalist`` (``job.generalist``'s) zero-shot on every contour in one batch,
    paired with the baselines' trials, at the plan's pinch candidate (each in its best order; the first
    ``job.generalist_candidates`` by fixed tension, None: all), member (``job.generalist_members``) and gain
    (``job.generalist_gains``) where it validates best; on a contour where that choice cuts no better than
    holding still at the planned pinch point on fresh episodes, it holds still there
    (:func:`agents.generalist.guarded_result`; without plans: the feasible centroid, the whole contour). The
    note it returns adds to each row whether it held still
    (``generalist_holds_still``), the candidate and the gain it chose (``generalist_candidate``,
    ``generalist_gain``), the member that played (``generalist_member``; 0: its own policy,
    :attr:`agents.generalist.Generalist.members`) and its own trials there (``generalist_played_*``), and
    to the table on how many contours it held still (``generalist_still_contours``)."""
    from warpcut.planning import default_pinch

    started = time.perf_counter()
    if plans is not None:
        keep = job.generalist_candidates
        candidates = [
            [(np.asarray(c["pinch"]), p.ordered_segments(c["order"])) for c in p.ranked(keep)] for p in plans
        ]
    else:
        candidates = [[(default_pinch(c, job.sim, job.arm), None)] for c in contours]
    callback = None if step_callbacks is None else step_callbacks("generalist", 0)
    if job.generalist_members is not None:  # its own policy, then the first of its members
        generalist = dataclasses.replace(generalist, members=generalist.members[: job.generalist_members - 1])
    guarded = guarded_result(
        generalist, contours, candidates, job.trials, job.sim, device, job.seed, callback, job.arm, True,
        job.generalist_gains, job.generalist_finalists,
    )  # fmt: skip
    plays, played = guarded.plays, guarded.played
    log(
        f"  generalist: {len(contours)} contour(s) zero-shot in {time.perf_counter() - started:.0f} s, "
        f"holding still on {int((~plays).sum())}"
    )

    def note(table: dict) -> None:
        for k, row in enumerate(table["rows"]):
            improvement = paired_improvement(row["none_trials_error_vertices"], played.error_vertices[k])
            row["generalist_holds_still"] = not bool(plays[k])
            row["generalist_candidate"] = guarded.chosen[k]
            row["generalist_gain"] = float(guarded.gain[k])
            row["generalist_member"] = int(guarded.member[k])
            row["generalist_played_trials_error_vertices"] = played.error_vertices[k].tolist()
            row["generalist_played_improvement_pct"], row["generalist_played_ci95"] = mean_ci95(improvement)
        table["generalist_still_contours"] = int((~plays).sum())

    return guarded.result, note


def _check_checkpoints(checkpoints: Path, contours: list[Contour], job: EvaluateJob) -> None:
    """Refuse ``checkpoints`` unless it holds, for every contour, a finished run (or any, with
    ``job.allow_partial``) trained on that contour, with the job's observations and actions and the same
    simulation settings (:func:`agents.policies.check_policy_run`), at a pinch point the gripper could hold
    with the job's arm (or any, with ``job.allow_infeasible_pinch``)."""
    env = {name: getattr(job.env, name) for name in ENV_FIELDS}
    for contour in contours:
        run = checkpoints / safe_name(contour.name)
        if not is_run(run):
            raise ValueError(
                f"checkpoints: no trained run for {contour.name!r} at {run} "
                "(expected CHECKPOINTS/NAME/options.json from 'warpcut train --out')"
            )
        requested = PatternCutOptions(contour=contour, sim_config=job.sim, **env)
        options = check_policy_run(run, requested, allow_partial=job.allow_partial)
        if not job.allow_infeasible_pinch:
            _, pinch, cuts = dataclasses.replace(options, allow_infeasible_pinch=True).per_env(1)
            problem = check_pinch(pinch[0], contour, job.sim, cuts and cuts[0], job.arm, allow=True)
            if problem is not None:
                fix = f"train {contour.name}'s run at a feasible pinch point (warpcut train without --pinch)"
                raise InfeasiblePinch(pinch[0], contour, f"{problem} (the run {run})", fix)
