"""What each command runs, as a dataclass: the layout of its config file (``--config``), the keys of its
``--set`` overrides, what ``--print-config`` prints and what a run directory's ``config.json`` holds.

Every job has the same sections where it has them: ``sim`` (:class:`~warpcut.sim.config.SimConfig`: the
physics and the protocol, e.g. ``sim.noise_std``, ``sim.score``), ``env`` (:class:`~envs.options.EnvConfig`:
what a policy observes, how it acts and is rewarded, domain randomisation) and ``train``
(:class:`~agents.config.TrainConfig`: the learner, its batch and its own section, e.g. ``train.es.sigma``).
The flags of a command set a few of these keys; the rest keep their defaults unless a file or ``--set``
changes them.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from agents.config import (
    ANALYTIC_PINCHES,
    BUDGETS,
    DEFAULT_BUDGET,
    DEFAULT_CONTOUR,
    DEFAULT_SELECTOR,
    EVALUATION_CANDIDATES,
    EVALUATION_TRIALS,
    GENERALIST_CONTOURS,
    GENERALIST_LOOKAHEAD,
    GENERALIST_VALIDATION_CONTOURS,
    SEED_RANGE,
    STUDENT_DEFAULTS,
    TEACHER_CONTOURS,
    TrainConfig,
    generalist_train_config,
)
from agents.methods import BASELINES, SELECTORS, SIMULATED, TABLE_METHODS, check_methods
from agents.plan_optimizer.config import GRAD_CONFIG, GRAD_CONFIGS, GradConfig
from envs.options import ENV_FIELDS, EnvConfig, PatternCutOptions
from warpcut.planning.feasibility import ArmModel
from warpcut.planning.generate import EXTRA_KINDS, KINDS, MAX_CONTOURS
from warpcut.sim.config import SimConfig
from warpcut.validation import (
    ConfigError,
    check_choice,
    check_flag,
    check_instance,
    check_integer,
    check_text,
    fail,
    is_integer,
    is_number,
)
from warpcut.viz.colours import COLOUR_FIELDS


def _counted(where: str, value: Any, optional: bool = False, note: str = "the budget's") -> None:
    """A count (trials, candidates): an integer >= 1 (None where ``optional``)."""
    if optional and value is None:
        return
    if not (is_integer(value) and value >= 1):
        fail(where, "must be an integer >= 1" + (f", or null for {note}" if optional else ""), value)


def _names(where: str, value: Any, what: str) -> None:
    """A list of names (methods, studies, contours): never one string, which would be read letter by
    letter."""
    if not (isinstance(value, list | tuple) and all(isinstance(v, str) for v in value)):
        fail(where, f"a list of {what}", value)


def _paths(where: str, value: Any) -> None:
    if not (
        isinstance(value, dict) and all(isinstance(k, str) and isinstance(v, str) for k, v in value.items())
    ):
        fail(where, "a mapping {label: path}", value)


def _point(where: str, value: Any) -> None:
    if value is None:
        return
    ok = isinstance(value, list | tuple) and len(value) == 2 and all(is_number(v) for v in value)
    if not (ok and all(math.isfinite(float(v)) for v in value)):
        fail(where, "[x, y], finite numbers in mm, or None", value)


_FIELD_CHECKS = {
    "contour": lambda w, v: check_instance(
        w, v, (str, dict, type(None)), "a built-in name, a contour file, or a contour {name, closed, points}"
    ),
    "pinch": _point,
    "allow_infeasible_pinch": check_flag,
    "allow_partial": check_flag,
    "plan": check_flag,
    "plots": check_flag,
    "arm": lambda w, v: check_instance(w, v, ArmModel, "an ArmModel (length_mm, width_mm, ...)"),
    "segments": lambda w, v: check_instance(w, v, (list, tuple, type(None)), "a list of polylines, or None"),
    "seed": lambda w, v: check_integer(w, v, *SEED_RANGE),
    "eval_trials": _counted,
    "sim": lambda w, v: check_instance(w, v, SimConfig, "a SimConfig (the sim section)"),
    "env": lambda w, v: check_instance(w, v, EnvConfig, "an EnvConfig (the env section)"),
    "train": lambda w, v: check_instance(w, v, TrainConfig, "a TrainConfig (the train section)"),
    "grad": lambda w, v: check_instance(w, v, GradConfig, "a GradConfig (the grad section)"),
    "record": lambda w, v: check_integer(w, v, 1, optional=True, note="no recording"),
    "video": lambda w, v: check_integer(w, v, 1, optional=True, note="no video"),
    "colour_by": lambda w, v: v in COLOUR_FIELDS or fail(w, f"choose one of {', '.join(COLOUR_FIELDS)}", v),
    "export_mesh": lambda w, v: check_text(w, v, optional=True, note="no meshes"),
    "generalist": lambda w, v: check_text(w, v),
    "init": lambda w, v: check_text(w, v, optional=True, note="a fresh policy"),
    "checkpoints": lambda w, v: check_text(w, v, optional=True, note="train a policy per contour"),
    "analytic_pinch": lambda w, v: check_choice(w, v, ANALYTIC_PINCHES),
    "methods": lambda w, v: _names(w, v, "method names"),
    "study": lambda w, v: _names(w, v, "studies"),
    "contours": lambda w, v: _names(w, v, "contour names or files"),
    "runs": _paths,
    "plans": _paths,
}
"""How each job's field is checked as it is given, by its name (the same name means the same in every job);
the fields a job reads its own way are its ``__post_init__``'s."""


def _check_fields(job: Any) -> None:
    """``ConfigError`` naming ``Job.field`` for the first field that is not what it takes (each on its own:
    a file and ``--set`` set one key at a time; what depends on several fields is the job's ``check``)."""
    for f in dataclasses.fields(job):
        check = _FIELD_CHECKS.get(f.name)
        if check is not None:
            check(f"{type(job).__name__}.{f.name}", getattr(job, f.name))


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
    feasible point nearest it."""
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
    ``paper`` (the paper's 30 candidates, a policy for each)."""
    policy: str = DEFAULT_SELECTOR
    """The tensioner that chooses the pinch candidate: ``rl``; ``generalist`` (one policy for every contour,
    no training: seconds); or ``fixed`` / ``analytic`` for a quick plan."""
    generalist: str = "generalist"
    """The generalist ``policy: generalist`` plays: ``generalist`` (the one warpcut ships) or a run
    directory of ``warpcut generalist``."""
    candidates: int | None = None
    """Pinch candidates sampled for the plan (None: the budget's)."""
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
        """The budget's ``candidates``, ``rl_candidates`` and ``trials``, with this job's where given."""
        given = {"candidates": self.candidates, "rl_candidates": self.rl_candidates, "trials": self.trials}
        return {**BUDGETS[self.budget], **{k: v for k, v in given.items() if v is not None}}

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
class EvaluateJob:
    """``warpcut evaluate``: the paper's Table I protocol over a suite of contours: per contour the
    no-tension error and each method's paired improvement with its 95% CI, and the mean row."""

    contours: list[str] = field(default_factory=lambda: ["all"])
    """Built-in names or contour files; ``all``: the built-in suite."""
    methods: list[str] = field(default_factory=lambda: list(TABLE_METHODS))
    """The methods (``none``, ``fixed``, ``analytic``, ``rl``, ``generalist``, ``grad``)."""
    trials: int = EVALUATION_TRIALS
    """Seeded trials per contour and method (the paper's 10)."""
    candidates: int = EVALUATION_CANDIDATES
    """Pinch candidates per plan (the paper's 30)."""
    plan: bool = True
    """Plan every cut (segments, order, pinch); false: one loop, fixed by random search, rl and analytic
    at the feasible centroid."""
    checkpoints: str | None = None
    """A directory of trained runs, one per contour (``CHECKPOINTS/NAME``, as ``warpcut train`` writes):
    the rl column plays them instead of training a policy per contour."""
    allow_partial: bool = False
    """Accept checkpoint runs whose training was interrupted (their last saved policy)."""
    allow_infeasible_pinch: bool = False
    """Accept checkpoint runs trained at a pinch point the gripper could not hold (on or near the cut line,
    under the cutting arm: :func:`warpcut.planning.pinch_problems`); their rows are marked
    (``rl_pinch_feasible``: false, ``rl_pinch_problem``)."""
    analytic_pinch: str = ANALYTIC_PINCHES[0]
    """Where the analytic controller pinches: ``feasible`` or ``centroid``."""
    arm: ArmModel = field(default_factory=ArmModel)
    """The cutting arm's footprint, for pinch feasibility."""
    seed: int = 0
    """Seed of everything random."""
    sim: SimConfig = field(default_factory=SimConfig)
    """The physics and the protocol (noise, score)."""
    env: EnvConfig = field(default_factory=EnvConfig)
    """What the rl column's policies observe, how they act and are rewarded."""
    train: TrainConfig = field(default_factory=TrainConfig)
    """The rl column's learner (a policy per contour)."""
    grad: GradConfig = GRAD_CONFIG
    """The grad column's optimiser (an open-loop plan per contour)."""
    generalist: str = "generalist"
    """The generalist column's policy: ``generalist`` (the one warpcut ships) or a run directory of
    ``warpcut generalist``."""
    record: int | None = None
    """Write ``recording.rrd`` of the first contour's first N envs of each method; None: none."""
    colour_by: str = "strain"
    """What the recorded sheet's vertex colours show: ``strain`` or ``height``."""
    video: int | None = None
    """Write MP4 videos of the first contour's first N envs of each method; None: none."""
    plots: bool = True
    """Write the plots (regions, improvements, learning curves)."""

    def __post_init__(self) -> None:
        _check_fields(self)
        for name in ("trials", "candidates"):
            _counted(f"EvaluateJob.{name}", getattr(self, name))

    def check(self) -> EvaluateJob:
        """Itself, or ``ValueError`` naming what its fields do not say alone (each is checked as it is
        given): the methods, the physics, the optimiser's ranges."""
        check_methods(self.methods, "methods")
        _sim_validated(self.sim)
        self.grad.validated()
        return self

    def unused_keys(self) -> dict[str, str]:
        """The keys this job would not use, ``{key: when it applies}``: the rl column's settings without rl,
        its training settings with checkpoints, the grad column's without grad, the other learners'
        sections, the recording's colours without a recording."""
        unused: dict[str, str] = {}
        if "rl" not in self.methods:
            why = "read by the rl column only (--methods ...,rl)"
            keys = ("train", "env", "checkpoints", "allow_partial", "allow_infeasible_pinch")
            unused |= {key: why for key in keys}
        elif self.checkpoints is not None:
            unused["train"] = "with checkpoints the rl column plays trained runs; nothing is trained"
        else:
            unused |= other_learners(self.train)
            unused["allow_partial"] = "read with checkpoints only"
            unused |= _pinch_keys(True, "checkpoints (their pinch points)")
        if "grad" not in self.methods:
            unused["grad"] = "read by the grad column only (--methods ...,grad)"
        if "generalist" not in self.methods:
            unused["generalist"] = "read by the generalist column only (--methods ...,generalist)"
        return {**unused, **_recording_keys(self)}


def other_learners(train: TrainConfig) -> dict[str, str]:
    """The sections of the learners ``train`` does not train with, ``{key: when it applies}``."""
    from agents.algorithms import ALGORITHMS

    return {f"train.{name}": f"read by --algo {name} only" for name in ALGORITHMS if name != train.algo}


def _pinch_keys(no_pinch: bool, source: str = "a pinch point (--pinch)") -> dict[str, str]:
    """``allow_infeasible_pinch`` where no pinch point is given (``source`` says what gives one): the
    default pinch points are feasible by construction."""
    if no_pinch:
        return {"allow_infeasible_pinch": f"read with {source} only; the default ones are feasible"}
    return {}


def _recording_keys(job: Any) -> dict[str, str]:
    """``colour_by`` without a recording."""
    if getattr(job, "record", None) is None:
        return {"colour_by": "colours a recording, and record is off (add --record [N])"}
    return {}


CONFIG_FILE = "config.json"
"""A run directory's job (this module's dataclasses, as plain data): ``--config`` takes it back, ``--resume``
checks it."""

OUTPUT_KEYS = ("record", "colour_by", "video", "plots", "export_mesh")
"""The keys of a job that say only what a run writes besides its results: a resumed run may change them."""


def with_dependent_defaults(job: Any, explicit: set[str]) -> Any:
    """``job`` with the defaults that follow from its other settings, where not set ``explicit``ly (dotted
    keys given by a file, ``--set`` or a flag):

    - the env's action type is the learner's (``agents.algorithms``): PPO trains discrete moves;
    - the gradient optimiser's steps and step size are its estimator's
      (:data:`agents.plan_optimizer.config.GRAD_CONFIGS`);
    - a policy started from a generalist (``init``) observes and acts as the generalist does;
    - a generalist learned from teachers (dagger) has its own observation and network
      (:data:`agents.config.STUDENT_DEFAULTS`).
    """
    from agents.algorithms import algorithm
    from agents.config_io import apply

    if hasattr(job, "train") and hasattr(job, "env") and "env.action_type" not in explicit:
        actions = algorithm(job.train.algo).action_type
        job = dataclasses.replace(job, env=dataclasses.replace(job.env, action_type=actions))
    if isinstance(job, GeneralistJob) and job.train.algo == "dagger":
        given = {key: value for key, value in STUDENT_DEFAULTS.items() if key not in explicit}
        job = apply(job, given, "a dagger generalist's defaults")
    if getattr(job, "init", None) is not None:  # fine-tuning observes and acts as the generalist does
        from agents.generalist import fine_tuning_defaults

        job = fine_tuning_defaults(job, explicit)
    if hasattr(job, "grad") and job.grad.estimator in GRAD_CONFIGS:
        own = GRAD_CONFIGS[job.grad.estimator]
        given = {key.split(".")[1] for key in explicit if key.startswith("grad.") and key.count(".") >= 1}
        keep = {
            f.name: getattr(job.grad, f.name)
            for f in dataclasses.fields(GradConfig)
            if f.name in given or f.name == "estimator"
        }
        job = dataclasses.replace(job, grad=dataclasses.replace(own, **keep))
    return job


def _sim_validated(sim: SimConfig) -> SimConfig:
    """``sim`` validated, or ``ValueError`` naming the ``sim.`` key (``sim.elasticity: ...``)."""
    try:
        return sim.validated()
    except ConfigError as error:
        raise error.renamed(f"sim.{error.field}") from None


def _grad_validated(grad: GradConfig) -> GradConfig:
    """``grad`` validated (its one spelling of ranges), or ``ValueError`` naming the ``grad.`` key."""
    try:
        return grad.validated()
    except ValueError as error:
        raise ValueError(f"grad.{error}") from None


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


GENERALIST_LEARNERS = ("es", "dagger")
"""The learners a generalist trains with."""


@dataclass
class GeneralistJob:
    """``warpcut generalist``: one tensioning policy for every contour, trained over many contours at once
    (:func:`agents.pipelines.generalist.train_generalist`). A run directory's ``config.json`` is this job."""

    generated: int = GENERALIST_CONTOURS
    """Generated training contours (the ``train`` split of :func:`warpcut.planning.generate_contours`,
    seeded ``seed``)."""
    contours: list[str] = field(default_factory=list)
    """Contours to train on as well: built-in names, files, ``all`` (the suite) or generated names of other
    streams or seeds (``gen-train-1:24``); by default none, so the suite stays out of training and measures
    the generalist zero-shot."""
    validation_contours: int = GENERALIST_VALIDATION_CONTOURS
    """Generated ``validation`` contours that model selection scores the policy on (held out)."""
    candidates: int = EVALUATION_CANDIDATES
    """Pinch candidates the planner searches per contour (as ``warpcut evaluate`` plans)."""
    seed: int = 0
    """Seed of the generated contours and of the training."""
    arm: ArmModel = field(default_factory=ArmModel)
    """The cutting arm's footprint, for pinch feasibility."""
    sim: SimConfig = field(default_factory=SimConfig)
    """The physics and the protocol."""
    env: EnvConfig = field(
        default_factory=lambda: EnvConfig(lookahead=GENERALIST_LOOKAHEAD, reward_reference="no_tension")
    )
    """What the policy observes (the look-ahead) and how it is rewarded (relative to no tension)."""
    train: TrainConfig = field(default_factory=generalist_train_config)
    """The learner: es, its population each cutting every contour; ``num_envs`` follows (population x
    contours)."""
    init: str | None = None
    """A generalist (a run directory, or ``generalist`` for the shipped one) whose policy es starts from
    instead of "hold still": es on the path score, refining a generalist learned from teachers."""

    def __post_init__(self) -> None:
        _check_fields(self)
        check_integer("GeneralistJob.generated", self.generated, 0, MAX_CONTOURS)
        check_integer("GeneralistJob.validation_contours", self.validation_contours, 1, MAX_CONTOURS)
        _counted("GeneralistJob.candidates", self.candidates)

    def check(self) -> GeneralistJob:
        """Itself, or ``ValueError`` naming what cannot train."""
        if self.train.algo not in GENERALIST_LEARNERS:
            raise ValueError(
                f"train.algo: a generalist trains with {' or '.join(GENERALIST_LEARNERS)} (each of es's "
                f"perturbed policies cuts every contour; dagger learns from teachers), not {self.train.algo}"
            )
        if self.train.algo == "dagger":
            self.train.dagger.dataset()
        elif self.generated == 0 and not self.contours:
            raise ValueError("generated: give training contours (generated > 0, or contours)")
        if not self.env.lookahead:
            raise ValueError(
                "env.lookahead: a generalist must see what lies ahead of the scissors; give 1 or more "
                f"(default {GENERALIST_LOOKAHEAD})"
            )
        return self

    def training_config(self, count: int) -> TrainConfig:
        """The learner's settings for ``count`` training contours: ``num_envs`` = es's population x contours,
        or dagger's one env a contour."""
        num_envs = self.train.es.population * count if self.train.algo == "es" else count
        if self.train.num_envs is not None and self.train.num_envs != num_envs:
            why = (
                f"every contour with each of es's {self.train.es.population} policies"
                if self.train.algo == "es"
                else "each teacher's contour once an iteration"
            )
            raise ValueError(
                f"train.num_envs: a generalist cuts {why}: {num_envs} envs for {count} contours; leave it "
                "unset"
            )
        return dataclasses.replace(self.train, num_envs=num_envs).check(False)

    def unused_keys(self) -> dict[str, str]:
        """Keys this job would not use: the other learners' sections, and with dagger the generated and
        built-in training contours (it trains on its teachers' contours)."""
        unused = other_learners(self.train)
        if self.train.algo == "dagger":
            why = "read by es generalists only (dagger trains on its teachers' contours)"
            unused |= {"generated": why, "contours": why}
        return unused


@dataclass
class TeachersJob:
    """``warpcut teachers``: a teacher for each of many generated contours, kept as a dataset that a
    generalist learns from (:func:`agents.pipelines.teachers.make_teachers`). A dataset's ``config.json`` is
    this job."""

    count: int = TEACHER_CONTOURS
    """Generated contours (the ``train`` split of :func:`warpcut.planning.generate_contours`, seeded
    ``seed``), each planned and given a teacher."""
    kinds: list[str] = field(default_factory=lambda: list(KINDS + EXTRA_KINDS))
    """The kinds drawn in turn (:data:`warpcut.planning.generate.KINDS` and ``EXTRA_KINDS``)."""
    candidates: int = EVALUATION_CANDIDATES
    """Pinch candidates the planner searches per contour (as ``warpcut evaluate`` plans)."""
    seed: int = 0
    """Seed of the generated contours and of the teachers' optimiser."""
    arm: ArmModel = field(default_factory=ArmModel)
    """The cutting arm's footprint, for pinch feasibility."""
    sim: SimConfig = field(default_factory=SimConfig)
    """The physics and the protocol the teachers are optimised under."""
    grad: GradConfig = field(default_factory=lambda: GRAD_CONFIGS["es"])
    """The teacher: the plan optimiser's settings (``warpcut optimize``'s, the es estimator)."""

    def __post_init__(self) -> None:
        _check_fields(self)
        check_integer("TeachersJob.count", self.count, 1, MAX_CONTOURS)
        _counted("TeachersJob.candidates", self.candidates)
        if (
            not isinstance(self.kinds, list | tuple)
            or not self.kinds
            or any(k not in KINDS + EXTRA_KINDS for k in self.kinds)
        ):
            fail("TeachersJob.kinds", f"a non-empty list of {', '.join(KINDS + EXTRA_KINDS)}", self.kinds)

    def check(self) -> TeachersJob:
        """Itself (every field is checked as it is set)."""
        return self

    def unused_keys(self) -> dict[str, str]:
        """Keys this job would not use: none."""
        return {}
