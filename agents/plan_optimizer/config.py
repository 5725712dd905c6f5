"""The plan optimiser's settings (torch-free, so the command line reads them without loading torch):
:class:`GradConfig`, the ``grad`` section of a job, and each estimator's defaults (:data:`GRAD_CONFIGS`)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from warpcut.sim.config import RANDOMIZE_ALIASES, randomize_ranges
from warpcut.validation import check_flag, check_integer, fail, is_number

GRAD_ESTIMATORS = ("es", "tape")
"""How the plan optimiser may estimate its gradient (``GradConfig.estimator``): "es" (the default) or
"tape"."""


@dataclass(frozen=True)
class GradConfig:
    """The plan optimiser (:mod:`agents.plan_optimizer`): Adam on an open-loop plan of grasp moves (and
    optionally the pinch point) through the differentiable simulator (:mod:`warpcut.gradients`)."""

    estimator: str = "es"
    """How each step's gradient is estimated. "es" (the default: +70.2% on the suite against the tape's
    +45.9%, docs/results.md): evolution strategies, the gradient of the path score itself smoothed by
    Gaussian perturbations of the plan (``es_population`` perturbed plans, antithetic pairs, ``es_trials``
    episodes each, ranked; forward passes only, one batch a step). "tape": the path surrogate's gradient
    through ``wp.Tape`` (:mod:`warpcut.gradients`), over ``trials`` episodes."""
    iterations: int = 40
    """Adam steps (es: one batch of ``es_population x es_trials`` episodes; tape: each one forward and one
    backward pass of ``trials`` episodes). Each estimator has its own default (:data:`GRAD_CONFIGS`)."""
    trials: int = 8
    """Noisy episodes per step of the tape estimator, the same seeds every step (the expected surrogate over
    them is minimised); their noise is not the evaluation's (seed ``seed + GRAD_SEED_OFFSET``)."""
    es_population: int = 64
    """Perturbed plans per step of the es estimator (an even number: antithetic pairs)."""
    es_trials: int = 2
    """Noisy episodes per perturbed plan (es), the same seeds every step, not the evaluation's."""
    es_sigma_mm: float = 0.3
    """Standard deviation of the es estimator's perturbation of each move (mm) and of each feedback gain
    (mm of move per mm of tracking error)."""
    es_feedback_phases: int = 0
    """es: 0 optimises an open-loop plan. P > 0 adds feedback, a closed-loop policy: every step's move is the
    plan's plus ``K @ e``, ``e`` the x-y tracking error (mm; the vector from the scissor tip to the contour
    point it is about to cut, as it lies on the moved sheet, what the analytic controller opposes) and ``K``
    a 3 x 2 gain matrix, one per phase (the episode split into P equal parts), optimised with the plan from
    zero (docs/robustness.md, "es policies")."""
    es_feedback_only: bool = False
    """es with feedback: True keeps the plan at zero and optimises only the gains, a policy that holds still
    where the sheet does not move from where the scissors expect it (docs/robustness.md, "es policies")."""
    es_feedback_sag: bool = False
    """es with feedback: the gains are scheduled on the sheet's sag. Each phase's matrix is 3 x 4, acting on
    ``[e, s e]``, ``s`` how far the sheet hangs before the cut (:func:`agents.plan_optimizer.plan.sheet_sag`:
    0 on a sheet without gravity, ~1.2 on the default one). On a flat sheet only the first half acts, so es
    over randomised sheets can learn a policy that holds still there (docs/robustness.md, "Gains scheduled on
    the sag")."""
    es_randomize: str = ""
    """es: physical parameters drawn anew at every step for the ``es_trials`` episodes (comma-separated names
    of :data:`warpcut.sim.config.RANDOMIZE_RANGES`, over their ranges; every perturbed plan cuts the same
    draws). Each episode's error is then weighed by the nominal sheet's no-tension error over its own
    (:class:`warpcut.task.NoTensionReference`, as ``relative_reward`` does), and the validation episodes
    draw theirs too (seeded, the same every iterate). Empty: the nominal sheet."""
    es_randomize_ranges: dict[str, list[float]] | None = None
    """es: the range of a randomised parameter, ``{name: [low, high]}`` in its units, where it differs from
    :data:`warpcut.sim.config.RANDOMIZE_RANGES` (``warpcut optimize --randomize-range``); None: the
    defaults."""
    learning_rate: float = 0.1
    """Adam's step (mm per grasp move); moves are projected back onto ``max_step_mm`` per axis. Each estimator
    has its own default (:data:`GRAD_CONFIGS`)."""
    validation_trials: int = 8
    """Held-out noisy episodes every iterate is scored on (path score); the best is kept. 0: keep the
    iterate with the lowest error on the optimiser's own episodes."""
    window: int | None = 10
    """Truncate the gradient to windows of this many env steps (a move answers only for the surrogate's
    terms up to its window's end: lower variance on a chaotic sheet, some bias); None: the whole episode.
    10 steps and a step of 0.3 mm did best of the settings tried on 12 contours (docs/results.md)."""
    optimize_pinch: bool = False
    """Also move the pinch point along its gradient (the grasped set held fixed per step), staying
    feasible."""
    pinch_learning_rate: float = 1.0
    """Adam's step for the pinch point (mm)."""

    def __post_init__(self) -> None:
        self._check_fields()

    def _check_fields(self) -> None:
        """What each field is, on its own, as it is given (a file and ``--set`` set one key at a time): a
        :class:`~warpcut.validation.ConfigError` naming ``GradConfig.field``. The step counts' ranges and what
        depends on several fields are :meth:`validated`'s."""
        where = "GradConfig."
        if self.estimator not in GRAD_ESTIMATORS:
            fail(where + "estimator", f"must be one of {', '.join(GRAD_ESTIMATORS)}", self.estimator)
        for name in ("iterations", "trials", "es_population", "es_trials", "es_feedback_phases"):
            check_integer(where + name, getattr(self, name))
        check_integer(where + "validation_trials", self.validation_trials, 0, note="0: none")
        check_integer(where + "window", self.window, 1, optional=True, note="the whole episode")
        for name in ("es_feedback_only", "es_feedback_sag", "optimize_pinch"):
            check_flag(where + name, getattr(self, name))
        for name in ("learning_rate", "pinch_learning_rate", "es_sigma_mm"):
            value = getattr(self, name)
            if not (is_number(value) and 0 < value < math.inf):
                fail(where + name, "must be a positive number of mm", value)
        if not isinstance(self.es_randomize, str):
            fail(
                where + "es_randomize",
                "comma-separated names of randomised parameters, or ''",
                self.es_randomize,
            )
        ranges = self.es_randomize_ranges
        if ranges is not None and not isinstance(ranges, dict):
            fail(where + "es_randomize_ranges", "a mapping {name: [low, high]}, or None", ranges)

    def validated(self) -> GradConfig:
        """Itself, every field checked again (:meth:`_check_fields`), or ``ValueError`` naming the field and
        the fix."""
        self._check_fields()
        for name in ("iterations", "trials", "es_population", "es_trials"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"{name}: must be a positive integer (got {value!r})")
        if self.es_population % 2:
            raise ValueError(f"es_population: must be even, antithetic pairs (got {self.es_population})")
        if self.estimator == "es" and self.optimize_pinch:
            raise ValueError("optimize_pinch: the pinch point moves only with estimator 'tape'; drop one")
        phases = self.es_feedback_phases
        if not isinstance(phases, int) or isinstance(phases, bool) or phases < 0:
            raise ValueError(f"es_feedback_phases: must be an integer >= 0, 0 for open loop (got {phases!r})")
        try:
            chosen = randomize_ranges(self.es_randomize, self.es_randomize_ranges)
        except ValueError as error:
            field = "es_randomize_ranges" if str(error).startswith("randomize_ranges") else "es_randomize"
            raise ValueError(f"{field}: {str(error).split(': ', 1)[1]}") from None
        for name in ("es_feedback_only", "es_feedback_sag"):
            if getattr(self, name) and not self.es_feedback_phases:
                raise ValueError(f"{name}: there are no gains to optimise; give es_feedback_phases >= 1")
        closed_loop = {
            "es_feedback_phases": self.es_feedback_phases,
            "es_feedback_only": self.es_feedback_only,
            "es_feedback_sag": self.es_feedback_sag,
            "es_randomize": self.es_randomize,
        }
        for name, value in closed_loop.items():
            if value and self.estimator != "es":
                raise ValueError(f"{name}: only estimator 'es' has it; use estimator 'es', or drop {name}")
        if self.estimator == "es" and self.validation_trials == 0:
            raise ValueError(
                "validation_trials: estimator 'es' scores each iterate on held-out episodes only; give at "
                f"least 1 (got {self.validation_trials!r})"
            )
        if self.es_randomize_ranges:  # one spelling, lists of floats, so a saved run's settings compare equal
            names = [RANDOMIZE_ALIASES.get(k, k) for k in self.es_randomize_ranges]
            canonical = {k: list(chosen[k]) for k in names}
            if canonical != self.es_randomize_ranges:
                return dataclasses.replace(self, es_randomize_ranges=canonical)
        return self


GRAD_CONFIGS = {
    "es": GradConfig(),
    "tape": GradConfig(estimator="tape", iterations=20, learning_rate=0.3),
}
"""The optimiser's defaults per estimator (library and command line). es: 40 steps of 0.1 mm, on fls-circle
and kidney +74.6% and +55.3% against +75.3% and +48.9% with 20 steps of 0.3 mm (docs/results.md); tape: 20
steps of 0.3 mm, windows of 10 steps."""

assert tuple(GRAD_CONFIGS) == GRAD_ESTIMATORS


def grad_config(estimator: str = "es", **overrides) -> GradConfig:
    """``estimator``'s defaults (:data:`GRAD_CONFIGS`) with the ``overrides`` that are not None (the CLI's
    options left unset are None), validated."""
    base = GRAD_CONFIGS.get(estimator, GradConfig(estimator=estimator))  # unknown: validated() names it
    given = {k: v for k, v in overrides.items() if v is not None}
    return dataclasses.replace(base, **given).validated()


GRAD_CONFIG = GRAD_CONFIGS["es"]
"""The optimiser's defaults (library and command line): the es estimator's, the better measured on the
suite (docs/results.md, "Why the plan optimiser's default is es")."""

GRAD_SEED_OFFSET = 4241
"""The gradient optimiser's episodes use seed ``seed + GRAD_SEED_OFFSET``: never the evaluation's noise."""
