"""Analytic policy gradients' settings (torch-free, so the command line reads them without loading torch)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from agents.algorithms import DETERMINISTIC_GAUSSIAN
from warpcut.validation import ConfigError, check_flag, shown


@dataclass
class ApgConfig:
    """Analytic policy gradients (:mod:`agents.apg.runner`): one episode per env an iteration, replayed
    backward through the differentiable simulator for the path surrogate's gradient with respect to every
    move, chained through the policy into its weights (Adam, gradient-norm clipping). APG's default batch is
    16 envs x 30 iterations: an APG iteration at 256 envs takes ~35 s on 2 CPU cores."""

    learning_rate: float = 3e-3
    """Adam's step size (the gradients are clipped to ``max_grad_norm``)."""
    max_grad_norm: float = 1.0
    """Gradient norm clip."""
    window: int | None = 5
    """Truncate the gradient to windows of this many env steps (lower variance on a chaotic sheet, some
    bias); None: through the whole episode."""
    accept: bool = False
    """Keep a step only if it lowers the iteration's mean path error on the same episodes (cut again with the
    new weights); otherwise revert it and halve the step size (a kept step grows it by 1.5, up to
    ``learning_rate``)."""

    def __post_init__(self) -> None:  # each field as it is given (a file's or --set's key at a time)
        self.check()

    def check(self, num_envs: int | None = None) -> None:
        """``ValueError`` naming the first field out of range (``num_envs``: unused)."""
        for name in ("learning_rate", "max_grad_norm"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not (0 < value < math.inf):
                raise ConfigError(f"train.apg.{name}", f"must be a finite number > 0 (got {shown(value)})")
        window = self.window
        if window is not None and (isinstance(window, bool) or not isinstance(window, int) or window < 1):
            raise ConfigError(
                "train.apg.window",
                f"must be an integer >= 1 or null, the whole episode (got {shown(window)})",
            )
        check_flag("train.apg.accept", self.accept)

    feedback = False
    """APG's actor has no feedback path."""

    def rsl_rl(
        self, discrete: bool, num_action_choices: int | None, episode_steps: int | None = None
    ) -> dict:
        """APG's part of rsl-rl's runner config (:mod:`agents.algorithms`): its runner steps whole episodes
        itself; rsl-rl's PPO only holds its actor, which plays its deterministic output."""
        return {
            "algorithm": {"class_name": "agents.ppo.algorithm:PPO"},
            "distribution": dict(DETERMINISTIC_GAUSSIAN),
            "num_steps_per_env": 1,
            "own": {"apg": dataclasses.asdict(self)},
        }
