"""What a pattern-cutting env cuts and how its policy sees and acts: :class:`PatternCutOptions`, the one
spec of a scenario that the envs, training (saved as a run directory's ``options.json``) and evaluation
share."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warpcut.contours import Contour, contour_from_json, load_contour
from warpcut.fiducials import NUM_FIDUCIALS, SHAFT_RADIUS_MM
from warpcut.planning import default_pinch
from warpcut.sim.config import PerEnv, SimConfig
from warpcut.task import default_segments

ContourSpec = str | os.PathLike | Contour
SIM_OVERRIDES = ("fixture", "resolution", "damping", "dt", "gravity", "elasticity", "noise_std")
"""The :class:`PatternCutOptions` fields that override ``sim_config``'s."""


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
    centroid, or the feasible point nearest to it (:func:`warpcut.planning.default_pinch`)."""
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
    residual_gain: float = 0.0
    """Add the analytic controller's move to every action: ``-residual_gain`` times the tracking error in
    x-y (mm per mm, per step; the paper's analytic gain is 0.048), so the policy learns a residual on it
    and its "stay" action is analytic control. 0: off (the policy's moves alone)."""
    dense_reward: bool = False
    """Add the per-step cut-deviation penalty (the path score's increment) to the sparse final reward."""
    max_episode_steps: int | None = None
    """Truncate episodes after this many steps; default: the whole cut."""
    candidates: Sequence[dict] | None = None
    """Several pinch candidates for one policy shared across them, each ``{"pinch": [x, y], "segments":
    polylines or None}`` (a plan's candidate with its best order): env ``i`` pinches candidate ``i % K`` and
    cuts its segments (None: the whole contour). ``pinch_point`` and ``segments`` must then be None, and the
    pinch point is observed (``observe_pinch``). :meth:`at_candidate` is the options of one candidate."""

    def __post_init__(self):
        if self.candidates is None:
            return
        if not self.candidates or any(not isinstance(c, dict) or "pinch" not in c for c in self.candidates):
            raise ValueError('candidates: give a non-empty list of {"pinch": [x, y], "segments": ...}')
        if self.pinch_point is not None or self.segments is not None:
            raise ValueError(
                "candidates: leave pinch_point and segments None; each candidate carries its own"
            )
        self.observe_pinch = True

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

    def at_candidate(self, k: int) -> PatternCutOptions:
        """The single-pinch options of candidate ``k`` (its pinch observed, as the shared policy expects)."""
        if self.candidates is None:
            raise ValueError("at_candidate: these options have no candidates")
        if not 0 <= k < len(self.candidates):
            raise ValueError(f"candidate: {k} is not in 0..{len(self.candidates) - 1}")
        c = self.candidates[k]
        pinch = [float(v) for v in c["pinch"]]
        return dataclasses.replace(self, candidates=None, pinch_point=pinch, segments=c.get("segments"))

    def per_env(self, num_envs: int) -> tuple[list[Contour], np.ndarray, list[list[np.ndarray]] | None]:
        """Per env: the contour, the pinch point (B, 2) and the segments (None: each contour whole)."""
        contours = self.contours(num_envs)
        config = self.config()
        if self.candidates is not None:  # env i: candidate i % K
            picks = [self.candidates[i % len(self.candidates)] for i in range(num_envs)]
            pinch = np.array([c["pinch"] for c in picks], dtype=np.float64)
            segments = [
                segments_per_env(c["segments"], 1)[0] if c.get("segments") else default_segments(contour)
                for c, contour in zip(picks, contours, strict=True)
            ]
            return contours, pinch, segments
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
        """The options as plain JSON values; :meth:`from_dict` reads them back. Contours are given by their
        name or file path, a :class:`Contour` object by its points."""
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
            out[f.name] = _plain(value)
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PatternCutOptions:
        """Options from :meth:`to_dict`'s output (e.g. a run directory's ``options.json``)."""
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
        if "sim_config" in fields:
            sim = fields["sim_config"]
            if isinstance(sim, dict):  # JSON lists back to the tuples SimConfig holds
                sim = SimConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in sim.items()})
            fields["sim_config"] = sim
        sim = fields.get("sim_config", SimConfig())
        sheet = (sim.width_mm, sim.height_mm)

        def contour(spec):
            return contour_from_json(spec, "options: contour", sheet) if isinstance(spec, dict) else spec

        if "contour" in fields:
            c = fields["contour"]
            fields["contour"] = [contour(s) for s in c] if isinstance(c, list) else contour(c)
        return cls(**fields)


def _contour_spec(contour: ContourSpec) -> str | dict:
    """A contour as :meth:`PatternCutOptions.to_dict` stores it: its name or path, or its points."""
    return contour.to_json() if isinstance(contour, Contour) else os.fspath(contour)


def _plain(value: Any) -> Any:
    """``value`` with NumPy arrays and scalars and tuples turned into lists and Python numbers."""
    if isinstance(value, np.ndarray | list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
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
