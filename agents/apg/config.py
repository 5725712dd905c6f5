"""Analytic policy gradients' settings (torch-free, so the command line reads them without loading torch)."""

from __future__ import annotations

import math
from dataclasses import dataclass

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

    def check(self) -> None:
        """``ValueError`` naming the first field out of range."""
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
