"""What a pattern-cutting env cuts and how its policy sees and acts: :class:`PatternCutOptions`, the one
spec of a scenario that the envs, training (saved as a run directory's ``options.json``) and evaluation
share, and its policy-facing part :class:`EnvConfig` (observations, actions, reward, domain
randomisation), whose defaults are the default learner's."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warpcut.contours import Contour, builtin_names, contour_from_json, load_contour
from warpcut.fiducials import NUM_FIDUCIALS, SHAFT_RADIUS_MM
from warpcut.planning import default_pinch
from warpcut.sim.config import PHYSICAL_PARAMETERS, PerEnv, SimConfig, randomize_ranges

ContourSpec = str | os.PathLike | Contour
SIM_OVERRIDES = ("fixture", "resolution", "damping", "dt", "gravity", "elasticity", "noise_std")
"""The :class:`PatternCutOptions` fields that override ``sim_config``'s."""

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
        for f in dataclasses.fields(self):  # wrong types named here, not deep inside the env
            problem = _field_problem(f.name, getattr(self, f.name))
            if problem:
                raise ValueError(f"{f.name}: {problem} (got {getattr(self, f.name)!r:.80})")


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
    """Contour to cut: a built-in name, a ``.json``/``.svg`` path or a ``Contour``; or a list, one per env."""
    pinch_point: Sequence[float] | np.ndarray | None = None
    """Material point (mm) the tensioning arm pinches, ``(2,)`` or ``(B, 2)``. Default: each contour's
    centroid, or the feasible point nearest to it (:func:`warpcut.planning.default_pinch`)."""
    segments: Sequence[Sequence[Sequence[float]]] | Sequence[Sequence[Sequence[Sequence[float]]]] | None = (
        None
    )
    """Material polylines (mm) the scissors cut, in order (e.g. a plan's ``ordered_segments()``): one such
    list for every env, or a list of them, one per env; default: the whole contour as one segment
    (``warpcut.task.default_segments``)."""
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

    def __post_init__(self):
        # to_dict()'s output given back as keyword arguments (e.g. to gymnasium.make): its dicts read here
        if isinstance(self.sim_config, dict):
            self.sim_config = sim_config_from_dict(self.sim_config, "sim_config")
        if (
            isinstance(self.contour, dict)
            or isinstance(self.contour, list)
            and any(isinstance(c, dict) for c in self.contour)
        ):
            self.contour = _read_contours(self.contour, self.sim_config)
        super().__post_init__()
        if not isinstance(self.sim_config, SimConfig):
            raise ValueError(
                f"sim_config: give a SimConfig or a dict of its fields (got {self.sim_config!r:.80})"
            )

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

    def per_env(self, num_envs: int) -> tuple[list[Contour], np.ndarray, list[list[np.ndarray]] | None]:
        """Per env: the contour, the pinch point (B, 2) and the segments (None: each contour whole)."""
        contours = self.contours(num_envs)
        config = self.config()
        if self.pinch_point is None:
            # Once per distinct contour (envs of one contour share its object): the grid search is slow.
            by_contour = {id(c): c for c in contours}
            found = {key: default_pinch(c, config) for key, c in by_contour.items()}
            pinch = np.array([found[id(c)] for c in contours])
        else:
            pinch = np.broadcast_to(np.asarray(self.pinch_point, dtype=np.float64), (num_envs, 2)).copy()
        segments = None if self.segments is None else segments_per_env(self.segments, num_envs)
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
                    [_contour_spec(c) for c in value]
                    if isinstance(value, list | tuple)
                    else _contour_spec(value)
                )
            elif f.name == "sim_config":
                value = dataclasses.asdict(value)
            out[f.name] = plain(value)
        return out

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
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ValueError(
                f"options: unknown field(s) {', '.join(unknown)}; known: {', '.join(sorted(names))}"
            )
        fields = dict(data)
        for name, value in fields.items():
            problem = _field_problem(name, value)
            if problem:
                raise ValueError(f"options: {name}: {problem} (got {value!r:.80})")
        if isinstance(fields.get("sim_config"), dict):
            fields["sim_config"] = sim_config_from_dict(fields["sim_config"], "options: sim_config")
        if "contour" in fields:
            fields["contour"] = _read_contours(
                fields["contour"], fields.get("sim_config", SimConfig()), "options: "
            )
        try:
            options = cls(**fields)
            options.config()  # the simulation settings, checked now
            options.randomized()
        except (TypeError, ValueError) as exc:  # TypeError: a setting of the wrong type, e.g. "x" > 0
            message = str(exc)
            raise ValueError(message if message.startswith("options: ") else f"options: {message}") from None
        return options


def _read_contours(spec: Any, sim: SimConfig, prefix: str = "") -> Any:
    """The contours ``{name, closed, points[, sheet_size]}`` in ``spec`` (one, or a list) as ``Contour``s;
    names and files as they are."""

    def read(item: Any) -> Any:
        if not isinstance(item, dict):
            return item
        sheet = item.get("sheet_size", (sim.width_mm, sim.height_mm))
        if not (isinstance(sheet, list | tuple) and len(sheet) == 2 and all(_is_number(v) for v in sheet)):
            raise ValueError(f"{prefix}contour: sheet_size: give [width_mm, height_mm] (got {sheet!r})")
        return contour_from_json(item, f"{prefix}contour", tuple(float(v) for v in sheet))

    return [read(s) for s in spec] if isinstance(spec, list) else read(spec)


def sim_config_from_dict(data: dict[str, Any], where: str) -> SimConfig:
    """A :class:`SimConfig` from a dict of its fields (JSON lists back to the tuples it holds); ``ValueError``
    naming ``where`` and an unknown field."""
    known = {f.name for f in dataclasses.fields(SimConfig)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")
    return SimConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in data.items()})


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


def _is_count(value: Any, least: int) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool) and value >= least


_FLAGS = ("resample_fiducials", "contour_features", "allow_z", "dense_reward", "relative_reward")


def _field_problem(name: str, value: Any) -> str | None:
    """What is wrong with the JSON ``value`` of the options field ``name`` (None: nothing this checks; the
    env checks the values themselves)."""
    if name in _FLAGS and not isinstance(value, bool):
        return "must be true or false"
    if name == "contour":
        specs = value if isinstance(value, list) else [value]
        if not specs or not all(isinstance(c, str | dict | os.PathLike | Contour) and c for c in specs):
            return "give a built-in name, a contour file, a contour object {name, closed, points}, or a list"
    if name == "sim_config" and not isinstance(value, dict | SimConfig):
        return "give an object of SimConfig fields"
    if name == "action_type":
        if value not in ACTION_TYPES:
            return f"choose one of {', '.join(ACTION_TYPES)}"
    if name == "num_fiducials" and not _is_count(value, 0):
        return "must be a non-negative integer"
    if name == "max_episode_steps" and value is not None and not _is_count(value, 1):
        return "must be an integer >= 1, or null"
    if name == "shaft_radius_mm" and not (_is_number(value) and 0 <= value < np.inf):
        return "must be a finite number >= 0"
    lists = ("pinch_point", "segments")
    if name in lists and value is not None and not isinstance(value, list | tuple | np.ndarray):
        return "must be a list, or null"
    if name == "pinch_point" and value is not None:
        try:
            points = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            points = None
        if points is None or points.ndim not in (1, 2) or points.shape[-1] != 2:
            return "give [x_mm, y_mm], or one such pair per env"
        if not np.isfinite(points).all():
            return f"{points.tolist()} is not finite; give material coordinates (x, y) on the sheet (mm)"
    if name == "randomize" and not (
        isinstance(value, list | tuple) and all(isinstance(v, str) for v in value)
    ):
        return 'give a list of parameter names, e.g. ["gravity", "noise_std"]'
    if name == "randomize_ranges" and value is not None and not isinstance(value, dict):
        return "give {parameter: [low, high]}, or null"
    if name in ("fixture", "device") and value is not None and not isinstance(value, str):
        return "must be a string, or null"
    if name in PHYSICAL_PARAMETERS and value is not None:
        try:
            values = list(np.ravel(value)) if isinstance(value, list | tuple | np.ndarray) else [value]
        except ValueError:  # ragged
            values = []
        if not values or not all(_is_number(v) for v in values):
            return "give a number, or a list of one number per env, or null"
    return None


def _contour_spec(contour: ContourSpec) -> str | dict:
    """A contour as :meth:`PatternCutOptions.to_dict` stores it: a built-in's name, or else the contour
    itself (a file is read, as :meth:`PatternCutOptions.contours` reads it)."""
    if not isinstance(contour, Contour):
        spec = os.fspath(contour)
        if spec in builtin_names():
            return spec
        contour = load_contour(spec)
    return {**contour.to_json(), "sheet_size": [float(v) for v in contour.sheet_size]}


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
