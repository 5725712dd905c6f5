"""The job over a suite of contours: ``warpcut evaluate`` (:class:`EvaluateJob`, the paper's Table I
protocol)."""

from __future__ import annotations

from dataclasses import dataclass, field

from agents.config import (
    ANALYTIC_PINCHES,
    EVALUATION_CANDIDATES,
    EVALUATION_TRIALS,
    GENERALIST_CANDIDATES,
    GENERALIST_FINALISTS,
    GENERALIST_GAINS,
    TrainConfig,
    check_gains,
)
from agents.jobs.fields import (
    _check_fields,
    _counted,
    _pinch_keys,
    _recording_keys,
    _sim_validated,
    other_learners,
)
from agents.methods import TABLE_METHODS, check_methods
from agents.plan_optimizer.config import GRAD_CONFIG, GradConfig
from envs.options import EnvConfig
from warpcut.planning.feasibility import ArmModel
from warpcut.sim.config import SimConfig


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
    generalist_candidates: int | None = GENERALIST_CANDIDATES
    """Pinch candidates the generalist column chooses among on validation episodes: the plan's best by
    fixed tension, each in its best order (None: all the plan's); 1: the planned pinch point only (as fixed
    and rl pinch)."""
    generalist_gains: tuple[float, ...] = GENERALIST_GAINS
    """Factors on the generalist's moves it chooses among with its candidate, on the same validation
    episodes (1: its moves as they are; [1]: no choice)."""
    generalist_members: int | None = None
    """Of the generalist's policies (its own, then its members: :attr:`agents.generalist.Generalist.actors`),
    the first N it chooses among with its candidate and gain (None: all; 1: its own policy alone)."""
    generalist_finalists: int = GENERALIST_FINALISTS
    """The generalist's best options per contour (member, candidate, gain) that play again on fresh
    validation episodes, the lowest mean over both winning (1: the best on the first episodes alone)."""
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
        _counted("EvaluateJob.generalist_candidates", self.generalist_candidates, True, "all the plan's")
        _counted("EvaluateJob.generalist_members", self.generalist_members, True, "all its members")
        _counted("EvaluateJob.generalist_finalists", self.generalist_finalists)
        self.generalist_gains = check_gains(self.generalist_gains, "EvaluateJob.generalist_gains")

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
            why = "read by the generalist column only (--methods ...,generalist)"
            keys = ("generalist", "generalist_candidates", "generalist_gains", "generalist_members",
                    "generalist_finalists")  # fmt: skip
            unused |= {key: why for key in keys}
        return {**unused, **_recording_keys(self)}
