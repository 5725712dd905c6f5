"""The paper's sensitivity experiments (Thananjeyan et al. 2017, Sec. VII-B and Fig. 5): does a tensioning
policy tuned on one simulated sheet still help on another?

Three studies, each a sweep of one setting of the simulation around the nominal sheet:

- ``resolution``: the mesh's vertices per side (the paper: 100 to 2500 vertices). Each resolution is its
  own batch (a batch holds one mesh). The error is reported as a percentage of the sheet's area, the
  paper's "error in vertices normalised by the test resolution".
- ``noise``: the process noise ``noise_std`` added to every free vertex per update (mm; the paper's
  N(0, sigma) on Eq. (1)). All values are one batch (per-env parameters).
- ``force``: the gravity-like external force (mm/s^2; the paper's f(t) around 2500 units/s^2, 521 mm/s^2
  here). All values are one batch; each value settles its own sheet and the scissors follow it as it
  hangs (open loop on the sheet the camera sees).

Every method cuts the same seeded noisy trials of every setting (paired noise: trial ``k`` of setting ``s``
is env ``s * trials + k`` of each method's batch). The noise and force studies report each method's
improvement over no tension per trial (%), as the paper's Fig. 5b-c; the resolution study reports the error
itself, no tension included. ``rl`` is a trained run's policy (``warpcut train``), at the run's pinch point
and cut order; fixed tension holds the same pinch point, analytic tension pinches its own (the feasible
centroid), no tension none.

A trial whose simulation diverges (at large noise, say) is not refused: its error is undefined, so it is
left out of its pair (a method's trial k and no tension's), and every method's count of diverged trials per
value is in the report (``diverged``) and in its table. The robustness target
(``scripts/robustness_tables.py``) counts a value where the policy diverged in more trials than no tension
against it.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from agents.cluster import Executor, Serial
from agents.config import EVALUATION_TRIALS
from agents.evaluation import run_method
from agents.jobs import RobustnessJob
from agents.methods import BASELINES, check_methods, tensioner
from agents.pipelines.common import claims_out, record_job
from agents.pipelines.robustness_studies import (
    STUDY_FIELDS,
    STUDY_METHODS,
    STUDY_UNITS,
    check_label,
    check_plans,
    check_runs,
    check_study,
    infeasible_pinches,
    nominal_scenario,
    parse_studies,
    read_plan,
)
from agents.plan_optimizer.config import GRAD_CONFIG, GradConfig
from agents.plan_optimizer.plan import PlanResult
from warpcut.contours import Contour, ContourError
from warpcut.planning import resolve_contour
from warpcut.sim.config import SimConfig
from warpcut.stats import bootstrap_ci, paired_improvement
from warpcut.trajectory import segments_key


def _override(study: str, values: Sequence[float], trials: int) -> dict:
    """The options/config fields that set a batch of every value of ``study`` x ``trials`` (a resolution
    study's batch holds its one value: a batch holds one mesh)."""
    if study == "resolution":
        return {"resolution": values[0]}
    per_env = [float(v) for v in np.repeat(np.asarray(values, dtype=np.float64), trials)]
    return {STUDY_FIELDS[study]: per_env}


def _stats(values: np.ndarray) -> dict[str, list]:
    """Per setting (rows of ``values``, trials along columns): median and quartiles of the finite trials,
    the median's 95% bootstrap interval (None for fewer than two trials) and every trial's value (None where
    undefined), so intervals of other statistics can be computed from the report."""
    out: dict[str, list] = {k: [] for k in ("median", "q25", "q75", "mean", "median_ci95", "per_trial")}
    for row in np.asarray(values, dtype=np.float64):
        finite = row[np.isfinite(row)]
        for key, q in (("median", 50), ("q25", 25), ("q75", 75)):
            out[key].append(float(np.percentile(finite, q)) if finite.size else None)
        out["mean"].append(float(finite.mean()) if finite.size else None)
        interval = bootstrap_ci(finite, "median")
        out["median_ci95"].append(None if interval is None else list(interval))
        out["per_trial"].append([float(v) if np.isfinite(v) else None for v in row])
    return out


def robustness_study(
    contour: str | Contour | None,
    study: str,
    out: Path | None = None,
    *,
    runs: Mapping[str, str | Path] | str | Path | None = None,
    plans: Mapping[str, str | Path] | None = None,
    methods: Sequence[str] | None = None,
    values: Sequence[float] | None = None,
    trials: int = EVALUATION_TRIALS,
    config: SimConfig | None = None,
    grad: GradConfig = GRAD_CONFIG,
    device: str | None = None,
    seed: int = 0,
    log: Callable[[str], None] = lambda _: None,
    allow_infeasible_pinch: bool = False,
    generalist: str | None = None,
    cluster: Executor | None = None,
) -> dict:
    """``warpcut robustness``: sweep one setting of the simulation and score every method at each value.

    Args:
        contour: The contour (built-in name, file or ``Contour``); with ``runs`` None means the runs', and
            another is refused.
        study: ``resolution``, ``noise`` or ``force`` (module docstring).
        out: Where ``robustness-STUDY.json`` goes (None: nowhere).
        runs: Trained runs of the contour (``warpcut train``/``run``), ``{label: run}`` (one run: ``{"rl":
            run}``): each label a method, its policy at its run's pinch point. The first run sets the pinch
            point fixed tension holds, the cut order and the nominal simulation (its options' nominal
            parameters). None: fixed tension pinches the plan's point (:func:`warpcut.planning.plan_cut`).
        plans: Optimised plans of the contour, ``{label: file}`` (``warpcut optimize``'s ``NAME.json``, or
            ``warpcut evaluate``'s ``grad/NAME.json``): each label is a method, the plan played as it was
            optimised (open loop, or closed loop with its feedback gains) at its own pinch point, in the
            study's cut order, at every value.
        methods: The methods to run besides the runs' policies, from :data:`STUDY_METHODS` (default: the
            baselines; ``none`` always runs, the others' improvements are measured against it). ``grad``
            optimises its plan first, at the pinch point and order fixed tension uses, kept in
            ``out/grad/CONTOUR.json`` (and reused by the next study).
        values, trials: The sweep (default :data:`STUDY_VALUES`); seeded noisy trials per value and method.
        config: The nominal simulation without a run (default ``SimConfig()``).
        grad: The ``grad`` method's optimiser settings.
        device, seed: Warp device; seed of the process noise (and of the plan).
        allow_infeasible_pinch: Accept infeasible pinch points (:func:`infeasible_pinches`), not refuse them.
        generalist: The ``generalist`` method's (None: the shipped one), at fixed's pinch point and order.
        cluster: Where each method's batches run (:mod:`agents.cluster`, a unit per method and batch of
            values); default: here, one after another. The report is the same either way.

    Returns: ``{"study", "values", "unit", "metric", "contour", "trials", "nominal", "pinch", "runs",
        "methods", "seconds", "skipped": [value], "diverged": {METHOD: [count]}, METHOD: {"median", "q25",
        "q75", "mean", "median_ci95", "per_trial"}}`` (per value; diverged trials, the median's 95%
        bootstrap interval, every trial's value), the metric being
        ``improvement_pct`` (noise, force) or ``error_pct_of_sheet`` (resolution; then ``none`` is a method
        too). Noise and force add ``none_error_mm2``, no tension's error. A run cut in another order than
        the first (another pinch) is paired with no tension cut in its own order (``own_order_none``)."""
    start, cluster = time.perf_counter(), cluster or Serial()
    values = check_study(study, values)
    if not isinstance(trials, int) or trials < 1:
        raise ValueError(f"trials: must be a positive integer (got {trials!r})")
    runs = check_runs(runs)
    scenario = nominal_scenario(contour, runs, config, device, seed, log)
    infeasible = infeasible_pinches(scenario, methods, plans, runs, allow_infeasible_pinch)
    contour, config, pinch, segments = (scenario[k] for k in ("contour", "config", "pinch", "segments"))
    own_order = {  # a run cut in another order than the first: against no tension cut in its own order
        label: cut
        for label, cut in scenario.get("run_segments", {}).items()
        if segments_key(cut) != segments_key(segments)
    }
    chosen, played = _methods(methods, runs, plans, scenario, grad, device, seed, out, log)
    common = dict(contour=contour, pinch=pinch, runs=runs, device=device, seed=seed, trials=trials)
    common |= {"generalist": generalist, "study": study, "config": config, "segments": segments}
    errors, own_none, skipped, ran_on = _study_errors(values, chosen, own_order, played, common, cluster, log)
    report = {
        "study": study,
        "values": [float(v) for v in values],
        "unit": STUDY_UNITS[study],
        "metric": "error_pct_of_sheet" if study == "resolution" else "improvement_pct",
        "contour": contour.name,
        "trials": trials,
        "nominal": _nominal(study, config),
        "pinch": [float(v) for v in pinch],
        "infeasible_pinches": infeasible,
        "runs": {label: str(run) for label, run in runs.items()},
        "plans": {label: str(path) for label, path in (plans or {}).items()},
        "methods": chosen if study == "resolution" else chosen[1:],
        "skipped": [float(v) for v in skipped],
        "own_order_none": sorted(own_order),
        "diverged": {m: _diverged_counts(values, skipped, errors[m]) for m in chosen},
        "ran_on": ran_on,
    }
    report.update(_method_stats(study, chosen, errors, own_none, config.width_mm * config.height_mm))
    report["seconds"] = time.perf_counter() - start
    if out is not None:
        from warpcut.io import write_json

        write_json(Path(out) / f"robustness-{study}.json", report)
    return report


def _study_errors(
    values: list[float],
    chosen: list[str],
    own_order: dict,
    played: Mapping[str, PlanResult],
    common: dict,
    cluster: Executor,
    log: Callable[[str], None],
) -> tuple[dict, dict, list[float], dict]:
    """:func:`robustness_study`'s (values, trials) errors of every method in ``chosen`` (and of no tension
    in each cut order of ``own_order``), a unit per method and batch of values on ``cluster``: the errors,
    no tension's own-order errors, the values skipped (a mesh too coarse) and where each unit ran."""
    study, trials, config = common["study"], common["trials"], common["config"]
    errors: dict[str, np.ndarray] = {m: np.full((len(values), trials), np.nan) for m in chosen}
    own_none = {label: np.full((len(values), trials), np.nan) for label in own_order}
    batches = [[k] for k in range(len(values))] if study == "resolution" else [list(range(len(values)))]
    units, owners = [], []  # a unit per batch and method (and per cut order of no tension, own_order's)
    for b, batch in enumerate(batches):
        overrides = _override(study, [values[k] for k in batch], trials)
        shared = dict(common, config=config.replace(**overrides), overrides=overrides, settings=len(batch))
        for method in chosen:
            units.append(dict(shared, method=method, plans=played))
            owners.append((b, method))
        for key, cut in {segments_key(cut): cut for cut in own_order.values()}.items():
            units.append(dict(shared, method="none", segments=cut, plans=None))
            owners.append((b, key))
    # the folder a unit reads (a worker of a cluster gets its files): its method's run, or the generalist
    runs, generalist = common["runs"], common["generalist"]
    folders = [runs.get(u["method"]) or (generalist if u["method"] == "generalist" else None) for u in units]
    log(f"  {study}: {', '.join(chosen)} at {len(values)} value(s), {trials} trials ({len(units)} batch(es))")
    results = dict(zip(owners, cluster.map(_errors_unit, units, dirs=folders), strict=True))
    made, skipped = {owner: unit.value for owner, unit in results.items()}, []
    for b, batch in enumerate(batches):
        picked = [values[k] for k in batch]
        failed = next((made[(b, m)] for m in chosen if isinstance(made[(b, m)], str)), None)
        for method in chosen:  # all NaN where the mesh was too coarse for the contour or grasp
            errors[method][batch] = np.nan if failed is not None else made[(b, method)]
        if failed is not None:
            log(f"  skipped {study} {picked[0]:g}: {failed}")
            skipped.extend(picked)
            continue
        for label, cut in own_order.items():
            own_none[label][batch] = made[(b, segments_key(cut))]
        _log_diverged(log, study, picked, {m: errors[m][batch] for m in chosen})
    ran_on = {m: [results[(b, m)].ran_on for b in range(len(batches))] for m in chosen}
    return errors, own_none, skipped, ran_on


def _methods(methods, runs, plans, scenario, grad, device, seed, out, log) -> tuple[list, dict]:
    """The methods a study runs, in order, and the plans it plays: ``plans``' and grad's (optimised at the
    scenario's pinch point and order, or read back from ``out/grad``)."""
    baselines = check_methods(list(methods or BASELINES), "methods", STUDY_METHODS)
    played = check_plans(plans, scenario["contour"], runs)
    chosen = ["none", *[m for m in baselines if m != "none"], *runs, *played]
    if "grad" in chosen:
        from agents.plan_optimizer.optimizer import cached_plan

        folder = None if out is None else Path(out) / "grad"
        contour, config, pinch, segments = (scenario[k] for k in ("contour", "config", "pinch", "segments"))
        played["grad"] = cached_plan(
            contour, pinch, segments, config, grad, device, seed, folder, log, allow_infeasible_pinch=True
        )  # its pinch point is judged with the others' (infeasible_pinches)
    return chosen, played


def _method_stats(study: str, methods: list[str], errors: dict, own_none: dict, sheet_mm2: float) -> dict:
    """Each method's statistics per value: its error as % of the sheet (resolution), or its improvement
    over no tension (paired; cut in the run's own order where ``own_none`` has it), and no tension's
    error (``none_error_mm2``)."""
    stats = {}
    for method in methods:
        if study == "resolution":
            stats[method] = _stats(100.0 * errors[method] / sheet_mm2)
        elif method != "none":
            none = own_none.get(method, errors["none"])
            stats[method] = _stats(paired_improvement(none, errors[method]))
    if study != "resolution":
        stats["none_error_mm2"] = _stats(errors["none"])
    return stats


def _nominal(study: str, config: SimConfig) -> float:
    """The nominal sheet's value of the swept setting (the dashed line of the paper's plots)."""
    if study == "resolution":
        return float(config.nx)
    value = np.asarray(getattr(config, STUDY_FIELDS[study]), dtype=np.float64)
    return float(value.reshape(-1)[0])


def _method_errors(
    method: str,
    contour: Contour,
    pinch: np.ndarray,
    segments: list[np.ndarray] | None,
    config: SimConfig,
    overrides: dict,
    settings: int,
    trials: int,
    runs: dict[str, Path],
    device: str | None,
    seed: int,
    plans: Mapping[str, PlanResult] | None = None,
    generalist: str | None = None,
) -> np.ndarray:
    """(settings, trials) errors (mm^2) of ``method``: one batch, env ``s * trials + k`` = setting ``s``,
    trial ``k``, with the same noise streams in every method's batch; NaN where the trial diverged."""
    if method == "generalist":
        from agents.generalist import generalist_result, load_generalist

        result = generalist_result(
            load_generalist(generalist), [contour] * settings, [pinch] * settings, [segments] * settings,
            trials, config, device, seed, allow_infeasible_pinch=True,  # judged on the nominal sheet
        )  # fmt: skip
        errors = np.asarray(result.error_mm2, dtype=np.float64)
        return np.where(np.isfinite(errors), errors, np.nan)
    if method in runs:
        from agents.policies import rollout_errors

        rollouts = rollout_errors(
            runs[method], settings * trials, seed=seed, device=device, paired_noise=(seed, 0),
            overrides={**overrides, "allow_infeasible_pinch": True},  # judged on the nominal sheet
        )  # fmt: skip
        return np.asarray(rollouts["error_mm2"], dtype=np.float64).reshape(settings, trials)
    policy = None if method in (plans or {}) else tensioner(method)
    if method in (plans or {}):  # grad's plan or a given one, at its own pinch point
        point, policy = np.asarray(plans[method].pinch), PlanResult.policy([plans[method]] * settings, trials)
    elif method == "analytic":
        from agents.baselines import AnalyticTension

        point = AnalyticTension().pinch_point(contour, config)
    else:
        point = None if method == "none" else pinch
    # run_method's layout is contour by contour, trials within: one "contour" per setting.
    result = run_method(
        [contour] * settings, [point] * settings, policy, trials, config, device, seed,
        segments=[segments] * settings, allow_diverged=True, allow_infeasible_pinch=True,  # judged nominal
    )  # fmt: skip
    return np.where(result.diverged_trials(), np.nan, np.asarray(result.error_mm2, dtype=np.float64))


def _errors_unit(unit: dict, folder: Path | None) -> np.ndarray | str:
    """A unit of :func:`robustness_study`: :func:`_method_errors` of ``unit``, its run or generalist read
    from ``folder``; a resolution the contour or grasp does not fit: its error's message (a skipped value)."""
    study, method, runs, generalist = (unit[k] for k in ("study", "method", "runs", "generalist"))
    runs = {**runs, method: folder} if method in runs else runs
    generalist = folder if method == "generalist" else generalist
    try:
        return _method_errors(
            method, unit["contour"], unit["pinch"], unit["segments"], unit["config"], unit["overrides"],
            unit["settings"], unit["trials"], runs, unit["device"], unit["seed"], unit["plans"], generalist,
        )  # fmt: skip
    except (ContourError, ValueError) as error:
        if study != "resolution" or not str(error).startswith(("resolution", "contour")):
            raise
        return str(error)


def _diverged_words(counts: Mapping[str, int]) -> str:
    """``"diverged trials (left out of their pairs): METHOD N, ..."`` for the methods with any; else ""."""
    which = ", ".join(f"{m} {n}" for m, n in counts.items() if n)
    return f"diverged trials (left out of their pairs): {which}" if which else ""


def _log_diverged(log: Callable[[str], None], study: str, values: list, errors: Mapping[str, np.ndarray]):
    """Log, per value of a batch, the methods with diverged trials (NaN errors) and how many."""
    for k, value in enumerate(values):
        words = _diverged_words({m: int(np.sum(~np.isfinite(e[k]))) for m, e in errors.items()})
        if words:
            log(f"  {study} {value:g}: {words}")


def _diverged_counts(values: list, skipped: list, errors: np.ndarray) -> list[int]:
    """Per value, the trials whose error is undefined (diverged); 0 for a skipped value."""
    rows = zip(values, errors, strict=True)
    return [0 if v in skipped else int(np.sum(~np.isfinite(row))) for v, row in rows]


def robustness_table(report: dict) -> list[str]:
    """The report as text lines: one row per value, one column per method (median [q25, q75]; a method at
    a pinch point the gripper could not hold is headed "METHOD (infeasible)")."""
    methods = report["methods"]
    metric = "improvement over none, %" if report["metric"] == "improvement_pct" else "error, % of sheet"
    lines = [
        f"{report['contour']}: {report['study']} study, {report['trials']} trials; median [q25, q75] {metric}"
    ]
    infeasible = report.get("infeasible_pinches") or {}
    heads = [f"{m} (infeasible)" if m in infeasible else m for m in methods]
    lines.append(f"{report['unit']:>20} " + " ".join(f"{m:>22}" for m in heads))
    for k, value in enumerate(report["values"]):
        cells = []
        for m in methods:
            med, lo, hi = (report[m][q][k] for q in ("median", "q25", "q75"))
            cells.append(f"{'-':>22}" if med is None else f"{med:>8.1f} [{lo:>5.1f}, {hi:>5.1f}]")
        mark = " (nominal)" if np.isclose(value, report["nominal"]) else ""
        lines.append(f"{value:>20g} " + " ".join(cells) + mark)
    counts = report.get("diverged") or {}
    for k, value in enumerate(report["values"]):
        words = _diverged_words({m: c[k] for m, c in counts.items()})
        if words:
            lines.append(f"at {value:g}: {words}")
    return lines


__all__ = ["check_job", "robustness", "robustness_study", "robustness_table"]


def check_job(job: RobustnessJob) -> RobustnessJob:
    """``job`` checked before any work, its studies in their one spelling (``all``: every study): its ranges
    (:meth:`~agents.jobs.RobustnessJob.check`), the studies and their values, the methods, the contour (or
    runs of it), each run a trained policy's and each plan an optimised one; ``ValueError`` naming the
    field."""
    job = job.check()
    studies = parse_studies(job.study)
    if job.values is not None and len(studies) != 1:
        raise ValueError("values: give the values of one study (or leave them out: each study's own)")
    for study in studies:
        check_study(study, job.values)
    check_methods(job.methods, "methods", STUDY_METHODS)
    if job.contour is None and not job.runs:
        raise ValueError("contour: give the contour (--contour), or trained runs of it (--run)")
    check_runs(job.runs)
    for label, path in job.plans.items():
        check_label("plans", label, taken=job.runs)
        read_plan(path)
    return dataclasses.replace(job, study=studies)


@claims_out("robustness")
def robustness(
    job: RobustnessJob,
    out: str | Path,
    *,
    resume: bool = False,
    overwrite: bool = False,
    device: str | None = None,
    log: Callable[[str], None] = lambda _: None,
    cluster: Executor | None = None,
) -> list[dict]:
    """``warpcut robustness``: :func:`robustness_study` for each of ``job.study``, in order.

    Args:
        job: The contour, studies, methods, runs, plans, sweep and trials
            (:class:`agents.jobs.RobustnessJob`).
        out: Run directory: ``config.json`` (the job), each study's ``robustness-STUDY.json`` as it finishes
            and ``grad/`` (the ``grad`` method's plan). Locked while it runs; refused if it holds another
            run (:func:`warpcut.io.claim_run_dir`).
        resume: Continue the run in ``out`` (started with the same job): a study already written is read
            back.
        overwrite: Delete what ``out`` holds first.
        device: Warp device.
        log: Called with each progress line.
        cluster: Where the studies' units run (:func:`robustness_study`); default: here.

    Returns:
        The studies' reports (:func:`robustness_study`'s), in order.
    """
    from warpcut.io import read_json

    job = check_job(job)  # before the job is recorded: bad settings leave no run behind
    out = Path(out)
    contour = None if job.contour is None else resolve_contour(job.contour)
    if not job.allow_infeasible_pinch and (job.runs or job.plans):  # before any work, too
        runs = check_runs(job.runs)
        if runs:
            scenario = nominal_scenario(contour, runs, job.sim, device, job.seed, log)
        else:
            scenario = {"contour": contour, "config": job.sim.validated(), "pinch": None, "segments": None}
        infeasible_pinches(scenario, job.methods, job.plans, runs, allow=False)
    if "generalist" in job.methods:  # before any work: a generalist to play (each unit loads its own)
        from agents.generalist import load_generalist

        load_generalist(job.generalist)
    record_job(out, job, resume)
    reports = []
    for study in job.study:
        path = out / f"robustness-{study}.json"
        if resume and path.is_file():
            log(f"  {study}: kept {path}")
            reports.append(read_json(path))
            continue
        log(f"{study} study")
        report = robustness_study(
            contour, study, out, runs=job.runs or None, plans=job.plans or None, methods=job.methods,
            values=job.values, trials=job.trials, config=job.sim, grad=job.grad, device=device, seed=job.seed,
            log=log, allow_infeasible_pinch=job.allow_infeasible_pinch, generalist=job.generalist,
            cluster=cluster,
        )  # fmt: skip
        reports.append(report)
    return reports
