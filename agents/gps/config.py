"""gps's settings (torch-free, so the command line reads them without loading torch)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from agents.es.config import EsConfig
from warpcut.sim.config import randomize_ranges
from warpcut.validation import check_instance, check_integer


@dataclass
class GpsConfig:
    """Guided policy search from the contour's optimised plan (:mod:`agents.gps`): the teacher is the plan
    that ``warpcut optimize --estimator es`` finds at the run's pinch point and segments; the student plays it
    as its feed-forward and learns a closed-loop correction by es on whole cuts.

    ``num_envs`` and ``iterations`` are :class:`~agents.config.TrainConfig`'s (where none are given: es's
    batch and half its env steps, :func:`agents.algorithms.default_iterations`).
    """

    teacher_iterations: int | None = None
    """Steps of the teacher's plan optimiser; None: the optimiser's own default for the es estimator
    (``warpcut optimize --estimator es``, :data:`agents.plan_optimizer.config.GRAD_CONFIGS`)."""
    refine: EsConfig = field(default_factory=EsConfig)
    """es's settings for the correction on top of the plan (:class:`~agents.es.config.EsConfig`; its
    ``feedback`` and ``scheduled`` shape the correction's network)."""

    randomize: tuple[str, ...] = ("gravity", "noise_std")
    """Sheet parameters the correction trains on drawn anew at every reset (``env.randomize``'s names, over
    their default ranges, :data:`warpcut.sim.config.RANDOMIZE_RANGES`: gravity 0 to twice the default,
    process noise 0 to five times), where the job's env randomises none: the plan is optimised for the
    nominal sheet, the correction for how a sheet differs from it. Model selection then scores each policy
    on the nominal sheet's held-out episodes and as many randomised ones (:meth:`sheets`). Empty: the
    nominal sheet alone (docs/results.md measures both)."""

    def __post_init__(self) -> None:  # each field as it is given (a file's or --set's key at a time)
        if isinstance(self.randomize, list):
            self.randomize = tuple(self.randomize)
        self.check()

    def check(self, num_envs: int | None = None) -> None:
        """``ValueError`` naming the first field out of range (``num_envs``: the batch es's population must
        divide)."""
        check_integer("train.gps.teacher_iterations", self.teacher_iterations, 1, optional=True,
                      note="the optimiser's")  # fmt: skip
        try:
            randomize_ranges(self.randomize)
        except ValueError as error:
            raise ValueError(f"train.gps.{error}") from None
        check_instance("train.gps.refine", self.refine, EsConfig, "an EsConfig")
        self.refine.check(num_envs, "train.gps.refine")
        if not self.refine.feedback:
            raise ValueError(
                "train.gps.refine.feedback: the student's correction acts on the tracking error; leave it "
                "true"
            )

    def sheets(self, options):
        """``(training, validation)``: the options of the env the correction trains on, and of each set of
        held-out episodes model selection scores (their errors concatenated). With :attr:`randomize` and a
        job whose env randomises nothing: the randomised sheet, and the nominal and randomised ones; else
        ``options`` for both."""
        if not self.randomize or options.randomize:
            return options, [options]
        randomised = dataclasses.replace(options, randomize=tuple(self.randomize))
        return randomised, [options, randomised]

    @property
    def feedback(self) -> bool:
        """Whether the correction has the linear feedback path on the tracking error."""
        return self.refine.feedback

    def rsl_rl(
        self, discrete: bool, num_action_choices: int | None, episode_steps: int | None = None
    ) -> dict:
        """gps's part of rsl-rl's runner config (:mod:`agents.algorithms`): es's (:attr:`refine`), with
        :class:`agents.gps.algorithm.GPS` and an actor that holds a plan of ``episode_steps`` moves, and the
        ``gps`` section the runner reads (:class:`agents.gps.runner.GpsRunner`)."""
        part = self.refine.rsl_rl(discrete, num_action_choices, episode_steps)
        part["algorithm"] = self.refine.algorithm_section("agents.gps.algorithm:GPS")
        part["actor"] = {
            **part["actor"],
            "class_name": "agents.gps.model:PlanFeedbackModel",
            "plan_steps": episode_steps,
        }
        part["own"] = {"gps": {"teacher_iterations": self.teacher_iterations}}
        return part
