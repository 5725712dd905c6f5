"""What a pattern-cutting env cuts and how its policy sees and acts: :class:`PatternCutOptions`, the one
spec of a scenario that the envs, training (saved as a run directory's ``options.json``) and evaluation
share, and its policy-facing part :class:`EnvConfig` (observations, actions, reward, domain
randomisation), whose defaults are the default learner's."""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warpcut.contours import Contour, builtin_names
from warpcut.fiducials import NUM_FIDUCIALS, SHAFT_RADIUS_MM
from warpcut.planning import ArmModel, check_pinch, default_pinch, resolve_contour
from warpcut.sim.config import (
    PHYSICAL_PARAMETERS,
    RANDOMIZE_ALIASES,
    RANDOMIZE_RANGES,
    PerEnv,
    SimConfig,
    check_sim_field,
    randomize_ranges,
)
from warpcut.sim.memory import check_batch_memory
from warpcut.validation import (
    ConfigError,
    check_choice,
    check_flag,
    check_instance,
    check_integer,
    check_known_fields,
    check_number,
    check_text,
    fail,
    is_number,
)

ContourSpec = str | os.PathLike | Contour
SIM_OVERRIDES = ("fixture", "resolution", "damping", "dt", "gravity", "elasticity", "noise_std")
"""The :class:`PatternCutOptions` fields that override ``sim_config``'s."""

REWARD_REFERENCES = ("area", "no_tension")
"""What a reward is relative to (:attr:`EnvConfig.reward_reference`)."""

NO_TENSION_FLOOR = 0.01
"""``reward_reference = "no_tension"`` divides by at least this share of the contour's area: a contour that
no tension already cuts almost exactly would otherwise weigh without bound."""

ACTION_TYPES = ("discrete", "continuous")
"""How a policy acts: ``discrete`` (stay or a 1 mm move along one axis) or ``continuous`` (a move of up to
1 mm
per axis)."""


@dataclass
class EnvConfig:
    """How a policy sees the sheet, acts on it and is rewarded: the env's side of a learner's recipe.

    The defaults are those of warpcut's default learner (es, ``agents.algorithms``), so a policy it trains
    runs on ``gymnasium.make("warpcut/PatternCut-v0", contour=...)`` as is: contour features observed,
    continuous x-y-z moves, a dense reward. The paper's setting is ``contour_features=False,
    action_type="discrete", allow_z=False, dense_reward=False``.
    """

    num_fiducials: int = NUM_FIDUCIALS
    """Fiducial points observed on the sheet (paper: 12)."""
    resample_fiducials: bool = False
    """Draw new fiducials at every reset. Otherwise they are drawn at a seeded reset (and the first one)
    and kept, so a given seed always gives the same fiducials."""
    shaft_radius_mm: float = SHAFT_RADIUS_MM
    """Radius of the cutting arm's shaft, which hides the fiducials under it (mm)."""
    contour_features: bool = True
    """Add the scissor tip, its cutting flag and the tracking error (the vector from the tip to the contour
    point it is about to cut, as it lies on the moved sheet) to the observation (the paper: fiducials
    only)."""
    lookahead: int = 0
    """Look-ahead points observed along the planned trajectory (:mod:`envs.observations`): what lies ahead
    of the scissors, the env's own progress and the grasp from the tip; needs ``contour_features``. 0: none
    (a policy for one contour learns its contour by heart); a policy for many contours needs them
    (``warpcut train --generated``)."""
    action_type: str = "continuous"
    """``"continuous"`` (moves of up to ``max_step_mm`` per axis) or ``"discrete"`` (the paper's: stay, or
    a 1 mm move along one axis)."""
    allow_z: bool = True
    """Let the grasp move along z too (lift or lower the sheet): a 3-D continuous action, or ``Discrete(7)``
    (the paper: x-y only)."""
    dense_reward: bool = True
    """Add the per-step cut-deviation penalty (the path score's increment) to the sparse final reward (the
    paper: the final reward alone)."""
    relative_reward: bool = False
    """Scale every env's reward by the nominal sheet's no-tension error over its own sheet's (module
    :mod:`envs.core`): with domain randomisation, each sheet counts by its relative improvement, as the
    evaluation counts it; validation scales each episode's error alike. Without randomisation every scale
    is 1."""
    reward_reference: str = "area"
    """What every env's reward is relative to: ``"area"``, the contour's intended area (the reward of the
    module :mod:`envs.core`); or ``"no_tension"``, the env's own no-tension error (noise-free, on its own
    sheet, for its contour and segments): the final reward is then ``-error / no-tension error``, minus
    Table I's improvement, so that across many contours each counts by its improvement, however large or
    hard it is (a generalist's training; the dense reward is scaled alike). ``"no_tension"`` implies what
    ``relative_reward`` does: leave that false."""
    max_episode_steps: int | None = None
    """Truncate episodes after this many steps; default: the whole cut."""
    randomize: Sequence[str] = ()
    """Domain randomisation: the physical parameters (``gravity``, ``elasticity``, ``noise_std`` or
    ``noise``, ``damping``) drawn anew for every env at every reset, uniformly over
    :data:`~warpcut.sim.config.RANDOMIZE_LEVELS` levels of their range (``randomize_ranges``). Empty:
    the nominal parameters throughout. Evaluation runs a trained policy on the nominal parameters
    (:meth:`PatternCutOptions.nominal`)."""
    randomize_ranges: dict[str, Sequence[float]] | None = None
    """``{parameter: [low, high]}`` for the randomised parameters, in their units; a parameter not given
    takes its :data:`~warpcut.sim.config.RANDOMIZE_RANGES` default."""

    def __post_init__(self):
        self._check_fields()

    def validated(self) -> EnvConfig:
        """Itself, every field checked again (they may have been changed since it was made); a
        :class:`~warpcut.validation.ConfigError` names ``Class.field`` and what it takes."""
        self._check_fields()
        return self

    def _check_fields(self) -> None:
        """Each field on its own, wrong types and values named here, not deep inside the env
        (:mod:`warpcut.validation`); whether ``randomize_ranges`` fits ``randomize`` is :meth:`randomized`'s
        (a file or ``--set`` may give one before the other)."""
        owner = type(self).__name__
        for name in _FLAGS:
            setattr(self, name, check_flag(f"{owner}.{name}", getattr(self, name)))
        self.num_fiducials = check_integer(f"{owner}.num_fiducials", self.num_fiducials, 0)
        self.lookahead = check_integer(f"{owner}.lookahead", self.lookahead, 0)
        check_choice(f"{owner}.reward_reference", self.reward_reference, REWARD_REFERENCES)
        if self.reward_reference == "no_tension" and self.relative_reward:
            raise ConfigError(
                f"{owner}.relative_reward", "implied by reward_reference=no_tension; set it false"
            )
        if self.lookahead and not self.contour_features:
            raise ConfigError(f"{owner}.lookahead", "needs contour_features=true (the tip it looks ahead of)")
        check_number(f"{owner}.shaft_radius_mm", self.shaft_radius_mm, 0, unit="mm")
        self.shaft_radius_mm = plain(self.shaft_radius_mm)
        check_choice(f"{owner}.action_type", self.action_type, ACTION_TYPES)
        self.max_episode_steps = check_integer(
            f"{owner}.max_episode_steps", self.max_episode_steps, 1, optional=True, note="the whole cut"
        )
        names = self.randomize
        if not (isinstance(names, list | tuple) and all(isinstance(n, str) for n in names)):
            fail(f"{owner}.randomize", "a list of parameter names, e.g. ['gravity', 'noise_std']", names)
        unknown = [n for n in names if n not in RANDOMIZE_RANGES and n not in RANDOMIZE_ALIASES]
        if unknown:
            known = ", ".join([*RANDOMIZE_RANGES, *RANDOMIZE_ALIASES])
            raise ConfigError(f"{owner}.randomize", f"unknown parameter {unknown[0]!r}; choose from {known}")
        ranges = self.randomize_ranges
        if ranges is not None and not (
            isinstance(ranges, dict)
            and all(
                isinstance(k, str)
                and isinstance(v, list | tuple | np.ndarray)
                and len(v) == 2
                and all(is_number(x) and math.isfinite(float(x)) for x in v)
                and float(v[0]) <= float(v[1])
                for k, v in ranges.items()
            )
        ):
            fail(
                f"{owner}.randomize_ranges",
                "{parameter: [low, high]} of finite numbers, low <= high, or None",
                ranges,
            )


ENV_FIELDS = tuple(f.name for f in dataclasses.fields(EnvConfig))
"""The :class:`EnvConfig` fields, which :class:`PatternCutOptions` holds too."""


@dataclass
class PatternCutOptions(EnvConfig):
    """A pattern-cutting scenario (what is cut, where the grasp pinches, the physics) and how the policy sees
    and acts on it (the :class:`EnvConfig` fields).

    Physical parameters take one value for all envs or a list with one value per env (see
    :class:`~warpcut.sim.config.SimConfig`); ``None`` keeps ``sim_config``'s value.
    """

    contour: ContourSpec | Sequence[ContourSpec] = "fls-circle"
    """Contour to cut: a built-in name, a ``.json``/``.svg`` path, a generated contour's name
    (``gen-test-0-0003-open``), a ``Contour`` or its JSON object; or a list, one per env
    (:func:`warpcut.planning.resolve_contour` reads each)."""
    pinch_point: Sequence[float] | np.ndarray | None = None
    """Material point (mm) the tensioning arm pinches, ``(2,)`` or ``(B, 2)``. Default: each contour's
    centroid, or the feasible point nearest to it (:func:`warpcut.planning.default_pinch`)."""
    segments: Sequence[Sequence[Sequence[float]]] | Sequence[Sequence[Sequence[Sequence[float]]]] | None = (
        None
    )
    """Material polylines (mm) the scissors cut, in order (e.g. a plan's ``ordered_segments()``): one such
    list for every env, or a list of them, one per env; default: the whole contour as one segment
    (``warpcut.trajectory.default_segments``)."""
    sim_config: SimConfig = field(default_factory=SimConfig)
    """Base simulation parameters (a ``SimConfig``, or a dict of its fields); the fields below override it
    when given."""
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
    """Process noise per free vertex per update (mm), paper sigma."""
    device: str | None = None
    """Warp device of the simulator (``"cpu"``, ``"cuda"``); default: CUDA when available."""
    arm: ArmModel = ArmModel()
    """The cutting arm whose footprint the pinch point must avoid (:class:`~warpcut.planning.ArmModel`, or
    its JSON ``{radius_mm, length_mm}``); default: the paper's, along the whole sheet."""
    allow_infeasible_pinch: bool = False
    """Cut at a given ``pinch_point`` the gripper could not hold (on or near the cut line, under the cutting
    arm: :func:`warpcut.planning.pinch_problems`) instead of refusing it
    (:class:`~warpcut.planning.InfeasiblePinch`); the task's ``pinch_problems`` and the results of a run
    trained on it say so."""

    def __post_init__(self):
        owner = type(self).__name__
        # to_dict()'s output given back as keyword arguments (e.g. to gymnasium.make): its dicts read here
        self.arm = ArmModel.from_json(self.arm, f"{type(self).__name__}.arm")
        if not isinstance(self.allow_infeasible_pinch, bool):
            raise ValueError(
                f"{type(self).__name__}.allow_infeasible_pinch: must be true or false "
                f"(got {self.allow_infeasible_pinch!r:.80})"
            )
        if isinstance(self.sim_config, dict):
            self.sim_config = SimConfig.from_dict(self.sim_config, f"{owner}.sim_config")
        check_instance(
            f"{owner}.sim_config", self.sim_config, SimConfig, "a SimConfig, or a dict of its fields"
        )
        specs = self.contour if isinstance(self.contour, list | tuple) else [self.contour]
        if not (specs and all(isinstance(c, str | os.PathLike | Contour | dict) and c for c in specs)):
            fail(
                f"{owner}.contour",
                "a built-in name, a .json or .svg contour file, a Contour or its JSON object {name, closed, "
                "points}, or a list of them, one per env",
                self.contour,
            )
        if any(isinstance(c, dict) for c in specs):  # read now: a bad one is named as it is given
            read = [
                resolve_contour(c, self.sim_config, f"{owner}.contour") if isinstance(c, dict) else c
                for c in specs
            ]
            self.contour = read if isinstance(self.contour, list | tuple) else read[0]
        super().__post_init__()

    def _check_fields(self) -> None:
        super()._check_fields()
        owner = type(self).__name__
        if self.pinch_point is not None:
            _check_pinch_point(f"{owner}.pinch_point", self.pinch_point)
        if self.segments is not None and not isinstance(self.segments, list | tuple | np.ndarray):
            fail(
                f"{owner}.segments",
                "a list of polylines [[x_mm, y_mm], ...], or one such list per env, or None",
                self.segments,
            )
        if self.segments is not None:  # the polylines' shapes and values, now (their count per env later)
            try:
                segments_per_env(self.segments, len(self.segments))
            except ValueError as exc:
                if "paths for" not in str(exc):
                    raise ValueError(f"{owner}.{exc}") from None
        for name in SIM_OVERRIDES:
            if getattr(self, name) is not None:
                setattr(self, name, check_sim_field(f"{owner}.{name}", name, getattr(self, name)))
        check_text(f"{owner}.device", self.device, optional=True, note="the default device")

    @classmethod
    def env_settings(cls, options: PatternCutOptions) -> EnvConfig:
        """The :class:`EnvConfig` part of ``options``."""
        return EnvConfig(**{name: getattr(options, name) for name in ENV_FIELDS})

    @classmethod
    def build(cls, options: PatternCutOptions | None = None, **kwargs: Any) -> PatternCutOptions:
        """``options`` (default: all defaults) with the fields in ``kwargs`` replaced."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(kwargs) - names)
        if unknown:
            raise TypeError(f"unknown option(s) {', '.join(unknown)}; choose from {', '.join(sorted(names))}")
        if options is not None and not isinstance(options, cls):
            raise ValueError(
                f"options: expected PatternCutOptions (got {type(options).__name__}); pass its fields as "
                "keyword arguments, or read a dict with PatternCutOptions.from_dict"
            )
        built = dataclasses.replace(options or cls(), **kwargs)  # fields checked in __post_init__
        if any(name in SIM_OVERRIDES or name == "sim_config" for name in kwargs):
            built.config()  # the simulation settings, checked now (ConfigError names the field)
        return built

    def config(self) -> SimConfig:
        """``sim_config`` with the given overrides, validated."""
        changes = {k: getattr(self, k) for k in SIM_OVERRIDES if getattr(self, k) is not None}
        return self.sim_config.replace(**changes)

    def randomized(self) -> dict[str, tuple[float, float]]:
        """The randomised parameters with their ranges (``randomize``), checked: ``ValueError`` naming the
        field, the parameter and the fix."""
        return randomize_ranges(self.randomize, self.randomize_ranges)

    def nominal(self) -> PatternCutOptions:
        """These options without domain randomisation: the scenario a policy is evaluated on."""
        return dataclasses.replace(self, randomize=(), randomize_ranges=None)

    def part(self, first: int, count: int, total: int) -> PatternCutOptions:
        """The options of envs ``first .. first + count - 1`` of a batch of ``total``: their contours, pinch
        points, segments and per-env physical parameters (a ``PatternCutVecEnv(count, ..., part=(first,
        total))`` of them cuts as those envs of the whole batch)."""
        contours, pinch, segments = self.per_env(total)
        config, rows = self.config(), slice(first, first + count)
        physics = {}
        for name in PHYSICAL_PARAMETERS:
            values = np.asarray(getattr(config, name), dtype=np.float64)
            if values.ndim == 1 and values.size == total > 1:
                physics[name] = values[rows].tolist()
        return dataclasses.replace(
            self,
            contour=contours[rows],
            pinch_point=pinch[rows],
            segments=None if segments is None else segments[rows],
            sim_config=config.replace(**physics),
            **{name: None for name in SIM_OVERRIDES},  # in sim_config now
        )

    def contours(self, num_envs: int) -> list[Contour]:
        """One loaded contour per env."""
        single = isinstance(self.contour, str | os.PathLike | Contour)
        specs = [self.contour] if single else list(self.contour)
        if len(specs) not in (1, num_envs):
            raise ValueError(
                f"contour: got {len(specs)} for {num_envs} envs; give one contour or one per env"
            )
        config = self.config()
        loaded = [resolve_contour(c, config) for c in specs]
        return loaded * num_envs if len(loaded) == 1 else loaded

    def per_env(self, num_envs: int) -> tuple[list[Contour], np.ndarray, list[list[np.ndarray]] | None]:
        """Per env: the contour, the pinch point (B, 2) and the segments (None: each contour whole).

        A batch that could not fit in memory is refused first, before these per-env lists are made
        (:func:`~warpcut.sim.memory.check_batch_memory` on the sheets alone; the task checks the episode)."""
        config = self.config()
        check_batch_memory(num_envs, config.nx * config.ny)
        contours = self.contours(num_envs)
        if self.pinch_point is None:
            # Once per distinct contour (envs of one contour share its object): the grid search is slow.
            by_contour = {id(c): c for c in contours}
            found = {key: default_pinch(c, config, self.arm) for key, c in by_contour.items()}
            pinch = np.array([found[id(c)] for c in contours])
        else:
            pinch = np.broadcast_to(np.asarray(self.pinch_point, dtype=np.float64), (num_envs, 2)).copy()
        segments = None if self.segments is None else segments_per_env(self.segments, num_envs)
        if self.pinch_point is not None and not self.allow_infeasible_pinch:  # before any env is built
            judged = set()
            for env, contour in enumerate(contours):
                if (id(contour), pinch[env].tobytes()) not in judged:
                    judged.add((id(contour), pinch[env].tobytes()))
                    cut = None if segments is None else segments[env]
                    check_pinch(pinch[env], contour, config, cut, self.arm)
        return contours, pinch, segments

    def to_dict(self) -> dict[str, Any]:
        """The options as plain JSON values; :meth:`from_dict` reads them back. A built-in contour is given
        by its name; any other (a ``Contour``, or a contour file, read now) by itself: ``name``, ``closed``,
        ``points`` and ``sheet_size``, so the options do not depend on the file or the working directory."""
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "contour":
                value = (
                    [self._stored_contour(c) for c in value]
                    if isinstance(value, list | tuple)
                    else self._stored_contour(value)
                )
            elif f.name == "sim_config":
                value = dataclasses.asdict(value)
            elif f.name == "arm":
                value = value.to_json()
            out[f.name] = plain(value)
        return out

    def _stored_contour(self, contour: ContourSpec) -> str | dict:
        """A contour as :meth:`to_dict` stores it: a built-in's name, or else the contour itself (a file read,
        a generated one drawn, as :meth:`contours` resolves them)."""
        if not isinstance(contour, Contour):
            spec = os.fspath(contour)
            if spec in builtin_names():
                return spec
            contour = resolve_contour(spec, self.config())
        return {**contour.to_json(), "sheet_size": [float(v) for v in contour.sheet_size]}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PatternCutOptions:
        """Options from :meth:`to_dict`'s output (e.g. a run directory's ``options.json``).

        Raises:
            ValueError: ``data`` is not an object of the options' fields, or a field has the wrong type or an
                invalid value; the message starts with ``options: FIELD``.
        """
        if not isinstance(data, dict):
            raise ValueError(
                f"options: expected a JSON object of PatternCutOptions fields (got {type(data).__name__})"
            )
        check_known_fields("options", data, cls)
        try:
            options = cls(**data)
            options.config()  # the simulation settings, checked now
            options.randomized()
        except ValueError as exc:  # "PatternCutOptions.FIELD: ..." read as "options: FIELD: ..."
            message = str(exc).removeprefix(f"{cls.__name__}.")
            raise ValueError(message if message.startswith("options: ") else f"options: {message}") from None
        return options


def _check_pinch_point(where: str, value: Any) -> None:
    """``ConfigError`` naming ``where`` unless ``value`` is one finite point ``[x_mm, y_mm]`` or one per
    env: a NaN or infinite pinch point would silently mean "no grasp"."""
    numbers = isinstance(value, list | tuple | np.ndarray)
    try:
        points = np.asarray(value, dtype=np.float64) if numbers else None
    except (TypeError, ValueError):
        points = None
    flat = np.ravel(np.asarray(value, dtype=object)) if points is not None else ()
    if (
        points is None
        or points.ndim not in (1, 2)
        or points.shape[-1] != 2
        or not all(is_number(v) for v in flat)
        or not np.isfinite(points).all()
    ):
        fail(
            where, "a finite point [x_mm, y_mm] on the sheet, or one per env, or None for the default", value
        )


_FLAGS = ("resample_fiducials", "contour_features", "allow_z", "dense_reward", "relative_reward")


def plain(value: Any) -> Any:
    """``value`` as plain JSON values: NumPy arrays and scalars and tuples turned into lists and Python
    numbers."""
    if isinstance(value, np.ndarray | list | tuple):
        return [plain(v) for v in value]
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, np.generic):
        return value.item()
    return value


def segments_per_env(segments: Sequence, num_envs: int) -> list[list[np.ndarray]]:
    """``PatternCutOptions.segments`` as one list of (N, 2) polylines per env."""
    usage = "give a list of polylines, each at least 2 points [[x_mm, y_mm], ...], or one such list per env"

    def path(value: Sequence, where: str) -> list[np.ndarray]:
        try:
            polylines = [np.asarray(p, dtype=np.float64) for p in value]
        except (TypeError, ValueError) as error:
            raise ValueError(f"segments{where}: {usage} ({error})") from None
        bad = [p.ndim != 2 or p.shape[1] != 2 or len(p) < 2 or not np.isfinite(p).all() for p in polylines]
        if not polylines or any(bad):
            raise ValueError(f"segments{where}: {usage} (finite numbers)")
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
