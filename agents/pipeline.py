"""warpcut's two pipelines as library calls, with their presets; the ``run`` and ``evaluate`` commands are
thin wrappers over them.

* :func:`run_pipeline`: plan one contour (segments, order, pinch candidates scored with fixed tension), let
  a tensioner choose the candidate (RL: a PPO policy per candidate, the one that validates best wins), then
  compare none / fixed / analytic / RL over seeded trials.
* :func:`evaluate_table`: the paper's Table I protocol over a suite of contours: per contour the
  no-tension error and each method's paired improvement with its 95% CI, and the mean row.

Both write their data (plans, results, trained policies) into a run directory and return a report; what
to print, plot or record is the caller's.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import inspect
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from agents.baselines import AnalyticTension
from agents.config import (
    ANALYTIC_PINCHES,
    BUDGETS,
    DEFAULT_BUDGET,
    DEFAULT_SELECTOR,
    EVALUATION_CANDIDATES,
    EVALUATION_TRIALS,
    GRAD_CONFIG,
    RECIPES,
    SHARED_BASE_PLAN,
    VALIDATION_TRIALS,
    GradConfig,
    Recipe,
    TrainConfig,
    iterations_text,
)
from agents.evaluation import Method, MethodResult, evaluate_suite, run_method
from agents.gradient import base_plan_options, grad_column
from agents.methods import SELECTORS, TABLE_METHODS, StepCallbacks, check_methods, point_text
from agents.rl import check_policy_run, is_run, nominal_validation_error, rollout_errors, train_contour
from envs.options import PatternCutOptions
from warpcut.contours import Contour, load_contour, resolve_contours
from warpcut.io import claim_run_dir, finite_json, read_json, safe_name, write_json
from warpcut.planning import ArmModel, Plan, plan_cut
from warpcut.sim.config import SimConfig


class TrainingInterrupted(KeyboardInterrupt):
    """Ctrl-C while a pipeline trained a policy: the checkpoint is saved in ``run_dir``."""

    def __init__(self, run_dir: Path):
        super().__init__(str(run_dir))
        self.run_dir = run_dir


def train_policy(
    options: PatternCutOptions,
    run_dir: Path,
    recipe: Recipe,
    *,
    iterations: int,
    num_envs: int,
    seed: int,
    eval_trials: int,
    progress: bool,
    resume: bool = False,
    label: str | None = None,
) -> dict:
    """Train a policy with ``recipe`` for ``options`` (``options`` carry the recipe's env fields) into
    ``run_dir`` (:func:`agents.rl.train_contour`); Ctrl-C (or SIGTERM/SIGHUP, see the CLI) raises
    :class:`TrainingInterrupted` naming the run directory. Returns the training summary.

    With ``resume`` a run already completed in ``run_dir`` is kept (its summary returned), and one that was
    interrupted continues from its checkpoint; without a checkpoint it starts again."""
    if resume and finished_run(run_dir):
        return read_json(Path(run_dir) / "summary.json")
    discrete = options.action_type == "discrete"
    cfg = TrainConfig(
        **{"discrete": discrete, **recipe.train, "num_envs": num_envs, "iterations": iterations, "seed": seed}
    )
    checkpoint = resume and any(Path(run_dir).glob("*.pt"))
    try:
        result = train_contour(
            options, run_dir, cfg, eval_trials=eval_trials, progress=progress,
            validation_trials=recipe.validation_trials, resume=run_dir if checkpoint else None, label=label,
        )  # fmt: skip
        return result["summary"]
    except KeyboardInterrupt as interrupt:
        raise TrainingInterrupted(run_dir) from interrupt


def finished_run(run_dir: str | Path) -> bool:
    """Whether ``run_dir`` holds a training run that completed and was evaluated (a pipeline's ``resume``
    keeps it)."""
    run_dir = Path(run_dir)
    summary, evaluation = run_dir / "summary.json", run_dir / "evaluation.json"
    if not (summary.is_file() and evaluation.is_file()):
        return False
    return read_json(summary).get("status") == "completed"


REQUEST_FILE = "request.json"
"""What a pipeline's run directory was asked for (its arguments), so that ``resume`` continues the same
run."""


def _claims_out(pipeline: Callable) -> Callable:
    """Run ``pipeline`` with its run directory ``out`` claimed (:func:`warpcut.io.claim_run_dir` with its
    ``resume`` and ``overwrite`` arguments): locked against a second process, and refused if it holds
    another run."""
    signature = inspect.signature(pipeline)

    @functools.wraps(pipeline)
    def claimed(*args, **kwargs):
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        given = bound.arguments
        with claim_run_dir(given["out"], resume=given["resume"], overwrite=given["overwrite"]):
            return pipeline(*args, **kwargs)

    return claimed


def _record_request(out: Path, command: str, resume: bool, **arguments) -> None:
    """Write ``out/request.json``; with ``resume``, first check that ``arguments`` are those the run was
    started with (a ValueError names each difference)."""
    request = {"command": command, "arguments": _jsonable(arguments)}
    path = out / REQUEST_FILE
    if resume and path.is_file():
        before = read_json(path)
        if before.get("command") != command:
            raise ValueError(f"--resume: {out} holds a '{before.get('command')}' run, not '{command}'")
        old, new = before.get("arguments", {}), request["arguments"]
        changed = [k for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k)]
        if changed:
            shown = "; ".join(f"{k}: {old.get(k)!r} then, {new.get(k)!r} now" for k in changed)
            raise ValueError(
                f"--resume: {out} was started with other settings ({shown}); repeat the run's settings, "
                "or start a new run (another --out, or --overwrite)"
            )
    write_json(path, request)


def _jsonable(obj):
    """``obj`` as :func:`~warpcut.io.write_json` would write and read it back (tuples as lists, dataclasses
    as dicts, paths as strings)."""

    def plain(value):
        return finite_json(dataclasses.asdict(value)) if dataclasses.is_dataclass(value) else str(value)

    return json.loads(json.dumps(finite_json(obj), default=plain))


def _check_checkpoints(
    checkpoints: Path,
    contours: list[Contour],
    config: SimConfig,
    recipe: Recipe,
    allow_partial: bool,
) -> None:
    """Refuse ``checkpoints`` unless it holds, for every contour, a finished run (or any, with
    ``allow_partial``) trained on that contour, with the recipe's observations and actions and the same
    simulation settings (:func:`agents.rl.check_policy_run`)."""
    for contour in contours:
        run = checkpoints / safe_name(contour.name)
        if not is_run(run):
            raise ValueError(
                f"checkpoints: no trained run for {contour.name!r} at {run} "
                "(expected CHECKPOINTS/NAME/options.json from 'warpcut train --out')"
            )
        requested = PatternCutOptions(contour=contour, sim_config=config, **recipe.options)
        check_policy_run(run, requested, allow_partial=allow_partial)


def _contour_key(spec: str, contour: Contour) -> dict:
    """How a request names a contour: as given, its name, and a digest of its points."""
    digest = hashlib.sha1(np.ascontiguousarray(contour.points, dtype=np.float64).tobytes()).hexdigest()[:12]
    return {"spec": spec, "name": contour.name, "points_sha1": digest}


def analytic_pinches(mode: str, contours: Sequence[Contour], plans: Sequence[Plan] | None) -> list | None:
    """Per contour, the analytic policy's pinch point for ``mode`` (:data:`ANALYTIC_PINCHES`); None: its own
    default, the feasible centroid without an arm footprint."""
    if mode not in ANALYTIC_PINCHES:
        raise ValueError(f"analytic_pinch: choose one of {', '.join(ANALYTIC_PINCHES)} (got {mode!r})")
    if mode == "centroid":
        return [np.asarray(c.centroid, dtype=np.float64) for c in contours]
    return None if plans is None else [p.analytic_pinch for p in plans]


# --- run_pipeline ---------------------------------------------------------------------------------------


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


@_claims_out
def run_pipeline(
    contour: str,
    out: str | Path,
    *,
    resume: bool = False,
    overwrite: bool = False,
    budget: str = DEFAULT_BUDGET,
    selector: str = DEFAULT_SELECTOR,
    shared_policy: bool = False,
    recipe: Recipe = RECIPES["warpcut"],
    candidates: int | None = None,
    rl_candidates: int | None = None,
    iterations: int | None = None,
    trials: int | None = None,
    num_envs: int | None = None,
    config: SimConfig | None = None,
    arm: ArmModel | None = None,
    analytic_pinch: str = ANALYTIC_PINCHES[0],
    device: str | None = None,
    seed: int = 0,
    log: Callable[[str], None] = lambda _: None,
    progress: bool = True,
    step_callbacks: StepCallbacks | None = None,
) -> RunReport:
    """Plan ``contour``, choose the pinch candidate with ``selector``, evaluate every method.

    Args:
        contour: Built-in name or contour file.
        out: Run directory: ``plan.json``, ``results.json`` and the policies (``rl/candidate-K/``, or
            ``rl/`` for a shared policy). Locked while the pipeline runs; refused if it holds another run
            (see :func:`warpcut.io.claim_run_dir`).
        resume: Continue the run in ``out`` (started with the same arguments, ``request.json``): policies
            trained to the end are kept, interrupted ones continue from their checkpoints.
        overwrite: Delete what ``out`` holds first.
        budget: A :data:`BUDGETS` preset; ``candidates``, ``rl_candidates``, ``iterations`` and ``trials``
            override its fields.
        selector: ``rl`` (a PPO policy per candidate; the one that validates best wins), ``fixed`` (the
            plan's choice) or ``analytic`` (each candidate scored with the analytic policy, noise-free).
        shared_policy: With rl: one policy for all the candidates, observing its pinch point.
        recipe: How rl policies are trained (:data:`agents.config.RECIPES`).
        num_envs: Envs per policy (default: :func:`agents.config.batch_defaults`; shared: >= 8 a candidate).
        config: Simulation settings (default: ``SimConfig()``).
        arm: The cutting arm's footprint for pinch feasibility (default: the paper's).
        analytic_pinch: :data:`ANALYTIC_PINCHES`.
        device: Warp device.
        seed: Seed of everything random.
        log: Called with each progress line.
        progress: Show PPO's progress bars.
        step_callbacks: Step callbacks of the evaluation's batches (:data:`agents.methods.StepCallbacks`).
    """
    overrides = dict(candidates=candidates, rl_candidates=rl_candidates, iterations=iterations, trials=trials)
    settings = _settings(budget, selector, overrides, recipe)
    config = (config or SimConfig()).validated()
    out = Path(out)
    loaded = load_contour(contour)
    _record_request(
        out, "run", resume, contour=_contour_key(contour, loaded), budget=budget, selector=selector,
        shared_policy=shared_policy, recipe=recipe, **settings, num_envs=num_envs, config=config,
        arm=arm or ArmModel(), analytic_pinch=analytic_pinch, seed=seed,
    )  # fmt: skip
    start = time.perf_counter()

    sampled = f"{settings['candidates']} sampled pinch candidates (+ the centroid if feasible)"
    log(f"[1/3] planning {loaded.name}: {sampled}")
    plan = plan_cut(
        loaded, config, num_candidates=settings["candidates"], seed=seed, device=device, arm=arm or ArmModel()
    )
    write_json(out / "plan.json", plan.to_json())
    pinch = plan.chosen["pinch"]
    log(
        f"      {len(plan.segments)} segment(s), order {list(plan.order)}, pinch "
        f"{point_text(pinch)} with fixed tension: {plan.chosen['error_vertices']:.1f} vertices"
    )
    listed = _ranked_candidates(plan, settings["rl_candidates"] if selector == "rl" else None)
    analytic = Method("analytic", pinches=analytic_pinches(analytic_pinch, [loaded], [plan]))
    runs: list[Path] = []
    rl_dir = None
    if selector == "fixed":
        chosen = 0  # the plan's choice: the best candidate by fixed tension
        log("[2/3] --policy fixed: the plan's pinch and order")
    elif selector == "analytic":
        log(f"[2/3] scoring the analytic policy at {len(listed)} pinch candidate(s)")
        chosen = _choose_by_analytic(loaded, plan, listed, config, device, seed)
        best = listed[chosen]
        analytic = Method(
            "analytic", pinches=[np.asarray(best["pinch"])], segments=[plan.ordered_segments(best["order"])]
        )
    else:
        train = dict(
            iterations=settings["iterations"], seed=seed, eval_trials=settings["trials"], resume=resume
        )
        rl_dir, chosen, runs = _train_candidates(
            contour, plan, listed, config, out, shared_policy, recipe, num_envs, device, train, log, progress
        )
    log(f"      chosen by {selector}: {_candidate_text(listed[chosen])}")

    methods = ["none", "fixed", "analytic"] + (["rl"] if selector == "rl" else [])
    log(f"[3/3] evaluating {', '.join(methods)}: {settings['trials']} trials each")
    specs = [Method("none"), Method("fixed", pinches=[pinch]), analytic]
    if rl_dir is not None:
        on_step = None if step_callbacks is None else step_callbacks("rl", 0)
        # Paired: the noise of the baselines' trials (evaluate_suite below, same seed).
        rl = rollout_errors(rl_dir, settings["trials"], seed + 1, device, on_step, paired_noise=(seed, 0))
        specs.append(Method("rl", result=MethodResult.from_rollouts([rl])))
    table = evaluate_suite(
        [loaded],
        specs,
        trials=settings["trials"],
        config=config,
        device=device,
        seed=seed,
        segments=[plan.ordered_segments()],
        step_callbacks=step_callbacks,
    )
    report = RunReport(
        loaded, config, plan, selector, methods, table, listed, chosen, budget, analytic_pinch,
        time.perf_counter() - start, runs,
    )  # fmt: skip
    write_json(out / "results.json", report.to_json())
    return report


def _settings(budget: str, selector: str, overrides: dict, recipe: Recipe) -> dict:
    """``run_pipeline``'s budget with the ``overrides`` that are not None. The budgets' iterations are PPO's:
    an APG or es recipe trains its own (:func:`agents.config.batch_defaults`) unless ``iterations`` is
    given."""
    if budget not in BUDGETS:
        raise ValueError(f"budget: choose one of {', '.join(BUDGETS)} (got {budget!r})")
    if selector not in SELECTORS:
        raise ValueError(f"selector: choose one of {', '.join(SELECTORS)} (got {selector!r})")
    chosen = dict(BUDGETS[budget])
    if recipe.train.get("algorithm", "ppo") != "ppo":
        chosen["iterations"] = recipe.batch["iterations"]
    return {**chosen, **{k: v for k, v in overrides.items() if v is not None}}


def _ranked_candidates(plan: Plan, keep: int | None) -> list[dict]:
    """The plan's candidates, best by fixed tension first (the first ``keep``; None: all)."""
    ranked = sorted(range(len(plan.candidates)), key=lambda c: plan.candidates[c]["error_vertices"])
    return [
        {
            "pinch": [float(v) for v in c["point"]],
            "order": [int(k) for k in c["best_order"]],
            "fixed_error_vertices": float(c["error_vertices"]),
        }
        for c in (plan.candidates[k] for k in ranked[:keep])
    ]


def _candidate_text(candidate: dict) -> str:
    """A candidate's pinch, order and scores, as the progress lines show them."""
    scores = ("fixed_error_vertices", "analytic_error_vertices", "rl_validation_error_vertices")
    return (
        f"pinch {point_text(candidate['pinch'])}, order {candidate['order']}"
        + "".join(f", {k.split('_')[0]} {candidate[k]:.1f}" for k in scores if k in candidate)
        + " vertices"
    )


def _choose_by_analytic(
    contour: Contour, plan: Plan, listed: list[dict], config: SimConfig, device: str | None, seed: int
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
    ).error_vertices[:, 0]
    for c, e in zip(listed, scores, strict=True):
        c["analytic_error_vertices"] = float(e)
    return int(np.argmin(scores))


def _train_candidates(
    contour: str,
    plan: Plan,
    listed: list[dict],
    config: SimConfig,
    out: Path,
    shared: bool,
    recipe: Recipe,
    num_envs: int | None,
    device: str | None,
    train: dict,
    log: Callable[[str], None],
    progress: bool,
) -> tuple[Path, int, list[Path]]:
    """The rl selector: a PPO policy per candidate in ``listed`` (or one shared by all), each candidate cut
    in its best order; records each candidate's validation error in ``listed``. Returns the winner's run
    directory, its index (the first, i.e. the better fixed rank, among ties) and every run directory."""
    if shared and recipe.base_plan:
        raise ValueError(SHARED_BASE_PLAN)
    cuts = [[s.tolist() for s in plan.ordered_segments(c["order"])] for c in listed]
    common = dict(contour=contour, sim_config=config, device=device, **recipe.options)
    batch = recipe.batch["num_envs"]
    if shared:
        envs = num_envs or max(batch, 8 * len(listed))
        choices = [{"pinch": c["pinch"], "segments": s} for c, s in zip(listed, cuts, strict=True)]
        jobs = [(out / "rl", PatternCutOptions(candidates=choices, **common))]
        what = f"one RL policy shared by {len(listed)} pinch candidate(s) ({envs} envs"
    else:
        envs = num_envs or batch
        jobs = [
            (out / "rl" / f"candidate-{k}", PatternCutOptions(pinch_point=c["pinch"], segments=s, **common))
            for k, (c, s) in enumerate(zip(listed, cuts, strict=True))
        ]
        if recipe.base_plan == "grad":  # each candidate's policy on its own grad plan (out/grad/candidate-K)
            jobs = [
                (run_dir, PatternCutOptions.build(options, **base_plan_options(
                    plan.contour, {"pinch_point": c["pinch"], "segments": s}, out / "grad" / f"candidate-{k}",
                    config, (GRAD_CONFIG, ArmModel()), device, train["seed"], log,
                )))
                for k, ((run_dir, options), c, s) in enumerate(zip(jobs, listed, cuts, strict=True))
            ]  # fmt: skip
        what = f"an RL policy for each of the best {len(listed)} pinch candidate(s) ({envs} envs each"
    log(f"[2/3] training {what}, {iterations_text(train['iterations'])})")
    for k, (run_dir, options) in enumerate(jobs):
        label = f"{recipe.train.get('algorithm', TrainConfig.algorithm).upper()} {plan.contour.name}, " + (
            f"{len(listed)} candidates"
            if shared
            else f"candidate {k + 1}/{len(jobs)} {point_text(listed[k]['pinch'])}"
        )
        summary = train_policy(
            options, run_dir, recipe, num_envs=envs, progress=progress, label=label, **train
        )
        if shared:
            errors = summary["candidates"]["validation_error_vertices"]
            for c, e in zip(listed, errors, strict=True):
                c["rl_validation_error_vertices"], c["run"] = e, str(run_dir.relative_to(out))
            return run_dir, int(summary["candidates"]["chosen"]), [run_dir]
        listed[k]["rl_validation_error_vertices"] = summary["best"]["validation_error"]
        listed[k]["rl_best_iteration"] = summary["best"]["iterations"]
        if options.randomize or options.relative_reward:  # validated off the nominal sheet: compare there
            listed[k]["rl_training_validation_error"] = summary["best"]["validation_error"]
            listed[k]["rl_validation_error_vertices"] = nominal_validation_error(
                run_dir, recipe.validation_trials or VALIDATION_TRIALS, train["seed"], device
            )
        listed[k]["run"] = str(run_dir.relative_to(out))
        log(
            f"      candidate {point_text(listed[k]['pinch'])}: fixed "
            f"{listed[k]['fixed_error_vertices']:.1f}, rl {listed[k]['rl_validation_error_vertices']:.1f} "
            f"vertices (validation{', nominal sheet' if 'rl_training_validation_error' in listed[k] else ''})"
        )
    chosen = min(range(len(listed)), key=lambda k: (listed[k]["rl_validation_error_vertices"], k))
    return out / listed[chosen]["run"], chosen, [run_dir for run_dir, _ in jobs]


# --- evaluate_table -------------------------------------------------------------------------------------


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
        """The table as Markdown: per contour the no-tension error and each method's improvement ± CI."""
        shown = [m for m in self.methods if m != "none"]
        head = "| contour | no tension (vertices) | " + " | ".join(f"{m} (%)" for m in shown) + " |"
        lines = [head, "|---|---|" + "---|" * len(shown)]
        for row in self.table["rows"]:
            cells = [f"{row[f'{m}_improvement_pct']:+.1f} ± {row[f'{m}_ci95']:.1f}" for m in shown]
            lines.append(
                f"| {row['contour']} | {row['none_error_vertices']:.1f} | " + " | ".join(cells) + " |"
            )
        mean = self.table["mean"]
        cells = [f"{mean[f'{m}_improvement_pct']:+.1f} ± {mean[f'{m}_ci95']:.1f}" for m in shown]
        lines.append("| **mean** | | " + " | ".join(cells) + " |")
        return "\n".join(lines)


@_claims_out
def evaluate_table(
    contours: str | Sequence[str],
    out: str | Path,
    *,
    resume: bool = False,
    overwrite: bool = False,
    methods: Sequence[str] = TABLE_METHODS,
    trials: int = EVALUATION_TRIALS,
    config: SimConfig | None = None,
    checkpoints: str | Path | None = None,
    allow_partial: bool = False,
    recipe: Recipe = RECIPES["warpcut"],
    iterations: int | None = None,
    num_envs: int | None = None,
    plan: bool | Sequence[Plan] = True,
    candidates: int = EVALUATION_CANDIDATES,
    arm: ArmModel | None = None,
    analytic_pinch: str = ANALYTIC_PINCHES[0],
    grad: GradConfig = GRAD_CONFIG,
    device: str | None = None,
    seed: int = 0,
    log: Callable[[str], None] = lambda _: None,
    stages: Stages = lambda stage, done, total: None,
    step_callbacks: StepCallbacks | None = None,
) -> TableReport:
    """The paper's Table I protocol on ``contours``.

    Every contour is cut as planned (``plan``: segments and order; fixed and rl pinch at the planned point,
    analytic per ``analytic_pinch``), or without a plan as one loop (fixed by random search, rl and
    analytic at the feasible centroid). The rl column is a policy per contour: ``checkpoints/NAME`` when
    ``checkpoints`` is given (runs ``warpcut train`` wrote), else trained now with the recipe into
    ``out/policies/NAME``. Its trials draw the baselines' noise (paired).

    Args:
        contours: Built-in names or contour files (``all``: the built-in suite).
        out: Run directory: ``plans.json``, ``results.json``, ``policies/`` (a run per contour, named by
            ``safe_name``). Locked while it runs; refused if it holds another run (``claim_run_dir``).
        resume: Continue the run in ``out`` (started with the same arguments, ``request.json``): its plans
            and the policies trained to the end are kept, interrupted ones continue from their checkpoints.
        overwrite: Delete what ``out`` holds first.
        methods, trials: Names from :data:`agents.methods.METHODS`; trials per contour and method.
        config: Simulation settings (default ``SimConfig()``); plans are searched noise-free.
        checkpoints: Directory of trained runs, one per contour, each checked against the request.
        allow_partial: Accept checkpoints whose training was interrupted (their last saved policy).
        recipe: How rl policies are trained when there are no checkpoints (:data:`agents.config.RECIPES`).
        iterations, num_envs: Per contour when training (default: :func:`agents.config.batch_defaults`).
        plan: Plan every cut (see above); or the plans themselves, one per contour (e.g. to compare
            recipes on the same plans).
        candidates: Pinch candidates per plan.
        arm: The cutting arm's footprint for pinch feasibility (default: the paper's).
        analytic_pinch: :data:`ANALYTIC_PINCHES`.
        grad: The optimiser (:class:`~agents.config.GradConfig`) of the ``grad`` column and of a recipe on its
            plans: a plan per contour at the planned pinch (else the feasible centroid), in ``out/grad``.
        device: Warp device.
        seed: Seed of everything random.
        log: Called with each progress line.
        stages: Called as each stage advances (:data:`Stages`: planning, training rl, evaluating).
        step_callbacks: Step callbacks of the batches (``("rl", k)``: contour k's rollout).
    """
    methods = check_methods(methods, "methods")
    config, arm = (config or SimConfig()).validated(), arm or ArmModel()
    batch = recipe.batch
    iterations, num_envs = iterations or batch["iterations"], num_envs or batch["num_envs"]
    out = Path(out)
    named = resolve_contours(contours)
    loaded = [c for _, c in named]
    if checkpoints is not None and "rl" in methods:
        _check_checkpoints(Path(checkpoints), loaded, config, recipe, allow_partial)
    _record_request(
        out, "evaluate", resume, contours=[_contour_key(spec, c) for spec, c in named], methods=list(methods),
        trials=trials, config=config, checkpoints=checkpoints, recipe=recipe, iterations=iterations,
        num_envs=num_envs, plan=plan if isinstance(plan, bool) else [p.contour.name for p in plan],
        candidates=candidates, arm=arm, analytic_pinch=analytic_pinch, seed=seed,
        **({"grad": grad} if "grad" in methods else {}),
    )  # fmt: skip
    start = time.perf_counter()
    settings = dict(num_candidates=candidates, seed=seed, device=device, arm=arm)
    plans = _table_plans(plan, loaded, config, settings, out, log, stages, resume)
    specs, runs, notes = [Method(m) for m in methods], [], []  # notes: add a column's own fields to the table
    for spec in specs:
        if spec.name == "fixed" and plans is not None:
            spec.pinches = [p.chosen["pinch"] for p in plans]
        elif spec.name == "analytic":
            spec.pinches = analytic_pinches(analytic_pinch, loaded, plans)
        elif spec.name == "rl":
            training = dict(
                recipe=recipe, iterations=iterations, num_envs=num_envs, resume=resume, grad=(grad, arm)
            )
            feedback = (log, step_callbacks, stages)
            spec.result, runs, kept = _rl_result(
                named, plans, checkpoints, out, trials, config, training, device, seed, *feedback
            )
            notes.append(functools.partial(_note_rl_iterations, kept))
        elif spec.name == "grad":
            spec.result, note = grad_column(
                loaded, plans, out, trials, config, (grad, arm), device, seed, log, step_callbacks
            )
            notes.append(note)
    batches = len({spec.name for spec in specs} | {"none"})  # evaluate_suite also runs none, the baseline
    running = iter(range(batches))
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
    )
    stages("evaluating", batches, batches)
    log(f"  evaluated {len(methods)} method(s) x {len(loaded)} contour(s) x {trials} trials")
    for note in notes:
        note(table)
    report = TableReport(
        loaded, methods, config, table, plans, analytic_pinch, time.perf_counter() - start, runs
    )
    write_json(out / "results.json", report.to_json())
    return report


Stages = Callable[[str, int, int], None]
"""``stages(stage, done, total)``: a pipeline's stage (e.g. "planning") has ``done`` of ``total`` steps
done (a progress bar per stage; ``warpcut evaluate`` draws them)."""


def _note_rl_iterations(kept: list[int | None], table: dict) -> None:
    """Which PPO iteration each contour's policy kept (``rl_policy_iteration``), and on how many contours
    model selection kept the initial policy (it holds still under the warpcut recipe)."""
    for row, iteration in zip(table["rows"], kept, strict=False):
        row["rl_policy_iteration"] = iteration
    if kept:
        table["rl_initial_policy_contours"] = sum(1 for it in kept if it == 0)


def _table_plans(
    plan: bool | Sequence[Plan],
    contours: list[Contour],
    config: SimConfig,
    settings: dict,
    out: Path,
    log: Callable[[str], None],
    stages: Stages,
    resume: bool = False,
) -> list[Plan] | None:
    """:func:`evaluate_table`'s plans: the ones given (checked against the contours), or made now with the
    plan search's ``settings`` (noise-free; written to ``out/plans.json``), or None (``plan`` False). With
    ``resume``, the plans ``out/plans.json`` holds are read back instead of searched again: the request
    (checked already) names the same contours, points and settings, and the search is deterministic."""
    if isinstance(plan, list | tuple):  # plans made already, one per contour
        plans = list(plan)
        if [p.contour.name for p in plans] != [c.name for c in contours]:
            raise ValueError("plan: give one Plan per contour, in the contours' order (or True / False)")
        return plans
    if not plan:
        return None
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
            return plans
    plans = _plan_all(contours, config, settings, log, stages)
    write_json(path, {p.contour.name: p.to_json() for p in plans})
    return plans


def _plan_all(
    contours: list[Contour], config: SimConfig, settings: dict, log: Callable[[str], None], stages: Stages
) -> list[Plan]:
    """Plan every contour (:func:`~warpcut.planning.plan_cut` with ``settings``), saying how far it got."""
    plans, started = [], time.perf_counter()
    for k, contour in enumerate(contours):
        log(f"  [{k + 1}/{len(contours)}] planning {contour.name} ({settings['num_candidates']} candidates)")
        stages("planning", k, len(contours))
        plans.append(plan_cut(contour, config, **settings))
    stages("planning", len(contours), len(contours))
    log(f"  planned {len(plans)} contour(s) in {time.perf_counter() - started:.0f} s")
    return plans


def _rl_result(
    named: list[tuple[str, Contour]],
    plans: list[Plan] | None,
    checkpoints: str | Path | None,
    out: Path,
    trials: int,
    config: SimConfig,
    training: dict,
    device: str | None,
    seed: int,
    log: Callable[[str], None],
    step_callbacks: StepCallbacks | None,
    stages: Stages,
) -> tuple[MethodResult, list[Path], list[int | None]]:
    """The rl column: per contour a run (from ``checkpoints`` or trained now with ``training``'s
    ``recipe``, ``iterations`` and ``num_envs``, at the planned pinch and segments when planned) rolled out
    for ``trials``, paired with the baselines' noise."""
    recipe = training["recipe"]
    rollouts, runs, iterations, started = [], [], [], time.perf_counter()
    for k, (spec, contour) in enumerate(named):
        if checkpoints is not None:
            run = Path(checkpoints) / safe_name(contour.name)
        else:
            run = out / "policies" / safe_name(contour.name)
            kept = training["resume"] and finished_run(run)
            verb = "kept" if kept else "training"
            count = f"[{k + 1}/{len(named)}]"
            log(f"  {count} {verb} rl for {contour.name} ({iterations_text(training['iterations'])})")
            planned = {}
            if plans is not None:
                planned = {
                    "pinch_point": [float(v) for v in plans[k].chosen["pinch"]],
                    "segments": [s.tolist() for s in plans[k].ordered_segments()],
                }
            if recipe.base_plan == "grad" and not kept:
                folder = out / "grad"  # the grad column's plans
                planned.update(
                    base_plan_options(contour, planned, folder, config, training["grad"], device, seed, log)
                )
            options = PatternCutOptions(
                contour=spec, sim_config=config, device=device, **recipe.options, **planned
            )
            train_policy(
                options, run, recipe, iterations=training["iterations"], num_envs=training["num_envs"],
                seed=seed, eval_trials=trials, progress=False, resume=training["resume"],
            )  # fmt: skip
            runs.append(run)
        iterations.append(policy_iteration(run))
        callback = None if step_callbacks is None else step_callbacks("rl", k)
        # Trial t sees the noise of the baselines' trial t of this contour (env k * trials + t there).
        rollouts.append(
            rollout_errors(
                run, trials, seed=seed + 1, device=device, on_step=callback, paired_noise=(seed, k * trials)
            )
        )
        stages("training rl" if checkpoints is None else "rolling out rl", k + 1, len(named))
    what = "trained" if checkpoints is None else "rolled out"
    log(f"  rl: {what} {len(named)} policy(ies) in {time.perf_counter() - started:.0f} s")
    return MethodResult.from_rollouts(rollouts), runs, iterations


def policy_iteration(run_dir: Path) -> int | None:
    """The PPO iteration whose policy a training run kept (0: the initial policy): the validated best, or
    the last without validation; None where the run has no summary."""
    path = Path(run_dir) / "summary.json"
    if not path.is_file():
        return None
    summary = read_json(path)
    return int(summary["best"]["iterations"] if summary.get("best") else summary["iterations"])
