"""The jobs on one contour: ``warpcut train`` (:class:`TrainJob`), ``run`` (:class:`RunJob`, the main job),
``optimize`` (:class:`OptimizeJob`), ``simulate`` (:class:`SimulateJob`) and ``robustness``
(:class:`RobustnessJob`)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from agents.config import (
    ANALYTIC_PINCHES,
    BUDGETS,
    DEFAULT_BUDGET,
    DEFAULT_CONTOUR,
    DEFAULT_SELECTOR,
    EVALUATION_CANDIDATES,
    EVALUATION_TRIALS,
    FINE_TUNING_GAIN,
    TrainConfig,
)
from agents.jobs.fields import (
    _check_fields,
    _counted,
    _grad_validated,
    _names,
    _pinch_keys,
    _recording_keys,
    _sim_validated,
    other_learners,
)
from agents.methods import BASELINES, SELECTORS, SIMULATED, check_methods
from agents.plan_optimizer.config import GRAD_CONFIG, GradConfig
from envs.options import ENV_FIELDS, EnvConfig, PatternCutOptions
from warpcut.planning.feasibility import ArmModel
from warpcut.sim.config import SimConfig
from warpcut.validation import (
    fail,
    is_number,
)


@dataclass
class TrainJob:
    """``warpcut train``: a policy for one contour, trained into a run directory and evaluated against no
    tension. A run directory's ``config.json`` is this job; ``warpcut train --config DIR/config.json`` runs it
    again."""

    contour: str | dict | None = None
    """The contour: a built-in name (``warpcut contours``), a ``.json``/``.svg`` file, or the contour itself
    (``{name, closed, points}``, as a run directory stores a contour that is not built in)."""
    pinch: list[float] | None = None
    """Pinch point ``[x, y]`` (mm, material coordinates); one the gripper could not hold (on or near the cut
    line, under the cutting arm) is refused unless ``allow_infeasible_pinch``. None: the centroid, or the
    feasible point nearest it; fine-tuning (``init``) with neither ``pinch`` nor ``segments`` given: where
    the generalist plays the contour (:func:`agents.generalist.generalist_cut`: the plan's candidate it
    validates best at, and its segments)."""
    allow_infeasible_pinch: bool = False
    """Train at a ``pinch`` the gripper could not hold (:func:`warpcut.planning.pinch_problems`) all the
    same; ``summary.json`` and ``evaluation.json`` mark it (``pinch_feasible``: false, ``pinch_problem``)."""
    arm: ArmModel = field(default_factory=ArmModel)
    """The cutting arm's footprint, for pinch feasibility."""
    segments: list | None = None
    """The polylines (mm) the scissors cut, in order (a plan's); None: the whole contour as one segment."""
    seed: int = 0
    """Seed of everything random: the episodes' noise and fiducials, the policy's initialisation and its
    learner's streams; validation derives its own episodes from it."""
    eval_trials: int = EVALUATION_TRIALS
    """Trials of the final evaluation against no tension (seed ``seed + 1``)."""
    sim: SimConfig = field(default_factory=SimConfig)
    """The physics and the protocol (noise, score)."""
    env: EnvConfig = field(default_factory=EnvConfig)
    """What the policy observes, how it acts and is rewarded."""
    train: TrainConfig = field(default_factory=TrainConfig)
    """The learner and its settings."""
    init: str | None = None
    """Start from a generalist's policy instead of "hold still" (fine-tuning; es only): ``generalist`` (the
    one warpcut ships) or a run directory of ``warpcut generalist``. The env then observes as the generalist
    does (its look-ahead), unless ``env.*`` says otherwise. None: a fresh policy."""
    init_gain: float = FINE_TUNING_GAIN
    """The factor on the generalist's moves that fine-tuning (``init``) starts from: its last layer and
    feedback gains scaled (es's moves are continuous; 1: its moves as they are). Default
    :data:`~agents.config.FINE_TUNING_GAIN`."""
    record: int | None = None
    """Write ``recording.rrd`` of the final evaluation's first N envs (rerun); None: no recording."""
    colour_by: str = "strain"
    """What the recorded sheet's vertex colours show: ``strain`` or ``height``."""
    video: int | None = None
    """Write an MP4 of the final evaluation's first N envs; None: no video."""
    plots: bool = True
    """Write ``learning_curve.png/svg``."""

    def __post_init__(self) -> None:
        _check_fields(self)

    @property
    def at_generalists_cut(self) -> bool:
        """Whether it fine-tunes where its generalist plays the contour (``init``, and neither ``pinch`` nor
        ``segments`` given: :attr:`pinch`)."""
        return self.init is not None and self.pinch is None and self.segments is None

    def options(self, device: str | None = None) -> PatternCutOptions:
        """The env's options for this job (the contour loaded where it is given inline)."""
        if self.contour is None:
            raise ValueError("contour: give the contour to train on (--contour), or --resume a run")
        return PatternCutOptions(
            contour=self.contour,
            pinch_point=self.pinch,
            segments=self.segments,
            sim_config=self.sim,
            device=device,
            arm=self.arm,
            allow_infeasible_pinch=self.allow_infeasible_pinch,
            **{name: getattr(self.env, name) for name in ENV_FIELDS},
        )

    @classmethod
    def for_options(
        cls, options: PatternCutOptions, train: TrainConfig, seed: int, eval_trials: int
    ) -> TrainJob:
        """The job that trains ``train``'s learner in ``options`` (e.g. a pipeline's policy for one contour at
        one pinch candidate); its contour stored by name or inline, so the job runs from any directory."""
        data = options.to_dict()
        return cls(
            contour=data["contour"],
            pinch=data["pinch_point"],
            allow_infeasible_pinch=options.allow_infeasible_pinch,
            arm=options.arm,
            segments=data["segments"],
            seed=seed,
            eval_trials=eval_trials,
            sim=options.config(),
            env=PatternCutOptions.env_settings(options),
            train=train,
        )

    def unused_keys(self) -> dict[str, str]:
        """The keys this job would not use, ``{key: when it applies}`` (a setting given for nothing is
        refused, not ignored: :func:`agents.cli.settings.refuse_unused_settings`): the other learners'
        sections, the recording's colours without a recording, and ``allow_infeasible_pinch`` without a
        ``pinch``."""
        return {**other_learners(self.train), **_recording_keys(self), **_pinch_keys(self.pinch is None)}


@dataclass
class RunJob:
    """``warpcut run``, the main job: plan one contour (segments, order, pinch candidates scored with fixed
    tension), let a tensioner choose the candidate (``rl``: a policy trained for each of the best
    ``rl_candidates``, the one that validates best wins), then compare none, fixed, analytic and rl over
    seeded trials."""

    contour: str | dict = DEFAULT_CONTOUR
    """The contour: a built-in name, a ``.json``/``.svg`` file, or the contour itself."""
    budget: str = DEFAULT_BUDGET
    """``fast`` (8 candidates, a policy for the best one, 10 trials: about a minute on 2 CPU cores) or
    ``paper`` (the paper's 30 candidates, a policy for each); the generalist's plan has 30 with either."""
    policy: str = DEFAULT_SELECTOR
    """The tensioner that chooses the pinch candidate: ``rl``; ``generalist`` (one policy for every contour,
    no training: seconds); or ``fixed`` / ``analytic`` for a quick plan."""
    generalist: str = "generalist"
    """The generalist ``policy: generalist`` plays: ``generalist`` (the one warpcut ships) or a run
    directory of ``warpcut generalist``."""
    candidates: int | None = None
    """Pinch candidates sampled for the plan (None: the budget's; with ``policy: generalist``, 30)."""
    rl_candidates: int | None = None
    """How many of the best candidates (by fixed tension) get a policy (None: the budget's)."""
    trials: int | None = None
    """Seeded trials of the evaluation (None: the budget's)."""
    analytic_pinch: str = ANALYTIC_PINCHES[0]
    """Where the analytic controller pinches: ``feasible`` (the centroid, or the feasible point nearest it)
    or ``centroid`` (the paper's literal choice, even where the robot could not grasp)."""
    arm: ArmModel = field(default_factory=ArmModel)
    """The cutting arm's footprint, for pinch feasibility (``arm.length_mm``: inf, the paper's cylinder)."""
    seed: int = 0
    """Seed of everything random."""
    sim: SimConfig = field(default_factory=SimConfig)
    """The physics and the protocol (noise, score)."""
    env: EnvConfig = field(default_factory=EnvConfig)
    """What the policies observe, how they act and are rewarded."""
    train: TrainConfig = field(default_factory=TrainConfig)
    """The learner and its settings (``train.iterations``: per policy)."""
    record: int | None = None
    """Write ``recording.rrd`` of the evaluation's first N envs of each method; None: none."""
    colour_by: str = "strain"
    """What the recorded sheet's vertex colours show: ``strain`` or ``height``."""
    plots: bool = True
    """Write the plots (regions, improvements, the pinch-candidate map, learning curves)."""

    def __post_init__(self) -> None:
        _check_fields(self)
        if self.budget not in BUDGETS:
            fail("RunJob.budget", f"choose one of {', '.join(BUDGETS)}", self.budget)
        if self.policy not in SELECTORS:
            fail("RunJob.policy", f"choose one of {', '.join(SELECTORS)}", self.policy)
        for name in ("candidates", "rl_candidates", "trials"):
            _counted(f"RunJob.{name}", getattr(self, name), optional=True)

    def settings(self) -> dict:
        """The budget's ``candidates`` (the generalist's with ``policy: generalist``), ``rl_candidates`` and
        ``trials``, with this job's where given."""
        budget = dict(BUDGETS[self.budget])
        generalist_candidates = budget.pop("generalist_candidates")
        if self.policy == "generalist":
            budget["candidates"] = generalist_candidates
        given = {"candidates": self.candidates, "rl_candidates": self.rl_candidates, "trials": self.trials}
        return {**budget, **{k: v for k, v in given.items() if v is not None}}

    def check(self) -> RunJob:
        """Itself, or ``ValueError`` naming what its fields do not say alone (each is checked as it is
        given): the physics, and with ``policy: rl`` whether the learner can train in the env."""
        _sim_validated(self.sim)
        if self.policy == "rl":
            self.train.check(self.env.action_type == "discrete")
        return self

    def unused_keys(self) -> dict[str, str]:
        """The keys this job would not use, ``{key: when it applies}``: the learner and its env without
        ``policy: rl``, the other learners' sections, the recording's colours without a recording."""
        if self.policy != "rl":
            why = "read by --policy rl only (it trains a policy per candidate)"
            unused = {key: why for key in ("train", "env", "rl_candidates")}
        else:
            unused = other_learners(self.train)
        if self.policy != "generalist":
            unused["generalist"] = "read by --policy generalist only"
        return {**unused, **_recording_keys(self)}


@dataclass
class OptimizeJob:
    """``warpcut optimize``: plan one contour's cut (segments, order and, unless ``pinch`` is given, the pinch
    point: fixed tension's best candidate), optimise a plan of grasp moves there through the simulator
    (``grad``: tape or es gradients; with es, feedback gains too), and evaluate it against no tension and
    fixed tension at the same pinch point over seeded trials (paired)."""

    contour: str | dict | None = None
    """The contour: a built-in name, a ``.json``/``.svg`` file, or the contour itself."""
    pinch: list[float] | None = None
    """Pinch point ``[x, y]`` (mm, material coordinates); one the gripper could not hold (on or near the cut
    line, under the cutting ``arm``) is refused unless ``allow_infeasible_pinch``. None: the plan's (fixed
    tension's best candidate)."""
    allow_infeasible_pinch: bool = False
    """Optimise at a ``pinch`` the gripper could not hold all the same; ``results.json`` marks it
    (``pinch_feasible``: false, ``pinch_problem``)."""
    candidates: int = EVALUATION_CANDIDATES
    """Pinch candidates sampled for the plan."""
    trials: int = EVALUATION_TRIALS
    """Seeded trials of the evaluation (none, fixed and grad, paired); the optimiser's episodes are others
    (``grad.trials``, ``grad.es_trials``)."""
    seed: int = 0
    """Seed of everything random: the plan, the optimiser's episodes and perturbations, the evaluation."""
    arm: ArmModel = field(default_factory=ArmModel)
    """The cutting arm's footprint, for pinch feasibility (a pinch point moved by ``grad.optimize_pinch``
    stays out of it)."""
    sim: SimConfig = field(default_factory=SimConfig)
    """The physics and the protocol (noise, score)."""
    grad: GradConfig = GRAD_CONFIG
    """The optimiser: its estimator, steps, episodes (``grad.iterations`` and ``grad.learning_rate``: the
    estimator's own unless given)."""

    def __post_init__(self) -> None:
        _check_fields(self)
        for name in ("candidates", "trials"):
            _counted(f"OptimizeJob.{name}", getattr(self, name))

    def check(self) -> OptimizeJob:
        """Itself (its ``grad`` ranges in their one spelling), or ``ValueError`` naming a field out of
        range."""
        if self.contour is None:
            raise ValueError("contour: give the contour to optimise for (--contour)")
        _sim_validated(self.sim)
        return dataclasses.replace(self, grad=_grad_validated(self.grad))

    def unused_keys(self) -> dict[str, str]:
        """The keys this job would not use, ``{key: when it applies}``: the optimiser's settings of the other
        estimator (:func:`agents.cli.settings.refuse_unused_settings`)."""
        es = [f.name for f in dataclasses.fields(GradConfig) if f.name.startswith("es_")]
        if self.grad.estimator == "es":
            unused = {f"grad.{k}": "read by estimator tape only (--estimator tape)" for k in TAPE_ONLY}
        else:
            unused = {f"grad.{k}": "read by estimator es only (--estimator es)" for k in es}
        return {**unused, **_pinch_keys(self.pinch is None)}


TAPE_ONLY = ("trials", "window", "pinch_learning_rate")
"""The :class:`~agents.plan_optimizer.config.GradConfig` fields only the tape estimator reads
(``optimize_pinch`` refuses es itself, as the closed-loop ``es_*`` fields refuse tape)."""


@dataclass
class RobustnessJob:
    """``warpcut robustness``: the paper's sensitivity studies (Fig. 5). Each study sweeps one setting of the
    simulation around the nominal sheet (``resolution``, ``noise``, ``force``: gravity) and scores every
    method at every value over the same seeded trials: the baselines, trained policies (``runs``),
    optimised plans (``plans``) and ``grad``, a plan optimised on the nominal sheet
    (:mod:`agents.pipelines.robustness`)."""

    contour: str | dict | None = None
    """The contour: a built-in name, a ``.json``/``.svg`` file, or the contour itself; None with ``runs``:
    the runs' contour."""
    study: list[str] = field(default_factory=list)
    """The studies to run, in order: ``resolution`` (vertices per side), ``noise`` (process noise, mm),
    ``force`` (gravity, mm/s^2), or ``all``."""
    methods: list[str] = field(default_factory=lambda: list(BASELINES))
    """The methods besides the runs' and plans': the baselines, ``generalist`` and ``grad``; ``none`` always
    runs, the others are measured against it."""
    generalist: str = "generalist"
    """The ``generalist`` method's policy: ``generalist`` (the one warpcut ships) or a run directory of
    ``warpcut generalist``."""
    runs: dict[str, str] = field(default_factory=dict)
    """Trained policies' runs of the contour (``warpcut train`` or ``run``), ``{label: run directory}``:
    each a method. The first sets the pinch point, the cut order and the nominal sheet (then ``sim`` is
    the run's own); none: fixed tension at the plan's pinch point on ``sim``'s sheet."""
    plans: dict[str, str] = field(default_factory=dict)
    """Optimised plans of the contour (``warpcut optimize``'s ``NAME.json``, or ``warpcut evaluate``'s
    ``grad/NAME.json``), ``{label: file}``: each a method, played as it was optimised (open or closed loop)
    at its own pinch point at every value."""
    allow_infeasible_pinch: bool = False
    """Accept runs and plans at a pinch point the gripper could not hold on the nominal sheet (on or near the
    cut line, under the cutting arm: :func:`warpcut.planning.pinch_problems`); the report marks them
    (``infeasible_pinches``)."""
    values: list[float] | None = None
    """The sweep of the one study given (vertices per side, mm or mm/s^2); None: each study's own
    (:data:`agents.pipelines.robustness_studies.STUDY_VALUES`)."""
    trials: int = EVALUATION_TRIALS
    """Seeded noisy trials per value and method (paired: trial k has the same noise in every method)."""
    seed: int = 0
    """Seed of everything random: the noise, the plan, ``grad``'s optimisation."""
    sim: SimConfig = field(default_factory=SimConfig)
    """The nominal sheet and the protocol (noise, score) without ``runs``."""
    grad: GradConfig = GRAD_CONFIG
    """The ``grad`` method's optimiser (only with ``grad`` in ``methods``)."""
    plots: bool = True
    """Write ``robustness.png/svg`` (the paper's Fig. 5, a panel per study)."""

    def __post_init__(self) -> None:
        _check_fields(self)
        _counted("RobustnessJob.trials", self.trials)
        values = self.values
        ok = values is None or isinstance(values, list | tuple) and all(is_number(v) for v in values)
        if not (ok and (values is None or all(math.isfinite(float(v)) for v in values))):
            fail("RobustnessJob.values", "a list of finite numbers (the study's units), or None", values)

    def check(self) -> RobustnessJob:
        """Itself (its ``grad`` ranges in their one spelling), or ``ValueError`` naming a field out of range;
        the studies, their values, runs and plans are the pipeline's to check
        (:func:`agents.pipelines.robustness.check_job`)."""
        for name in ("runs", "plans"):
            if not all(isinstance(v, str) and v for v in getattr(self, name).values()):
                raise ValueError(f"{name}: give {{label: path}}, each path a directory or file")
        _sim_validated(self.sim)
        return dataclasses.replace(self, grad=_grad_validated(self.grad))

    def unused_keys(self) -> dict[str, str]:
        """The keys this job would not use, ``{key: when it applies}``: ``grad`` without the grad method,
        ``sim`` with runs (:func:`agents.cli.settings.refuse_unused_settings`)."""
        unused = {}
        if "grad" not in self.methods:
            unused["grad"] = "read by the grad method only (--methods ...,grad)"
        if "generalist" not in self.methods:
            unused["generalist"] = "read by the generalist method only (--methods ...,generalist)"
        if self.runs:
            unused["sim"] = "with --run the nominal sheet is the run's"
        return {**unused, **_pinch_keys(not (self.runs or self.plans), "runs or plans (their pinch points)")}


@dataclass
class SimulateJob:
    """``warpcut simulate``: cut one contour with each baseline tensioner (no training) over seeded trials
    and compare their errors with no tension's."""

    contour: str | dict | None = None
    """The contour: a built-in name (``warpcut contours``), a ``.json``/``.svg`` file, or the contour
    itself."""
    policy: list[str] = field(default_factory=lambda: list(BASELINES))
    """The tensioners to compare: ``none``, ``fixed``, ``analytic``, ``generalist`` (one policy for every
    contour, no training)."""
    generalist: str = "generalist"
    """The generalist ``policy`` plays: ``generalist`` (the one warpcut ships) or a run directory of
    ``warpcut generalist``."""
    pinch: list[float] | None = None
    """Pinch point ``[x, y]`` (mm, material coordinates) of fixed, analytic and the generalist; one the
    gripper could not hold (on or near the cut line, under the cutting arm) is refused unless
    ``allow_infeasible_pinch``. None: fixed's best point by random search, analytic's and the generalist's
    feasible centroid."""
    allow_infeasible_pinch: bool = False
    """Simulate a ``pinch`` the gripper could not hold (:func:`warpcut.planning.pinch_problems`) all the
    same; the printed rows and ``--json`` mark it (``pinch_feasible``: false, ``pinch_problem``)."""
    trials: int = 1
    """Seeded trials per tensioner; they differ by their process noise (``sim.noise_std``)."""
    seed: int = 0
    """Seed of the trials' noise (and of fixed's pinch search)."""
    sim: SimConfig = field(default_factory=SimConfig)
    """The physics and the protocol: ``sim.noise_std``, ``sim.score``, ``sim.resolution``, ``sim.fixture``
    ..."""
    record: int | None = None
    """Write ``recording.rrd`` (next to ``--json``, or in ``logs/simulate-TIMESTAMP``) of each tensioner's
    first N envs; None: no recording."""
    colour_by: str = "strain"
    """What the recorded sheet's vertex colours show: ``strain`` or ``height`` (with ``record``)."""
    video: int | None = None
    """Write MP4 videos of each tensioner's first N envs where the recording goes; None: no video."""
    export_mesh: str | None = None
    """A directory: each tensioner's final sheet (its first trial) as ``POLICY_env0_stepN.glb`` (mm, z up,
    strain colours); None: no meshes."""
    plots: bool = True
    """Write ``regions.png/svg`` (each tensioner's cut region) where the recording goes."""

    def __post_init__(self) -> None:
        _check_fields(self)
        _names("SimulateJob.policy", self.policy, "tensioners")
        _counted("SimulateJob.trials", self.trials)

    def check(self) -> SimulateJob:
        """Itself, or ``ValueError`` naming what its fields do not say alone (each is checked as it is
        given): a contour, the tensioners, the physics."""
        if self.contour is None:
            raise ValueError("contour: give the contour to cut (--contour)")
        check_methods(self.policy, "policy", SIMULATED)
        _sim_validated(self.sim)
        return self

    def unused_keys(self) -> dict[str, str]:
        """The keys this job would not use, ``{key: when it applies}``: a setting given for nothing is
        refused, not ignored (:func:`agents.cli.settings.refuse_unused_settings`)."""
        unused = {}
        if not {"fixed", "analytic", "generalist"} & set(self.policy):
            runs = ",".join(self.policy)
            why = f"only fixed, analytic and generalist pinch, and policy is {runs} (add one to policy)"
            unused["pinch"] = unused["allow_infeasible_pinch"] = why
        else:
            unused |= _pinch_keys(self.pinch is None)
        if "generalist" not in self.policy:
            unused["generalist"] = "read by --policy ...,generalist only"
        if self.record is None:
            unused["colour_by"] = "colours a recording, and record is off (add --record [N])"
        return unused
