"""The env contract of pattern cutting with a tensioning arm (Thananjeyan et al., ICRA 2017).

One arm cuts a contour open loop; the policy moves the other arm's grasp 1 mm at a time to keep the sheet
in tension. :class:`PatternCut` is the batched engine (B sheets on one episode clock, NumPy in and out):
what every env is. :class:`envs.pattern_cut.PatternCutEnv` is one sheet as a ``gymnasium.Env``,
:class:`envs.vector.PatternCutVecEnv` the batch as a ``gymnasium.vector.VectorEnv``; both take the fields
of :class:`envs.options.PatternCutOptions` as keyword arguments.

Actions:
    ``"discrete"`` (paper): ``Discrete(5)`` = stay, +x, -x, +y, -y, each ``max_step_mm`` (1 mm);
    ``allow_z=True`` adds +z, -z (``Discrete(7)``). ``"continuous"``: ``Box(-1, 1, (2,))``, the x and y
    move in units of ``max_step_mm`` (``(3,)`` with ``allow_z``); values outside [-1, 1] are clipped.
    Any NaN or infinite (or, for discrete, non-integer or out-of-range) action raises ``ValueError``. The
    simulator also caps the grasp's total displacement at ``max_displacement_mm``.

Reward:
    Sparse (paper): 0 before the last step; at it, ``-error_mm2 / contour.area_mm2``, the cut's error
    (``sim_config.score``: the paper's path score by default, :mod:`warpcut.scoring`) relative to the
    intended area. With ``dense_reward``, every step also adds ``-deviation / max_displacement_mm /
    num_steps``, where ``deviation`` is the mean distance, in material coordinates, between where the
    scissors cut during the step and where they meant to cut (:meth:`CuttingTask.cut_deviation`: the path
    score's own increment; 0 while the tip travels), so an episode's shaping sums to about minus the mean
    deviation in units of ``max_displacement_mm``. With ``relative_reward`` both are scaled, per env, by
    the nominal sheet's no-tension error over that of the env's own sheet (noise-free, computed once per
    parameter set, :class:`warpcut.task.NoTensionReference`; at most
    :data:`warpcut.task.RELATIVE_REWARD_MAX_SCALE`): under domain randomisation a sheet that hangs flat,
    where any cut is nearly right, weighs as much as the nominal one, as it does in the evaluation's
    relative improvement.

Episode:
    Ends (``terminated``) once the scissors have followed the whole trajectory, ``num_steps`` steps. Every
    step's ``info`` has ``cut_deviation_mm`` (that step's mean deviation, NaN while travelling) and
    ``running_path_error_mm2`` (the deviations so far times the tip's advance: the area between the
    intended and the cut path so far, about what the path score will charge). The last step's ``info``
    also holds the score (:meth:`warpcut.scoring.Score.info`: ``error_vertices``, ``error_mm2``, the path
    and separated errors, ``separated``, ``dropped_fraction``, ``missed_vertices``, ``excess_vertices``)
    and ``relative_error`` (``error_mm2 / area_mm2``). With ``max_episode_steps`` below ``num_steps`` the
    episode is instead cut short (``truncated``) with no score and no final reward.

Divergence:
    An env whose simulation leaves the physical range (non-finite vertex positions, or vertices flung far
    from the sheet: :meth:`warpcut.task.CuttingTask.diverged`, e.g. from a huge ``noise_std``) is frozen:
    from that step on its observation is all zeros (never NaN), its reward 0, its score NaN (never a
    number to average in), and ``info["diverged"]`` (B,) bool, present in every step's info once any env
    has diverged, is True for it. :class:`PatternCut` ends the episode (``terminated``) once every env has
    diverged: the single env at once. :class:`envs.vector.PatternCutVecEnv` terminates each diverged env at
    the step it diverged.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from warpcut.sim.config import sample_parameters
from warpcut.task import CuttingTask, NoTensionReference
from warpcut.validation import check_instance, check_integer

from .observations import (
    LOOKAHEAD_STEPS,
    Fiducials,
    normalise_positions,
    observation_bounds,
    sample_fiducials,
)
from .options import NO_TENSION_FLOOR, PatternCutOptions

DISCRETE_MOVES = np.array(
    [[0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float32
)
"""Grasp move of each discrete action, in units of ``max_step_mm``: stay, +x, -x, +y, -y, +z, -z."""


def check_part(part: tuple[int, int] | None, num_envs: int) -> tuple[int, int]:
    """``part`` (``(first, total)``: ``num_envs`` envs from ``first`` of a batch of ``total``) checked; None:
    the whole batch, ``(0, num_envs)``."""
    if part is None:
        return 0, num_envs
    ok = isinstance(part, tuple | list) and len(part) == 2
    ok = ok and all(isinstance(v, int | np.integer) for v in part)
    if not ok or not (0 <= part[0] and part[0] + num_envs <= part[1]):
        raise ValueError(
            f"part: give (first, total), {num_envs} envs from env first of a batch of total envs, "
            f"0 <= first and first + {num_envs} <= total (got {part!r})"
        )
    return int(part[0]), int(part[1])


class PatternCut:
    """B pattern-cutting scenes on one episode clock: NumPy observations, actions, rewards; no autoreset.

    Args:
        options: The scenario.
        num_envs: Batch size B.
        part: ``(first, total)``: these B envs are envs ``first .. first + B - 1`` of a batch of ``total``
            (``options`` theirs: :meth:`~envs.options.PatternCutOptions.part`), and cut as those envs of the
            whole batch would, for the same seed and actions: the same process noise, fiducials and
            randomised sheets. Default: the whole batch.

    Attributes:
        task: The underlying :class:`~warpcut.task.CuttingTask` (what the baseline tensioners drive).
        fiducials: The tracked fiducial points.
        observation_space: One env's observation space (layout: :mod:`envs.observations`).
        action_space: One env's action space.
        area_mm2: (B,) intended area of each env's contour (mm^2).
        episode_steps: Steps per episode: the cut's ``num_steps``, or ``max_episode_steps`` if smaller.
        last_moves: (B, 3) the grasp moves (mm) of the last step.
    """

    def __init__(self, options: PatternCutOptions, num_envs: int, part: tuple[int, int] | None = None):
        check_instance("PatternCut.options", options, PatternCutOptions, "a PatternCutOptions")
        num_envs = check_integer("PatternCut.num_envs", num_envs, 1)
        part = check_part(part, num_envs)
        options.validated()  # its fields may have been changed since it was made
        self._build(options, num_envs, part)

    @classmethod
    def checked(cls, options: PatternCutOptions, num_envs: int, part: tuple[int, int]) -> PatternCut:
        """A scene of arguments checked already: a vector env's (its options built and checked just now,
        its batch size and ``part`` checked)."""
        scene: PatternCut = cls.__new__(cls)
        scene._build(options, num_envs, part)
        return scene

    def _build(self, options: PatternCutOptions, num_envs: int, part: tuple[int, int]) -> None:
        self.part = part
        self.options = options
        self.num_envs = num_envs
        low, high = observation_bounds(options.num_fiducials, options.contour_features, options.lookahead)
        self.observation_space = gym.spaces.Box(low, high, dtype=np.float32)
        num_axes = 3 if options.allow_z else 2
        if options.action_type == "discrete":
            self.action_space = gym.spaces.Discrete(1 + 2 * num_axes)
        else:
            self.action_space = gym.spaces.Box(-1.0, 1.0, (num_axes,), dtype=np.float32)
        config = options.config()
        contours, pinch_points, segments = options.per_env(num_envs)
        self._randomized = options.randomized()  # the randomised parameters and their ranges, checked
        self.task = CuttingTask(
            config, contours, num_envs, pinch_points=pinch_points, segments=segments, device=options.device,
            arm=options.arm, allow_infeasible_pinch=options.allow_infeasible_pinch,
        )  # fmt: skip
        self.task.sim.first_noise_stream = self.part[0]  # env e draws the noise of env first + e
        self.config = self.task.config
        self.area_mm2 = np.array([c.area_mm2 for c in contours])
        self.episode_steps = min(self.task.num_steps, options.max_episode_steps or self.task.num_steps)
        self.fiducials = Fiducials(self.task.grid, options.shaft_radius_mm)
        self.task.fiducials = self.fiducials  # what a recording of the task shows
        self.last_moves = np.zeros((num_envs, 3), dtype=np.float32)
        self._sampled = False
        self._running_path_error = np.zeros(num_envs)
        self.diverged = np.zeros(num_envs, dtype=bool)
        """(B,) bool: envs whose simulation diverged this episode (module docstring)."""
        self._reward_scale: np.ndarray | None = None
        self._no_tension = NoTensionReference()
        """No-tension errors (noise-free) by (settle parameters, contour, segments): relative_reward."""
        self.newly_diverged = np.zeros(num_envs, dtype=bool)
        """(B,) bool: envs that diverged in the last step."""
        self._over = False
        self._fiducial_reader: tuple[tuple, Callable[[], tuple[np.ndarray, np.ndarray]]] | None = None
        """The fiducials' cells and a ``Simulator.interpolator`` of them (:meth:`_fiducial_cells`)."""

    def pinch_info(self) -> dict[str, np.ndarray]:
        """Whether each env's pinch point is a grasp the gripper could make: ``pinch_feasible`` (B,) bool,
        and where one is not (allowed by ``allow_infeasible_pinch``), ``pinch_problem`` (B,) the rule it
        breaks ("" where feasible). In the reset infos and with each episode's score."""
        problems = self.task.pinch_problems
        info = {"pinch_feasible": np.array([p is None for p in problems])}
        if not info["pinch_feasible"].all():
            info["pinch_problem"] = np.array([p or "" for p in problems], dtype=object)
        return info

    @property
    def step_index(self) -> int:
        """Steps taken in the current episode."""
        return self.task.step_index

    def reset(self, rng: np.random.Generator, resample_fiducials: bool, repeat: int = 1) -> np.ndarray:
        """Start an episode with process noise seeded from ``rng``; return (B, D) observations.

        Args:
            rng: Random source of the noise seed and of the fiducials.
            resample_fiducials: Draw new fiducials (always done at the first reset).
            repeat: With randomised parameters, the batch is ``repeat`` copies of ``B / repeat`` sheets: env
                ``e`` draws the parameters of env ``e % (B / repeat)`` (common random numbers: es compares
                its perturbed policies, copy by copy, on the same sheets).
        """
        seed = int(rng.integers(2**31 - 1))
        if resample_fiducials or not self._sampled:
            if self.options.num_fiducials == 0:  # an observation of time, grasp (and contour features) only
                self.fiducials.material = np.zeros((self.num_envs, 0, 2))
            else:
                self.fiducials.material = sample_fiducials(
                    rng, self.options.num_fiducials, self.task.contours, self.task.pinch_points, self.config,
                    self.part,
                )  # fmt: skip
            self._sampled = True
        if self._randomized:
            first, total = self.part
            if repeat < 1 or total % repeat:
                raise ValueError(f"repeat: {repeat} must be >= 1 and divide the {total} envs")
            draws = sample_parameters(rng, self._randomized, total // repeat)
            rows = slice(first, first + self.num_envs)
            self.task.set_params(**{name: np.tile(values, repeat)[rows] for name, values in draws.items()})
            steps = self.task.num_steps
            self.episode_steps = min(steps, self.options.max_episode_steps or steps)
        if self.options.relative_reward:
            self._reward_scale = self._no_tension.scale(self.task, self.options.config())
        elif self.options.reward_reference == "no_tension":
            own, _ = self._no_tension.errors(self.task, self.options.config())
            self._reward_scale = self.area_mm2 / np.maximum(own, NO_TENSION_FLOOR * self.area_mm2)
        self.task.reset(seed=seed)
        self._running_path_error = np.zeros(self.num_envs)
        self.diverged = np.zeros(self.num_envs, dtype=bool)
        self.newly_diverged = np.zeros(self.num_envs, dtype=bool)
        self._over = False
        self.fiducials.reset(self.task.sim.positions())
        return self.observe()

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool, bool, dict[str, np.ndarray]]:
        """Move the grasps, advance the scissors one step.

        Args:
            actions: (B,) action indices (discrete; integer-valued floats are accepted) or (B, A) moves in
                units of ``max_step_mm`` (continuous).

        Returns:
            ``(observations (B, D) float32, rewards (B,) float64, terminated, truncated, info)``; ``info``
            holds (B,) arrays: every step the cut's deviation, and at the last step of a completed cut the
            score (module docstring); ``diverged`` once an env diverged. ``terminated`` is also True once
            every env has diverged.
        """
        if not self._sampled:
            raise RuntimeError("step: call reset() first")
        if self._over or self.task.done or self.step_index >= self.episode_steps:
            raise RuntimeError("step: the episode is over; call reset() first")
        first_update = self.task.update_index
        moves = self.moves(actions)
        self.last_moves = moves
        self.task.step(moves)
        diverged = self.task.diverged()
        self.newly_diverged = diverged & ~self.diverged
        self.diverged = diverged
        terminated = self.task.done or bool(diverged.all())
        truncated = not terminated and self.step_index >= self.episode_steps
        self._over = terminated or truncated
        rewards = np.zeros(self.num_envs)
        deviation, count = self.task.cut_deviation(first_update, self.task.update_index)
        deviation = np.where(diverged, np.nan, deviation)
        count = np.where(diverged, 0, count)
        moved = np.nan_to_num(deviation, nan=0.0)
        self._running_path_error += moved * count * self.config.trajectory_spacing_mm
        if self.options.dense_reward:
            rewards -= moved / self.config.max_displacement_mm / self.task.num_steps
        info = {"cut_deviation_mm": deviation, "running_path_error_mm2": self._running_path_error.copy()}
        if diverged.any():
            info["diverged"] = diverged.copy()
        if terminated:
            score = self.task.score()  # NaN for the diverged envs
            relative = score.error_mm2 / self.area_mm2
            rewards -= np.where(diverged, 0.0, relative)
            info.update(_score_info(score), relative_error=relative, **self.pinch_info())
        if self._reward_scale is not None:
            rewards *= self._reward_scale
        return self.observe(), rewards, terminated, truncated, info

    @property
    def reward_scale(self) -> np.ndarray:
        """(B,) the factor each env's reward is scaled by this episode (``relative_reward``; else all 1)."""
        return np.ones(self.num_envs) if self._reward_scale is None else self._reward_scale.copy()

    def moves(self, actions: np.ndarray) -> np.ndarray:
        """(B, 3) grasp moves (mm) for a batch of actions; raise ``ValueError`` naming a bad action."""
        actions = np.asarray(actions)
        b = self.num_envs
        if actions.dtype.kind not in "biuf":
            raise ValueError(f"action: expected numbers, got {actions!r}")
        finite = np.isfinite(actions)
        if not finite.all():
            env = int(np.argwhere(~finite)[0][0]) if actions.ndim else 0
            raise ValueError(f"action: {actions.tolist()} is not finite (env {env}); give finite numbers")
        if isinstance(self.action_space, gym.spaces.Discrete):
            n = int(self.action_space.n)
            if actions.shape != (b,):
                raise ValueError(f"action: expected shape ({b},) of indices in [0, {n}), got {actions.shape}")
            if np.any(actions != np.round(actions)) or np.any((actions < 0) | (actions >= n)):
                raise ValueError(f"action: {actions.tolist()} must be integers in [0, {n})")
            return DISCRETE_MOVES[actions.astype(np.int64)] * self.config.max_step_mm
        num_axes = self.action_space.shape[0]
        if actions.shape != (b, num_axes):
            raise ValueError(f"action: expected shape ({b}, {num_axes}), got {actions.shape}")
        moves = np.zeros((b, 3), dtype=np.float32)
        moves[:, :num_axes] = np.clip(actions, -1.0, 1.0) * self.config.max_step_mm
        return moves

    def tracking_error(self) -> np.ndarray:
        """(B, 3) :meth:`CuttingTask.tracking_error` (mm); NaN while travelling or done."""
        return self.task.tracking_error()

    def _fiducial_cells(self) -> tuple[np.ndarray, np.ndarray]:
        """The fiducials' world positions (B, K, 3) and whether their cells are whole (B, K), read by an
        interpolator made once per set of cells (a reset, or fiducials placed by hand and reset)."""
        cells = self.fiducials.cells
        if self._fiducial_reader is None or self._fiducial_reader[0] is not cells:
            self._fiducial_reader = (cells, self.task.sim.interpolator(*cells))
        return self._fiducial_reader[1]()

    def observe(self) -> np.ndarray:
        """(B, D) float32 observations of the current state (layout: :mod:`envs.observations`)."""
        u = self.task.update_index
        tip = self.task.tip_positions(max(u - 1, 0))  # where the scissors are now
        fiducials = self.fiducials.track_cells(*self._fiducial_cells(), tip)
        if self.options.lookahead:  # the env's own progress: the batch's clock means nothing across contours
            time = np.minimum(self.task.update_index / self.task.trajectory_updates, 1.0)[:, None]
        else:
            time = np.full((self.num_envs, 1), self.step_index / self.task.num_steps)
        grasp = self.task.sim.displacements()
        parts = [
            time,
            grasp / self.config.max_displacement_mm,
            normalise_positions(fiducials, self.config).reshape(self.num_envs, -1),
        ]
        if self.options.contour_features:
            tracking = np.nan_to_num(self.tracking_error(), nan=0.0) / self.config.max_displacement_mm
            parts += [normalise_positions(tip[:, :3], self.config), tip[:, 3:4], tracking]
        if self.options.lookahead:
            parts += self._lookahead(tip, grasp)
        obs = np.concatenate(parts, axis=1).astype(np.float32)
        obs[self.diverged] = 0.0  # a diverged env's state means nothing (and may be NaN)
        # NaN to 0 and the rest clipped to the bounds (infinities to them): np.nan_to_num then np.clip, the
        # same values with two passes fewer (the envs observe every step).
        np.copyto(obs, 0.0, where=np.isnan(obs))
        return np.clip(obs, self.observation_space.low, self.observation_space.high, out=obs)

    def _lookahead(self, tip: np.ndarray, displacements: np.ndarray) -> list[np.ndarray]:
        """The look-ahead block of the observation (``lookahead``; :mod:`envs.observations`): the grasp from
        the tip, and per look-ahead point the planned tip's move, the tracking error there and whether it
        cuts."""
        config, task = self.config, self.task
        count = self.options.lookahead
        stride = LOOKAHEAD_STEPS * config.updates_per_step
        tips, targets = task.lookahead(stride * np.arange(1, count + 1))
        half = max(config.width_mm, config.height_mm) / 2
        grasp = np.nan_to_num(task.pinch_points, nan=0.0) + displacements[:, :2]
        pinch = (grasp - tip[:, :2]) / half
        moves = (tips[..., :2] - tip[:, None, :2]) / half
        errors = np.nan_to_num(targets - tips[..., :3], nan=0.0) / config.max_displacement_mm
        points = np.concatenate([moves, errors, tips[..., 3:4]], axis=2).reshape(self.num_envs, -1)
        return [pinch, points]


def _score_info(score) -> dict[str, np.ndarray]:
    """:meth:`Score.info`, with ``diverged`` only where an env diverged (the step infos' convention)."""
    info = score.info()
    if not info["diverged"].any():
        del info["diverged"]
    return info


def check_reset_options(options: dict[str, Any] | None, allowed: tuple[str, ...] = ()) -> dict[str, Any]:
    """The reset ``options`` as a dict; ``ValueError`` naming any key outside ``allowed``."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise ValueError(f"reset: options must be a dict or None (got {type(options).__name__})")
    unknown = sorted(set(options) - set(allowed), key=str)
    if unknown:
        takes = f"it takes only {', '.join(map(repr, allowed))}" if allowed else "this env takes none"
        raise ValueError(f"reset: unknown options {unknown}; {takes}")
    return options


def reject_reset_options(options: dict[str, Any] | None) -> None:
    """Raise ``ValueError`` for non-empty reset ``options``: these envs take none."""
    check_reset_options(options)
