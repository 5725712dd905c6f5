"""The jobs over many contours: ``warpcut generalist`` (:class:`GeneralistJob`) and ``teachers``
(:class:`TeachersJob`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from agents.config import (
    EVALUATION_CANDIDATES,
    GENERALIST_CONTOURS,
    GENERALIST_LOOKAHEAD,
    GENERALIST_VALIDATION_CONTOURS,
    TEACHER_CONTOURS,
    TrainConfig,
    generalist_train_config,
)
from agents.jobs.fields import (
    _check_fields,
    _counted,
    other_learners,
)
from agents.plan_optimizer.config import GRAD_CONFIGS, GradConfig
from envs.options import EnvConfig
from warpcut.planning.feasibility import ArmModel
from warpcut.planning.generate import EXTRA_KINDS, KINDS, MAX_CONTOURS
from warpcut.sim.config import SimConfig
from warpcut.validation import (
    check_integer,
    check_number,
    check_text,
    fail,
)

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
    near: str | None = None
    """A generalist (a directory of ``warpcut generalist``, or ``generalist``) that every teacher starts
    from: its deterministic moves on the contour's cut (the nominal sheet, the optimiser's noise) are the
    optimiser's first plan, and ``tether`` keeps the teacher near them (guided policy search: teachers found
    near the student agree with one another where the student's behaviour does). None: teachers start from a
    still grasp."""
    tether: float = 0.0
    """With ``near``: the weight (vertices per mm²) of the cost of the teacher's grasp path leaving the
    student's, the mean over the cut's steps of their squared distance; 0: the student's moves are only the
    start (:func:`agents.plan_optimizer.optimizer.optimize_plan`)."""

    def __post_init__(self) -> None:
        _check_fields(self)
        check_text("TeachersJob.near", self.near, optional=True, note="teachers start from a still grasp")
        check_number("TeachersJob.tether", self.tether, 0, unit="vertices per mm^2")
        check_integer("TeachersJob.count", self.count, 1, MAX_CONTOURS)
        _counted("TeachersJob.candidates", self.candidates)
        if (
            not isinstance(self.kinds, list | tuple)
            or not self.kinds
            or any(k not in KINDS + EXTRA_KINDS for k in self.kinds)
        ):
            fail("TeachersJob.kinds", f"a non-empty list of {', '.join(KINDS + EXTRA_KINDS)}", self.kinds)

    def check(self) -> TeachersJob:
        """Itself, or ``ConfigError`` for fields that do not fit together (each is checked as it is set)."""
        if self.tether and self.near is None:
            fail("TeachersJob.tether", "tethers teachers to a student: give near=DIR too, or 0", self.tether)
        return self

    def unused_keys(self) -> dict[str, str]:
        """Keys this job would not use: none."""
        return {}
