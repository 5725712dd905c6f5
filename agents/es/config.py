"""Evolution strategies' settings (torch-free, so the command line reads them without loading torch)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from agents.algorithms import DETERMINISTIC_GAUSSIAN
from warpcut.validation import ConfigError, check_flag, shown


@dataclass
class EsConfig:
    """Evolution strategies on the policy's weights (:mod:`agents.es.algorithm`): every iteration plays
    ``population`` perturbed copies of the policy, in antithetic pairs, each on ``num_envs / population``
    whole cuts in one batch, ranks them by the path score and takes a step of Adam along the ranked
    perturbations.

    The policy is the MLP plus a linear feedback path on the tracking error (``feedback``). The two parts
    get their own perturbation scales and steps: a perturbed MLP moves the grasp by a near-constant bias that
    adds up over a long cut, so its σ and step are small; the gains act on the normalised tracking error,
    where useful values are ~0.5-1, so theirs are large.
    """

    population: int = 64
    """Perturbed policies per iteration, in antithetic pairs: even, and dividing ``num_envs`` (256 envs: 4
    episodes each)."""
    sigma: float = 0.005
    """Standard deviation of the perturbations of the MLP's weights (its output is in units of
    ``max_step_mm``). With 0.05 the perturbed population cut long contours far worse than its centre and es
    learned nothing there."""
    feedback_sigma: float = 0.1
    """Standard deviation of the perturbations of the feedback gains (on the normalised tracking error)."""
    learning_rate: float = 0.001
    """Adam's step for the MLP's weights, in weight space: small, so the MLP stays near "hold still" while
    the gains learn."""
    feedback_learning_rate: float = 0.1
    """Adam's step for the feedback gains."""
    feedback: bool = True
    """Give the actor the linear feedback path on the tracking error (:class:`agents.models.FeedbackMLP`;
    it needs the contour features in the observation). Without it es learns the MLP alone: give it a larger
    ``sigma`` and ``learning_rate`` then (0.05 and 0.01 worked)."""

    scheduled: bool = False
    """Schedule the feedback gains on the observation (:class:`agents.models.FeedbackMLP`): the MLP also
    outputs a gain matrix added to the static one. What a policy for many contours needs (``warpcut
    generalist``); a policy for one contour does without."""

    def __post_init__(self) -> None:  # each field as it is given (a file's or --set's key at a time)
        self.check()

    def check(self, num_envs: int | None = None, where: str = "train.es") -> None:
        """``ValueError`` naming the first field out of range (``num_envs``: the batch the population must
        divide; ``where``: the section's key, e.g. ``train.gps.refine`` where another learner holds it)."""
        population = self.population
        if (
            isinstance(population, bool)
            or not isinstance(population, int)
            or population < 2
            or population % 2
        ):
            raise ConfigError(
                f"{where}.population",
                f"must be an even integer >= 2, antithetic pairs (got {shown(population)})",
            )
        if num_envs is not None and num_envs % population:
            fits = max((p for p in range(2, min(num_envs, 64) + 1, 2) if num_envs % p == 0), default=None)
            fix = f"e.g. {where}.population={fits}" if fits else "give an even num_envs"
            raise ValueError(
                f"{where}.population: {population} must divide num_envs ({num_envs}), each perturbed "
                "policy playing "
                f"as many episodes; {fix}"
            )
        for name in ("sigma", "feedback_sigma", "learning_rate", "feedback_learning_rate"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not (0 < value < math.inf):
                raise ConfigError(f"{where}.{name}", f"must be a finite number > 0 (got {shown(value)})")
        check_flag(f"{where}.feedback", self.feedback)
        check_flag(f"{where}.scheduled", self.scheduled)
        if self.scheduled and not self.feedback:
            raise ConfigError(
                f"{where}.scheduled", f"schedules the feedback gains: needs {where}.feedback=true"
            )

    def algorithm_section(self, class_name: str = "agents.es.algorithm:ES") -> dict:
        """rsl-rl's ``algorithm`` section: ``class_name`` and the arguments of
        :class:`agents.es.algorithm.ES`."""
        return {
            "class_name": class_name,
            "population": self.population,
            "sigma": self.sigma,
            "feedback_sigma": self.feedback_sigma,
            "learning_rate": self.learning_rate,
            "feedback_learning_rate": self.feedback_learning_rate,
        }

    def rsl_rl(
        self, discrete: bool, num_action_choices: int | None, episode_steps: int | None = None
    ) -> dict:
        """es's part of rsl-rl's runner config (:mod:`agents.algorithms`): one whole cut of
        ``episode_steps`` per env an iteration, the actor's deterministic output."""
        if episode_steps is None:
            raise ValueError("es plays whole cuts: give the env's episode_steps")
        return {
            "algorithm": self.algorithm_section(),
            "distribution": dict(DETERMINISTIC_GAUSSIAN),
            "num_steps_per_env": episode_steps,
            "actor": {"scheduled": True} if self.feedback and self.scheduled else {},
        }
