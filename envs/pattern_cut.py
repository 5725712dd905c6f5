"""Pattern cutting with a tensioning arm (Thananjeyan et al., ICRA 2017) as a Gymnasium env.

One arm cuts a contour open loop; the policy moves the other arm's grasp 1 mm at a time to keep the sheet
in tension. :class:`PatternCut` is the batched engine (B sheets on one episode clock, NumPy in and out);
:class:`PatternCutEnv` is one sheet as a ``gymnasium.Env``, :class:`envs.vector.PatternCutVecEnv` the batch
as a ``gymnasium.vector.VectorEnv``. Both take the fields of :class:`PatternCutOptions` as keyword arguments.

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
    deviation in units of ``max_displacement_mm``.

Episode:
    Ends (``terminated``) once the scissors have followed the whole trajectory, ``num_steps`` steps. Every
    step's ``info`` has ``cut_deviation_mm`` (that step's mean deviation, NaN while travelling) and
    ``running_path_error_mm2`` (the deviations so far times the tip's advance: the area between the
    intended and the cut path so far, about what the path score will charge). The last step's ``info``
    also holds the score (:meth:`warpcut.scoring.Score.info`: ``error_vertices``, ``error_mm2``, the path
    and separated errors, ``separated``, ``dropped_fraction``, ``missed_vertices``, ``excess_vertices``)
    and ``relative_error`` (``error_mm2 / area_mm2``). With ``max_episode_steps`` below ``num_steps`` the
    episode is instead cut short (``truncated``) with no score and no final reward.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from envs.observations import Fiducials, normalise_positions, observation_bounds, sample_fiducials
from warpcut.contours import Contour, load_contour
from warpcut.fiducials import NUM_FIDUCIALS, SHAFT_RADIUS_MM
from warpcut.planning import nearest_feasible
from warpcut.sim.config import PerEnv, SimConfig
from warpcut.task import CuttingTask

ContourSpec = str | os.PathLike | Contour
ACTION_TYPES = ("discrete", "continuous")
DISCRETE_MOVES = np.array(
    [[0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float32
)
"""Grasp move of each discrete action, in units of ``max_step_mm``: stay, +x, -x, +y, -y, +z, -z."""
SIM_OVERRIDES = ("fixture", "resolution", "damping", "dt", "gravity", "elasticity", "noise_std")


@dataclass
class PatternCutOptions:
    """A pattern-cutting scenario and how the policy sees and acts on it.

    Physical parameters take one value for all envs or a list with one value per env (see
    :class:`~warpcut.sim.config.SimConfig`); ``None`` keeps ``sim_config``'s value.
    """

    contour: ContourSpec | Sequence[ContourSpec] = "fls-circle"
    """Contour to cut: a built-in name, a ``.json``/``.svg`` path or a ``Contour``; or a list, one per env."""
    pinch_point: Sequence[float] | np.ndarray | None = None
    """Material point (mm) the tensioning arm pinches, ``(2,)`` or ``(B, 2)``. Default: each contour's
    centroid, or the feasible point nearest to it (:func:`warpcut.planning.nearest_feasible`)."""
    segments: Sequence[Sequence[Sequence[float]]] | Sequence[Sequence[Sequence[Sequence[float]]]] | None = (
        None
    )
    """Material polylines (mm) the scissors cut, in order (e.g. a plan's ``ordered_segments()``): one such
    list for every env, or a list of them, one per env; default: the whole contour as one segment
    (``warpcut.task.default_segments``)."""
    sim_config: SimConfig = field(default_factory=SimConfig)
    """Base simulation parameters; the fields below override it when given."""
    fixture: str | None = None
    """How the sheet is held: ``"corners"`` (FLS, the default) or ``"rows"``."""
    resolution: int | tuple[int, int] | None = None
    """Vertices per side (default 25)."""
    damping: PerEnv | None = None
    """Verlet velocity retention per update (paper alpha = 0.99)."""
    dt: PerEnv | None = None
    """Update time step (s)."""
    gravity: PerEnv | None = None
    """Downward acceleration (mm/s^2)."""
    elasticity: PerEnv | None = None
    """Spring correction per sweep (paper tau = 1)."""
    noise_std: PerEnv | None = None
    """Process noise per free vertex per update (mm), paper sigma; default 0."""
    device: str | None = None
    """Warp device of the simulator (``"cpu"``, ``"cuda"``); default: CUDA when available."""
    num_fiducials: int = NUM_FIDUCIALS
    """Fiducial points observed on the sheet (paper: 12)."""
    resample_fiducials: bool = False
    """Draw new fiducials at every reset. Otherwise they are drawn at a seeded reset (and the first one)
    and kept, so a given seed always gives the same fiducials."""
    shaft_radius_mm: float = SHAFT_RADIUS_MM
    """Radius of the cutting arm's shaft, which hides the fiducials under it (mm)."""
    contour_features: bool = False
    """Add the scissor tip, its cutting flag and the tracking error to the observation, for policies
    meant to generalise across contours."""
    observe_pinch: bool = False
    """Add the pinch point (material x, y, normalised) to the observation, for one policy shared across
    pinch points (``warpcut run`` trains one over all pinch candidates)."""
    action_type: str = "discrete"
    """``"discrete"`` (paper: stay, +-x, +-y at 1 mm) or ``"continuous"`` (moves in units of 1 mm)."""
    allow_z: bool = False
    """Let the grasp move along z too: ``Discrete(7)``, or a 3-D continuous action (paper: x-y only)."""
    dense_reward: bool = False
    """Add the per-step cut-deviation penalty (the path score's increment) to the sparse final reward."""
    max_episode_steps: int | None = None
    """Truncate episodes after this many steps; default: the whole cut."""

    @classmethod
    def build(cls, options: PatternCutOptions | None = None, **kwargs: Any) -> PatternCutOptions:
        """``options`` (default: all defaults) with the fields in ``kwargs`` replaced."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(kwargs) - names)
        if unknown:
            raise TypeError(f"unknown option(s) {', '.join(unknown)}; choose from {', '.join(sorted(names))}")
        return dataclasses.replace(options or cls(), **kwargs)

    def config(self) -> SimConfig:
        """``sim_config`` with the given overrides, validated."""
        changes = {k: getattr(self, k) for k in SIM_OVERRIDES if getattr(self, k) is not None}
        return self.sim_config.replace(**changes)

    def contours(self, num_envs: int) -> list[Contour]:
        """One loaded contour per env."""
        single = isinstance(self.contour, str | os.PathLike | Contour)
        specs = [self.contour] if single else list(self.contour)
        if len(specs) not in (1, num_envs):
            raise ValueError(
                f"contour: got {len(specs)} for {num_envs} envs; give one contour or one per env"
            )
        loaded = [c if isinstance(c, Contour) else load_contour(c) for c in specs]
        return loaded * num_envs if len(loaded) == 1 else loaded

    def to_dict(self) -> dict[str, Any]:
        """The options as plain JSON-friendly values (contours by name), e.g. for experiment loggers."""
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "contour":
                specs = value if isinstance(value, list | tuple) else [value]
                value = [c.name if isinstance(c, Contour) else os.fspath(c) for c in specs]
            elif f.name == "sim_config":
                value = dataclasses.asdict(value)
            elif f.name == "segments" and value is not None:
                value = [np.asarray(p).tolist() for p in value]
            out[f.name] = np.asarray(value).tolist() if isinstance(value, np.ndarray) else value
        return out


class PatternCut:
    """B pattern-cutting scenes on one episode clock: NumPy observations, actions, rewards; no autoreset.

    Args:
        options: The scenario.
        num_envs: Batch size B.

    Attributes:
        task: The underlying :class:`~warpcut.task.CuttingTask` (what the baseline tensioners drive).
        fiducials: The tracked fiducial points.
        observation_space: One env's observation space (layout: :mod:`envs.observations`).
        action_space: One env's action space.
        area_mm2: (B,) intended area of each env's contour (mm^2).
        episode_steps: Steps per episode: the cut's ``num_steps``, or ``max_episode_steps`` if smaller.
    """

    def __init__(self, options: PatternCutOptions, num_envs: int):
        if options.action_type not in ACTION_TYPES:
            raise ValueError(f"action_type: choose one of {ACTION_TYPES} (got {options.action_type!r})")
        if not isinstance(options.num_fiducials, int) or options.num_fiducials < 0:
            raise ValueError(f"num_fiducials: must be a non-negative integer (got {options.num_fiducials!r})")
        if not options.shaft_radius_mm >= 0:
            raise ValueError(f"shaft_radius_mm: must be >= 0 mm (got {options.shaft_radius_mm!r})")
        if options.max_episode_steps is not None and options.max_episode_steps < 1:
            raise ValueError(f"max_episode_steps: must be >= 1 or None (got {options.max_episode_steps!r})")
        self.options = options
        self.num_envs = num_envs
        config = options.config()
        contours = options.contours(num_envs)
        if options.pinch_point is None:
            pinch_points = np.array([nearest_feasible(c.centroid, c, config) for c in contours])
        else:
            pinch_points = options.pinch_point
        segments = None
        if options.segments is not None:
            segments = _segments_per_env(options.segments, num_envs)
        self.task = CuttingTask(
            config, contours, num_envs, pinch_points=pinch_points, segments=segments, device=options.device
        )
        self.config = self.task.config
        self.area_mm2 = np.array([c.area_mm2 for c in contours])
        self.episode_steps = min(self.task.num_steps, options.max_episode_steps or self.task.num_steps)
        self.fiducials = Fiducials(self.task.grid, options.shaft_radius_mm)
        self.task.fiducials = self.fiducials  # what a recording of the task shows
        low, high = observation_bounds(options.num_fiducials, options.contour_features, options.observe_pinch)
        self.observation_space = gym.spaces.Box(low, high, dtype=np.float32)
        num_axes = 3 if options.allow_z else 2
        if options.action_type == "discrete":
            self.action_space = gym.spaces.Discrete(1 + 2 * num_axes)
        else:
            self.action_space = gym.spaces.Box(-1.0, 1.0, (num_axes,), dtype=np.float32)
        self._sampled = False
        self._running_path_error = np.zeros(num_envs)

    @property
    def step_index(self) -> int:
        """Steps taken in the current episode."""
        return self.task.step_index

    def reset(self, rng: np.random.Generator, resample_fiducials: bool) -> np.ndarray:
        """Start an episode with process noise seeded from ``rng``; return (B, D) observations.

        Args:
            rng: Random source of the noise seed and of the fiducials.
            resample_fiducials: Draw new fiducials (always done at the first reset).
        """
        seed = int(rng.integers(2**31 - 1))
        if resample_fiducials or not self._sampled:
            self.fiducials.material = sample_fiducials(
                rng, self.options.num_fiducials, self.task.contours, self.task.pinch_points, self.config
            )
            self._sampled = True
        self.task.reset(seed=seed)
        self._running_path_error = np.zeros(self.num_envs)
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
            score (module docstring).
        """
        if self.task.done or self.step_index >= self.episode_steps:
            raise RuntimeError("step: the episode is over; call reset() first")
        first_update = self.task.update_index
        self.task.step(self.moves(actions))
        terminated = self.task.done
        truncated = not terminated and self.step_index >= self.episode_steps
        rewards = np.zeros(self.num_envs)
        deviation, count = self.task.cut_deviation(first_update, self.task.update_index)
        moved = np.nan_to_num(deviation, nan=0.0)
        self._running_path_error += moved * count * self.config.trajectory_spacing_mm
        if self.options.dense_reward:
            rewards -= moved / self.config.max_displacement_mm / self.task.num_steps
        info = {"cut_deviation_mm": deviation, "running_path_error_mm2": self._running_path_error.copy()}
        if terminated:
            score = self.task.score()
            relative = score.error_mm2 / self.area_mm2
            rewards -= relative
            info.update(score.info(), relative_error=relative)
        return self.observe(), rewards, terminated, truncated, info

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
        """(B, 3) ``target_world() - tip`` (mm) for the next update; NaN while travelling or done."""
        return self.task.target_world() - self.task.tip_positions()[:, :3]

    def observe(self) -> np.ndarray:
        """(B, D) float32 observations of the current state (layout: :mod:`envs.observations`)."""
        u = self.task.update_index
        tip = self.task.tip_positions(max(u - 1, 0))  # where the scissors are now
        fiducials = self.fiducials.track(self.task.sim.positions(), self.task.sim.alive_mask(), tip)
        parts = [
            np.full((self.num_envs, 1), self.step_index / self.task.num_steps),
            self.task.sim.displacements() / self.config.max_displacement_mm,
            normalise_positions(fiducials, self.config).reshape(self.num_envs, -1),
        ]
        if self.options.contour_features:
            tracking = np.nan_to_num(self.tracking_error(), nan=0.0) / self.config.max_displacement_mm
            parts += [normalise_positions(tip[:, :3], self.config), tip[:, 3:4], tracking]
        if self.options.observe_pinch:
            pinch = np.nan_to_num(self.task.pinch_points, nan=0.0)
            parts.append(normalise_positions(np.pad(pinch, ((0, 0), (0, 1))), self.config)[:, :2])
        obs = np.concatenate(parts, axis=1).astype(np.float32)
        return np.clip(obs, self.observation_space.low, self.observation_space.high)


class PatternCutEnv(gym.Env):
    """One sheet being cut while the policy tensions it; see the module docstring and
    :class:`PatternCutOptions` (every field is a keyword argument).

    Args:
        options: The scenario; keyword arguments replace its fields.
        render_mode: Must be ``None``: the env does not render.
    """

    metadata = {"render_modes": []}

    def __init__(
        self, options: PatternCutOptions | None = None, render_mode: str | None = None, **kwargs: Any
    ):
        if render_mode is not None:
            raise ValueError(f"render_mode: PatternCutEnv does not render (got {render_mode!r}); use None")
        self.options = PatternCutOptions.build(options, **kwargs)
        self.scene = PatternCut(self.options, num_envs=1)
        self.observation_space = self.scene.observation_space
        self.action_space = self.scene.action_space

    @property
    def task(self) -> CuttingTask:
        """The underlying one-env :class:`~warpcut.task.CuttingTask`."""
        return self.scene.task

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Settled, uncut sheet; the grasp at the pinch point. A ``seed`` also redraws the fiducials.
        There are no reset ``options``."""
        super().reset(seed=seed)
        reject_reset_options(options)
        obs = self.scene.reset(self.np_random, seed is not None or self.options.resample_fiducials)
        return obs[0], {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Move the grasp by ``action`` and advance the scissors one step (module docstring)."""
        obs, rewards, terminated, truncated, info = self.scene.step(np.asarray(action)[None])
        return obs[0], float(rewards[0]), terminated, truncated, {k: float(v[0]) for k, v in info.items()}


def _segments_per_env(segments: Sequence, num_envs: int) -> list[list[np.ndarray]]:
    """``PatternCutOptions.segments`` as one list of (N, 2) polylines per env."""
    usage = "give a list of polylines, each at least 2 points [[x_mm, y_mm], ...], or one such list per env"

    def path(value: Sequence, where: str) -> list[np.ndarray]:
        try:
            polylines = [np.asarray(p, dtype=np.float64) for p in value]
        except (TypeError, ValueError) as error:
            raise ValueError(f"segments{where}: {usage} ({error})") from None
        if not polylines or any(p.ndim != 2 or p.shape[1] != 2 or len(p) < 2 for p in polylines):
            raise ValueError(f"segments{where}: {usage}")
        return polylines

    try:  # one path for every env: segments[i][j] is a point [x, y]
        per_env = np.ndim(segments[0][0][0]) > 0
    except (TypeError, IndexError, ValueError):
        per_env = False
    if not per_env:
        return [path(segments, "")] * num_envs
    if len(segments) != num_envs:
        raise ValueError(f"segments: got {len(segments)} paths for {num_envs} envs; give one, or one per env")
    return [path(s, f"[{k}]") for k, s in enumerate(segments)]


def reject_reset_options(options: dict[str, Any] | None) -> None:
    """Raise ``ValueError`` for non-empty reset ``options``: these envs take none."""
    if options:
        raise ValueError(f"reset: unknown options {sorted(options)}; the pattern-cutting envs take none")
