"""How each step of the plan optimiser estimates its gradient (``GradConfig.estimator``): ``tape``, the path
surrogate's gradient through ``wp.Tape`` (:class:`TapeGradient`), or ``es``, the path score's gradient
smoothed by Gaussian perturbations of the plan (:class:`SmoothedGradient`); and the held-out episodes every
iterate is scored on (:class:`HeldOut`, weighed by :class:`RelativeWeights` on randomised sheets)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from agents.plan_optimizer.config import GradConfig
from agents.plan_optimizer.plan import PlanPolicy
from warpcut.sim.config import SimConfig, randomize_ranges, sample_parameters
from warpcut.task import CuttingTask, NoTensionReference


def path_distance(plans: np.ndarray, anchor: np.ndarray, max_step: float) -> np.ndarray:
    """The mean over steps of the squared distance (mm²) between the grasp path of each of ``plans`` (``(P, T,
    3)``, or one ``(T, 3)``) and that of ``anchor`` (``(T, 3)``): each path is its moves added up, each move
    clipped to ``max_step`` per axis as the simulator clips it (the displacement cap left out)."""
    paths = np.cumsum(np.clip(plans, -max_step, max_step), axis=-2, dtype=np.float64)
    reference = np.cumsum(np.clip(anchor, -max_step, max_step), axis=0, dtype=np.float64)
    return ((paths - reference) ** 2).sum(axis=-1).mean(axis=-1)


class Tether(NamedTuple):
    """A cost on a plan's leaving an anchor's moves (guided policy search's trust region around a student,
    :func:`agents.plan_optimizer.optimizer.optimize_plan`'s ``anchor``): ``weight`` (vertices per mm²) times
    :func:`path_distance` from ``anchor`` (``(T, 3)`` mm)."""

    anchor: np.ndarray
    weight: float

    def cost(self, plans: np.ndarray, max_step: float) -> np.ndarray:
        """The tether's cost (vertices) of each of ``plans``."""
        return self.weight * path_distance(plans, self.anchor, max_step)


class TapeGradient:
    """The tape estimator (``GradConfig.estimator == "tape"``): the path surrogate's gradient through
    ``wp.Tape`` (:class:`warpcut.gradients.DifferentiableRollout`), averaged over the episodes of ``task``
    (``GradConfig.trials``; the noise of ``seed``, the same every step); ``pinch_grad`` holds the last
    step's gradient with respect to the pinch point."""

    def __init__(self, task: CuttingTask, settings: GradConfig, seed: int):
        from warpcut.gradients import DifferentiableRollout

        self.rollout, self.settings, self.seed = DifferentiableRollout(task), settings, seed
        self.pinch_grad: np.ndarray | None = None

    @property
    def num_steps(self) -> int:
        return self.rollout.num_steps

    def state(self) -> None:
        return None  # nothing random: the episodes' noise is the seed's

    def load(self, state: None) -> None:
        pass

    def step(self, plan: np.ndarray, gains: None, last: bool) -> tuple[dict, np.ndarray | None, None]:
        """``(history fields, gradient, None)`` for :func:`optimize_plan` (no feedback gains); the last
        iterate has no backward pass."""
        batch = np.broadcast_to(plan, (self.settings.trials, *plan.shape))
        if last:
            forward, grads = self.rollout.forward(batch, seed=self.seed), None
        else:
            forward, grads = self.rollout.value_and_grad(batch, seed=self.seed, window=self.settings.window)
        self.pinch_grad = None if grads is None else grads.pinch.mean(axis=0)
        record = {
            "surrogate": float(np.nanmean(forward.surrogate)),
            # a diverged episode is NaN (and has no gradient)
            "error_vertices": float(np.nanmean(forward.score.error_vertices)),
        }
        return record, None if grads is None else grads.actions.mean(axis=0), None


class SmoothedGradient:
    """The es estimator (``GradConfig.estimator == "es"``): the gradient of the path score averaged over
    Gaussian perturbations of the plan, ``∇ E[error(plan + σε)]``, estimated from ``es_population`` perturbed
    plans in antithetic pairs (``+ε``, ``-ε``), each played on ``es_trials`` noisy episodes, all in one
    simulator batch. Errors are replaced by their centred ranks (robust to the score's outliers and scale;
    Salimans et al. 2017), a diverged plan ranking last. Forward passes only: no surrogate, no tape; what is
    smoothed is the score the evaluation reports.

    ``task``: the ``es_population x es_trials`` episodes (plan ``p``'s trials are envs ``p * es_trials ...``);
    ``seed``: the perturbations' random stream (NumPy's PCG64; :meth:`state` and :meth:`load` keep it across
    a resume); ``tether``: a cost added to each perturbed plan's error before the ranking (:class:`Tether`),
    or None."""

    def __init__(
        self,
        task: CuttingTask,
        settings: GradConfig,
        max_step: float,
        seed: int,
        tether: Tether | None = None,
    ) -> None:
        self.task, self.settings, self.max_step, self.tether = task, settings, float(max_step), tether
        self.rng = np.random.default_rng(seed)
        self.ranges = randomize_ranges(settings.es_randomize, settings.es_randomize_ranges)
        self.weights = RelativeWeights(task.config) if self.ranges else None

    @property
    def num_steps(self) -> int:
        return self.task.num_steps

    def state(self) -> dict:
        return self.rng.bit_generator.state

    def load(self, state: dict) -> None:
        self.rng.bit_generator.state = state

    def step(
        self, plan: np.ndarray, gains: np.ndarray | None, last: bool
    ) -> tuple[dict, np.ndarray | None, np.ndarray | None]:
        """``(history fields, plan's gradient, gains' gradient)`` for :func:`optimize_plan`; the last
        iterate is only validated."""
        if last:
            return {"surrogate": None, "error_vertices": None}, None, None
        error, grad, gains_grad = self(plan, gains)
        return {"surrogate": None, "error_vertices": error}, grad, gains_grad

    def __call__(
        self, plan: np.ndarray, gains: np.ndarray | None = None
    ) -> tuple[float, np.ndarray, np.ndarray | None]:
        """``(mean error of the perturbed plans in vertices (weighed, with es_randomize), gradient estimate
        shaped like plan, like gains (None without))``."""
        population, trials, sigma = (
            self.settings.es_population,
            self.settings.es_trials,
            self.settings.es_sigma_mm,
        )
        if self.settings.es_feedback_only:  # the plan stays as it is (zero): only the gains move
            eps = np.zeros((population, *plan.shape), dtype=np.float32)
        else:
            half = self.rng.standard_normal((population // 2, *plan.shape)).astype(np.float32)
            eps = np.concatenate([half, -half])
        plans = np.clip(plan + sigma * eps, -self.max_step, self.max_step).astype(np.float32)
        perturbed, eps_gains = None, None
        if gains is not None:
            half = self.rng.standard_normal((population // 2, *gains.shape)).astype(np.float32)
            eps_gains = np.concatenate([half, -half])
            perturbed = list(gains + sigma * eps_gains)
        if self.ranges:  # the same draws for every perturbed plan: env p * trials + k draws trial k's
            draws = sample_parameters(self.rng, self.ranges, trials)
            self.task.set_params(**{k: np.tile(v, population) for k, v in draws.items()})
        errors = self.task.run(PlanPolicy(list(plans), trials, perturbed)).error_vertices
        if self.weights is not None:
            errors = errors * self.weights(self.task)
        errors = errors.reshape(population, trials)
        finite = np.isfinite(errors).all(axis=1)
        fitness = np.where(finite, errors.mean(axis=1), np.inf)
        mean = float(np.mean(fitness[finite])) if finite.any() else float("nan")
        if self.tether is not None:
            fitness = fitness + self.tether.cost(plans, self.max_step)
        ranks = np.empty(population)
        ranks[np.argsort(fitness, kind="stable")] = np.arange(population)
        centred = ranks / (population - 1) - 0.5  # the highest error +0.5
        grad = np.tensordot(centred, eps, axes=1) / (population * sigma)
        gains_grad = (
            None if eps_gains is None else np.tensordot(centred, eps_gains, axes=1) / (population * sigma)
        )
        return mean, grad, gains_grad


class RelativeWeights:
    """Each env's weight under ``GradConfig.es_randomize``: the nominal sheet's no-tension error over that of
    the env's own sheet (:class:`warpcut.task.NoTensionReference`), so a sheet that hangs flat counts as much
    as the nominal one, as in the evaluation's relative improvement."""

    def __init__(self, nominal: SimConfig):
        self.nominal, self.reference = nominal, NoTensionReference()

    def __call__(self, task: CuttingTask) -> np.ndarray:
        return self.reference.scale(task, self.nominal)


class HeldOut:
    """The held-out episodes every iterate is scored on (``GradConfig.validation_trials``): their mean path
    error in vertices; with ``settings.es_randomize`` (over ``es_randomize_ranges``) they draw their
    parameters once, seeded by ``seed``, and each error is weighed as the es estimator weighs its own
    (:class:`RelativeWeights`)."""

    def __init__(self, task: CuttingTask, settings: GradConfig, seed: int):
        self.task, ranges = task, randomize_ranges(settings.es_randomize, settings.es_randomize_ranges)
        self.weights = RelativeWeights(task.config) if ranges else None
        if ranges:
            task.set_params(**sample_parameters(np.random.default_rng(seed), ranges, task.num_envs))

    def __call__(self, plan: np.ndarray, gains: np.ndarray | None) -> float:
        errors = self.task.run(PlanPolicy([plan], self.task.num_envs, [gains])).error_vertices
        if self.weights is not None:
            errors = errors * self.weights(self.task)
        return float(np.nanmean(errors))
