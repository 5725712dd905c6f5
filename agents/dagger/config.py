"""dagger's settings (torch-free, so the command line reads them without loading torch)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from agents.algorithms import DETERMINISTIC_GAUSSIAN
from warpcut.validation import ConfigError, check_flag, check_integer, check_text, shown


@dataclass
class DaggerConfig:
    """DAgger from a teacher dataset (:mod:`agents.dagger`).

    Each iteration cuts every env's contour once; an env follows its teacher with probability
    ``beta ** iteration`` (the first iteration: every env, the teachers' own states), else the student. The
    label of a state is the teacher's move at that point of the cut, corrected toward where the teacher's
    grasp is there (:meth:`agents.dagger.algorithm.DAgger.teacher_moves`). The student then takes ``updates``
    steps of Adam on minibatches of the aggregated labelled states (at most ``buffer`` of them, the oldest
    dropped first).
    """

    teachers: str | None = None
    """The teacher dataset (a directory of ``warpcut teachers``); every env's contour needs a teacher there,
    at the env's pinch point."""
    beta: float = 0.5
    """The share of envs that follow their teacher decays as ``beta ** iteration``: 1 in the first iteration
    (behaviour cloning), then the student's own states (0: the student's alone after the first)."""
    learning_rate: float = 0.001
    """Adam's step for the student's weights."""
    updates: int = 500
    """Adam steps an iteration, each on ``minibatch`` labelled states drawn from the aggregated dataset."""
    minibatch: int = 1024
    """Labelled states per Adam step."""
    buffer: int = 200_000
    """The most labelled states kept (the oldest dropped first); a checkpoint carries them, so a run resumes
    exactly (4 bytes x ~100 numbers each)."""
    stride: int = 2
    """Keep every ``stride``-th step of a cut (neighbouring steps are nearly the same state)."""
    horizon: int = 8
    """Steps ahead the label aims at: the move that takes the grasp to the teacher's ``horizon`` steps on, a
    ``horizon``-th of the way a step (1: the teacher's next move; more: its moves averaged). An es plan's
    moves jitter from step to step (0.45 mm a step on average, about as much as they move the grasp), which
    nothing the student observes predicts; 8 steps (8 mm of cut) measured best of 1, 8 and 16
    (docs/results.md)."""
    feedback: bool = True
    """Give the student the linear feedback path on the tracking error (:class:`agents.models.FeedbackMLP`),
    as es's generalist has: fine-tuning from it with es takes the same network."""
    scheduled: bool = True
    """Schedule the feedback gains on the observation (:class:`agents.models.FeedbackMLP`)."""

    def __post_init__(self) -> None:
        self.check()

    def check(self, num_envs: int | None = None, where: str = "train.dagger") -> None:
        """``ValueError`` naming the first field out of range."""
        check_text(
            f"{where}.teachers", self.teachers, optional=True, note="given by warpcut generalist --teachers"
        )
        for name, low, high in (("beta", 0.0, 1.0), ("learning_rate", 0.0, math.inf)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not (low <= value <= high):
                raise ConfigError(
                    f"{where}.{name}", f"must be a number in [{low:g}, {high:g}] (got {shown(value)})"
                )
        if self.learning_rate <= 0 or not math.isfinite(self.learning_rate):
            raise ConfigError(
                f"{where}.learning_rate", f"must be a finite number > 0 (got {shown(self.learning_rate)})"
            )
        check_integer(f"{where}.updates", self.updates, 1, 100_000)
        check_integer(f"{where}.minibatch", self.minibatch, 1, 1_000_000)
        check_integer(f"{where}.buffer", self.buffer, 1, 10_000_000)
        check_integer(f"{where}.stride", self.stride, 1, 1000)
        check_integer(f"{where}.horizon", self.horizon, 1, 1000)
        check_flag(f"{where}.feedback", self.feedback)
        check_flag(f"{where}.scheduled", self.scheduled)
        if self.scheduled and not self.feedback:
            raise ConfigError(
                f"{where}.scheduled", f"schedules the feedback gains: needs {where}.feedback=true"
            )

    def dataset(self) -> str:
        """:attr:`teachers`, or ``ValueError`` saying how to give one."""
        if self.teachers is None:
            raise ValueError(
                "train.dagger.teachers: dagger learns from a teacher dataset; make one (warpcut teachers) "
                "and give it (warpcut generalist --teachers DIR)"
            )
        return self.teachers

    def rsl_rl(
        self, discrete: bool, num_action_choices: int | None, episode_steps: int | None = None
    ) -> dict:
        """dagger's part of rsl-rl's runner config (:mod:`agents.algorithms`): one whole cut per env an
        iteration, the actor's deterministic output."""
        if episode_steps is None:
            raise ValueError("dagger plays whole cuts: give the env's episode_steps")
        self.dataset()
        algorithm = {"class_name": "agents.dagger.algorithm:DAgger"}
        algorithm |= {name: getattr(self, name) for name in ("teachers", "beta", "learning_rate", "updates")}
        algorithm |= {name: getattr(self, name) for name in ("minibatch", "buffer", "stride", "horizon")}
        return {
            "algorithm": algorithm,
            "distribution": dict(DETERMINISTIC_GAUSSIAN),
            "num_steps_per_env": episode_steps,
            "actor": {"scheduled": True} if self.feedback and self.scheduled else {},
        }
