"""Simulation parameters, with the paper's defaults and units.

Units are millimetres and seconds throughout. The sheet lies in the x-y plane at rest, z up, origin at
its lower-left corner. Every *physical* parameter (``damping``, ``dt``, ``gravity``, ``elasticity``,
``noise_std``) may be a single value shared by all envs or a sequence with one value per env: the
simulator reads it as ``param[env % len(param)]``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warpcut.validation import (
    ConfigError,
    check_choice,
    check_flag,
    check_integer,
    check_known_fields,
    check_number,
    check_numbers,
    fail,
    is_integer,
)

FIXTURES = ("corners", "rows")
SCORES = ("path", "separated")
SPRING_FAMILIES = ("structural", "shear", "bending")
PHYSICAL_PARAMETERS = ("damping", "dt", "gravity", "elasticity", "noise_std")

AUTHORS_UNITS_PER_MM = 4.8
"""The authors' canvas units per mm (their 480-unit sheet is 100 mm wide)."""
GRAVITY_MM_S2 = 521.0
"""The authors' f(t) = 2500 units/s^2 at 4.8 units/mm, rounded (mm/s^2): the default ``gravity``."""
AUTHORS_CUT_RADIUS_MM = 10.0 / AUTHORS_UNITS_PER_MM
"""The authors' cut radius, 10 canvas units (~2.08 mm)."""

ARM_RADIUS_MM = 4.0
"""Radius of the cutting arm's shaft (mm), for pinch feasibility. A da Vinci shaft is about 8 mm across."""
ARM_LENGTH_MM = math.inf
"""How far the cutting arm's footprint reaches from the scissor tip toward +x (mm), for pinch feasibility:
the paper's model, a cylinder along the whole sheet, by default. Then nothing inside a closed contour is
feasible: the grasp holds the sheet around the piece, never the piece (:func:`warpcut.planning.under_arm`).
A short footprint (e.g. 15 mm) lets the gripper hold the piece being cut (docs/results.md)."""
PINCH_CANDIDATES = 30
"""Pinch points a plan or a fixed-pinch search samples from the feasible region (the paper's N = 30)."""
SEGMENT_TOLERANCE_MM = 1.0
"""Default segmentation tolerance (mm): x reversals of a contour smaller than this are ignored
(:func:`warpcut.planning.segment_contour`)."""

Scalar = float | int
PerEnv = Scalar | Sequence[Scalar] | np.ndarray


DT_MAX_S = 1.0
"""Largest ``dt`` accepted (s): 60 times the paper's 0.016 s. The sheet falls ``gravity * dt**2`` per
update; beyond some mm per update the springs no longer hold it (see :data:`SETTLED_REACH_SHEETS`)."""
GRAVITY_MAX_MM_S2 = 1.0e5
"""Largest ``gravity`` accepted (mm/s^2), about 10 g (the default is the authors' 521 mm/s^2)."""
NOISE_STD_MAX_MM = 1.0
"""Largest ``noise_std`` accepted (mm per update): 33 times the default 0.03 mm, almost 4 times the top of the
Fig. 5 noise sweep (0.27 mm), a quarter of the default grid's spacing. Beyond it the sheet is noise, not
gauze, and its scores mean nothing."""
RUNAWAY_SHEETS = 10.0
"""A vertex farther than this many sheet sizes (``max(width_mm, height_mm)``, plus
``max_displacement_mm``) beyond the sheet's rest outline in x or y, or above it, has run away: its env
*diverged* (:class:`SimulationDiverged`), as has one with a non-finite coordinate. Material cut free may
fall any distance, so there is no bound below. The bound is generous (a noisy but sane sheet never comes
near it) because it marks blow-ups, not poor physics."""
SETTLED_REACH_SHEETS = 1.0
"""A settled (uncut, fixture-held) sheet with a vertex farther than this many sheet sizes from its rest
outline, in any direction, does not hang but falls through its springs: the settling diverged. (At the
default sweeps the sheet sags ~17 mm at the default gravity and dt, ~75 mm when ``gravity * dt**2`` is
5 mm, and more than its size beyond ~15 mm per update.)"""


class SimulationDiverged(ValueError):
    """A simulation left the physical range: non-finite vertex positions, or vertices flung far from the
    sheet (:data:`RUNAWAY_SHEETS`), usually from too much ``noise_std``, ``gravity`` or ``dt``. The message
    says where and which parameters to change. A ``ValueError`` (bad input), so the CLI reports it in one
    line."""


CHEBYSHEV_RHO_MAX = 0.99
"""Largest ``SimConfig.chebyshev_rho`` accepted (exclusive): the weights approach 2 and the sweeps diverge."""

CHEBYSHEV_ELASTICITY_MAX = 1.2
"""Largest ``elasticity`` accepted with Chebyshev sweeps (``chebyshev_rho > 0``): over-relaxed sweeps
(elasticity > 1) break the extrapolation's assumption. Measured on the default sheet: up to 1.2 it settles
as 20 plain sweeps do (sag 15.8 vs 15.9 mm at 1.2); at 1.35 the stretch reaches 38% (9 x 9: at 1.3 already),
at 1.4 174% (docs/physics.md, "Fewer sweeps")."""

CHEBYSHEV_RESIDUAL_MAX = 0.3
"""The largest Chebyshev residual factor ``1 / T_K(1 / rho)`` accepted (:func:`chebyshev_rho_limit`)."""

RESOLUTION_RANGE = (5, 100)
"""The vertices per sheet side a simulation may have (``SimConfig.resolution``), coarsest and finest."""


RANDOMIZE_RANGES: dict[str, tuple[float, float]] = {
    "gravity": (0.0, 2.0 * GRAVITY_MM_S2),
    "elasticity": (0.6, CHEBYSHEV_ELASTICITY_MAX),
    "noise_std": (0.0, 0.15),
    "damping": (0.97, 0.995),
}
"""Domain randomisation's default range of each parameter it can draw
(``envs.options.PatternCutOptions.randomize``), in the parameter's units: gravity from 0 to twice the
default (mm/s^2; the force study's sweep), elasticity up to the largest the default Chebyshev sweeps
accept, process noise up to five times the default (mm), and damping around the paper's 0.99."""
RANDOMIZE_ALIASES = {"noise": "noise_std"}
"""Short names ``--randomize`` accepts for a parameter."""
RANDOMIZE_LEVELS = 9
"""Levels a randomised parameter takes, evenly spaced over its range including both ends: a parameter that
shapes the settled sheet (all but noise) settles and lays out the trajectories once per level combination
met, so a finite set keeps every reset after the first few cheap."""


@dataclass
class SimConfig:
    """Everything that defines a batch of gauze sheets, the scissors and the grasp.

    Defaults follow Thananjeyan et al. (ICRA 2017) where the paper gives a value; see
    ``docs/physics.md`` for the mapping of each field to the paper's symbols (alpha, delta, tau, f(t)).
    """

    width_mm: float = 100.0
    """Sheet size along x (mm). FLS gauze is 10 cm x 10 cm."""
    height_mm: float = 100.0
    """Sheet size along y (mm)."""
    resolution: int | tuple[int, int] = 25
    """Vertices per side, ``n`` or ``(nx, ny)``; the paper uses 25 x 25 (625 vertices). 5 to 100."""

    damping: PerEnv = 0.99
    """Verlet velocity retention per update (paper alpha = 0.99). 1 = undamped, 0 = no momentum."""
    dt: PerEnv = 0.016
    """Update time step (s), in (0, 1]; gravity acts as ``gravity * dt**2`` per update."""
    gravity: PerEnv = GRAVITY_MM_S2
    """Downward (-z) acceleration (mm/s^2), in [0, 1e5]: the authors' 2500 units/s^2 at 4.8 units/mm
    (paper f(t))."""
    elasticity: PerEnv = 1.0
    """Fraction of a spring's length error corrected per relaxation sweep (paper tau = 1)."""
    noise_std: PerEnv = 0.03
    """Std. dev. of Gaussian process noise added to every free vertex per update (mm), paper sigma. The
    default makes seeded trials real samples (the authors' trials differed by their relaxation order; its
    calibration: docs/physics.md, "Process noise"); 0 is the noise-free protocol. Settling is always
    noise-free. Noise large enough to blow the sheet up (non-finite or runaway vertices) makes its env
    *diverge* (:data:`RUNAWAY_SHEETS`): flagged, never scored."""

    sweeps: int = 7
    """Gauss-Seidel relaxation sweeps per update, each relaxing every spring colour once. The paper used 5
    with structural springs and rows pinned; clipped corners need shear springs and the stiffness of ~20
    plain sweeps to hang like gauze, which 7 Chebyshev-accelerated sweeps reach (docs/physics.md)."""
    chebyshev_rho: float = 0.94
    """Chebyshev semi-iterative acceleration of the sweeps (Wang 2015, "A Chebyshev semi-iterative approach
    for accelerating projective and position-based dynamics"): the spectral radius ``rho`` assumed for one
    sweep, in [0, 1). After every sweep from the second on, each vertex is extrapolated to
    ``older + w_k * (swept - older)``, ``older`` being its position two sweeps before and ``w_k`` the
    Chebyshev weights (:func:`chebyshev_weights`). 0 turns it off: plain Gauss-Seidel, the paper's. The
    default reaches the sheet of 20 plain sweeps from far fewer (docs/physics.md, "Fewer sweeps")."""
    springs: tuple[str, ...] = ("structural", "shear")
    """Spring families: ``structural`` (grid edges), ``shear`` (cell diagonals), ``bending`` (two apart)."""
    fixture: str = "corners"
    """How the sheet is held: ``corners`` (four clips, the FLS task) or ``rows`` (top and bottom rows)."""
    first_order_z: bool = False
    """Move z without momentum, as the authors' code did (their sheet never settles). ``authors`` preset."""

    settle_updates: int = 200
    """Updates under gravity, without grasp or scissors, before the cut starts (paper: 200)."""
    updates_per_step: int = 2
    """Simulator updates per env step (one tensioning action per step; paper: 2)."""
    trajectory_spacing_mm: float = 1.0
    """Distance the scissor tip advances along the trajectory per update (mm)."""
    cut_radius_mm: float | None = None
    """Vertices within this distance (in x-y) of the scissor tip are cut. Default: one grid spacing."""
    cut_height_mm: float | None = None
    """...and within this vertical distance of the tip (mm), if given: material farther above or below is
    missed. Default ``None``: no limit, whatever lies under the tip in x-y is cut (the authors' code)."""
    grasp_radius_mm: float | None = None
    """Vertices within this distance of the pinch point are held by the gripper. Default: 1.6 spacings."""
    max_step_mm: float = 1.0
    """Largest grasp move per axis per env step (mm); actions are clipped to it (paper: 1 mm)."""
    max_displacement_mm: float = 10.0
    """Largest distance the grasp may be moved from where it pinched (mm); the displacement is clipped."""
    score: str = "path"
    """What ``error_*`` (tables, rewards) measures: ``path`` (paper: the region the scissors' path through
    the material encloses, against the intended one) or ``separated`` (the material that came free).
    Both are always computed (:class:`warpcut.scoring.Score`)."""

    @property
    def nx(self) -> int:
        return self.resolution if isinstance(self.resolution, int) else int(self.resolution[0])

    @property
    def ny(self) -> int:
        return self.resolution if isinstance(self.resolution, int) else int(self.resolution[1])

    @property
    def spacing_mm(self) -> tuple[float, float]:
        """Rest distance between neighbouring vertices along x and y (mm)."""
        return self.width_mm / (self.nx - 1), self.height_mm / (self.ny - 1)

    @property
    def cut_radius(self) -> float:
        return self.cut_radius_mm if self.cut_radius_mm is not None else max(self.spacing_mm)

    @property
    def cut_height(self) -> float:
        """``cut_height_mm`` as the kernels take it: infinite when there is no limit."""
        return math.inf if self.cut_height_mm is None else float(self.cut_height_mm)

    @property
    def grasp_radius(self) -> float:
        return self.grasp_radius_mm if self.grasp_radius_mm is not None else 1.6 * max(self.spacing_mm)

    @property
    def runaway_bounds(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """``(lower, upper)`` world corners (mm) of the box a vertex must stay in, or its env diverged
        (:data:`RUNAWAY_SHEETS`; no bound below: ``lower[2]`` is ``-inf``)."""
        reach = RUNAWAY_SHEETS * max(self.width_mm, self.height_mm) + self.max_displacement_mm
        return (-reach, -reach, -math.inf), (self.width_mm + reach, self.height_mm + reach, reach)

    def replace(self, **changes) -> SimConfig:
        """A copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes).validated()

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str) -> SimConfig:
        """A config from a dict of its fields (JSON lists back to the tuples it holds); ``ValueError``
        naming ``where`` and an unknown field, or ``where.FIELD`` and a bad value."""
        check_known_fields(where, data, cls)
        try:
            return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in data.items()})
        except ConfigError as error:
            raise error.renamed(f"{where}.{error.field}") from None

    @classmethod
    def authors(cls, **changes) -> SimConfig:
        """The authors' released setting, as their code runs it: rows pinned, structural springs, 5 sweeps,
        z moved without momentum, half the gravity step (their update applies ``g dt^2 / 2``, ours
        ``g dt^2``), a 2.08 mm cut radius (their 10 canvas units) and one update per trajectory point.

        It hangs the sheet as their code does (docs/physics.md, ``SimConfig.authors()``; checked by
        ``tests/test_simulator.py::test_authors_preset_reproduces_their_settled_sheet``). One departure
        remains: their cut removes only the cut vertex's own springs, so a cut vertex stays tied to its right
        and upper neighbours and is dragged along; here it is removed with all its springs.
        """
        base = dict(
            fixture="rows",
            springs=("structural",),
            sweeps=5,
            chebyshev_rho=0.0,
            first_order_z=True,
            gravity=GRAVITY_MM_S2 / 2,
            cut_radius_mm=AUTHORS_CUT_RADIUS_MM,
            updates_per_step=1,
        )
        base.update(changes)
        return cls(**base).validated()

    @property
    def sweep_weights(self) -> np.ndarray:
        """The Chebyshev weight applied after each sweep (float32, one per sweep; all 1 when off)."""
        return chebyshev_weights(self.sweeps, self.chebyshev_rho)

    def per_env(self, name: str, num_envs: int) -> np.ndarray:
        """The physical parameter ``name`` as a float32 array of length 1 or ``num_envs``."""
        values = np.atleast_1d(np.asarray(getattr(self, name), dtype=np.float64)).astype(np.float32)
        if values.ndim != 1 or values.size not in (1, num_envs):
            raise ConfigError(
                f"SimConfig.{name}",
                f"got {values.size} values for {num_envs} envs; give one value or one per env",
            )
        return values

    def __post_init__(self) -> None:
        self._check_fields()

    def _check_fields(self) -> None:
        """Check each field on its own (:func:`check_sim_field`), NumPy scalars and lists stored as Python
        numbers and tuples; what depends on several fields is :meth:`validated`'s."""
        for f in dataclasses.fields(self):
            setattr(self, f.name, check_sim_field(f"SimConfig.{f.name}", f.name, getattr(self, f.name)))

    def validated(self) -> SimConfig:
        """Itself, every field checked again (they may have been changed since) and the fields that depend
        on each other checked together; :class:`ConfigError` naming ``SimConfig.field`` and the fix."""
        self._check_fields()
        elasticity = np.asarray(self.elasticity, dtype=np.float32)  # (as the kernels read it)
        if self.chebyshev_rho > 0 and np.any(elasticity > np.float32(CHEBYSHEV_ELASTICITY_MAX)):
            raise ConfigError(
                "SimConfig.elasticity",
                f"above {CHEBYSHEV_ELASTICITY_MAX:g} the sweeps over-relax, and the Chebyshev extrapolation "
                f"on top of that (chebyshev_rho {self.chebyshev_rho:g}) breaks the sheet; keep elasticity <= "
                f"{CHEBYSHEV_ELASTICITY_MAX:g}, or set chebyshev_rho=0 (plain sweeps, elasticity up to 2) "
                "and raise sweeps",
            )
        if self.sweeps >= 2 and self.chebyshev_rho > chebyshev_rho_limit(self.sweeps):
            raise ConfigError(
                "SimConfig.chebyshev_rho",
                f"{self.chebyshev_rho:g} extrapolates too far for {self.sweeps} sweeps (the sheet would "
                f"oscillate and blow up); give at most {chebyshev_rho_limit(self.sweeps):.3f}, 0 (plain "
                "Gauss-Seidel), or more sweeps",
            )
        return self


def _positive_mm(where: str, value: Any, optional: bool = False, note: str = "") -> None:
    check_number(where, value, 0, low_open=True, unit="mm", optional=optional, note=note)


def _resolution(where: str, value: Any) -> int | tuple[int, int]:
    low, high = RESOLUTION_RANGE
    requirement = f"an integer in [{low}, {high}], or a pair (nx, ny) of them (the paper: 25)"
    if is_integer(value):
        if not low <= value <= high:
            fail(where, requirement, value)
        return int(value)
    pair = isinstance(value, list | tuple) or (isinstance(value, np.ndarray) and value.ndim == 1)
    if not (pair and len(value) == 2 and all(is_integer(n) and low <= n <= high for n in value)):
        fail(where, requirement, value)
    return (int(value[0]), int(value[1]))


def _springs(where: str, value: Any) -> tuple[str, ...]:
    families = ", ".join(repr(s) for s in SPRING_FAMILIES)
    ok = isinstance(value, list | tuple) and all(isinstance(s, str) and s in SPRING_FAMILIES for s in value)
    if not (ok and "structural" in value):
        fail(where, f"a list of spring families from {families}, including 'structural'", value)
    return tuple(value)


_FIELD_RULES: dict[str, Callable[[str, Any], Any]] = {
    "width_mm": _positive_mm,
    "height_mm": _positive_mm,
    "resolution": _resolution,
    "damping": lambda w, v: check_numbers(w, v, 0, 1, note="paper: 0.99"),
    "dt": lambda w, v: check_numbers(w, v, 0, DT_MAX_S, low_open=True, unit="s", note="paper: 0.016"),
    "gravity": lambda w, v: check_numbers(
        w, v, 0, GRAVITY_MAX_MM_S2, unit="mm/s^2", note=f"downward; default {GRAVITY_MM_S2:g}"
    ),
    "elasticity": lambda w, v: check_numbers(
        w, v, 0, 2, low_open=True, high_open=True, note="1 is plain Gauss-Seidel, above 1 over-relaxes"
    ),
    "noise_std": lambda w, v: check_numbers(
        w, v, 0, NOISE_STD_MAX_MM, unit="mm", note="per update; 0: no process noise, default 0.03"
    ),
    "sweeps": lambda w, v: check_integer(w, v, 1, 200),
    "chebyshev_rho": lambda w, v: check_number(
        w, v, 0, CHEBYSHEV_RHO_MAX, high_open=True, note="0 is plain Gauss-Seidel; default 0.94"
    ),
    "springs": _springs,
    "fixture": lambda w, v: check_choice(w, v, FIXTURES),
    "first_order_z": check_flag,
    "settle_updates": lambda w, v: check_integer(w, v, 0),
    "updates_per_step": lambda w, v: check_integer(w, v, 1),
    "trajectory_spacing_mm": _positive_mm,
    "cut_radius_mm": lambda w, v: _positive_mm(w, v, True, "one grid spacing"),
    "cut_height_mm": lambda w, v: _positive_mm(w, v, True, "no limit"),
    "grasp_radius_mm": lambda w, v: _positive_mm(w, v, True, "1.6 grid spacings"),
    "max_step_mm": _positive_mm,
    "max_displacement_mm": _positive_mm,
    "score": lambda w, v: check_choice(w, v, SCORES),
}
"""How each :class:`SimConfig` field is checked (:mod:`warpcut.validation`)."""


def check_sim_field(where: str, name: str, value: Any) -> Any:
    """``value`` checked as :class:`SimConfig`'s field ``name`` (whoever holds it: ``where`` names it in
    the error), as the config stores it: NumPy scalars as Python numbers, ``resolution`` and ``springs``
    as tuples. Raises :class:`ConfigError`."""
    normalised = _FIELD_RULES[name](where, value)
    if name in ("resolution", "springs"):
        return normalised
    return value.item() if isinstance(value, np.generic) else value


def chebyshev_weights(sweeps: int, rho: float) -> np.ndarray:
    """Chebyshev weights ``w_1 .. w_sweeps`` (float32) for spectral radius ``rho`` (Wang 2015, eq. 12 with
    the acceleration starting at the second sweep): ``w_1 = 1``, ``w_2 = 2 / (2 - rho^2)``,
    ``w_k = 4 / (4 - rho^2 w_(k-1))``. They rise from 1 toward ``2 / (1 + sqrt(1 - rho^2))``; ``rho = 0``
    gives all ones (no extrapolation). Every backend reads these float32 values, so all extrapolate alike."""
    weights = np.ones(sweeps, dtype=np.float64)
    r2 = float(rho) ** 2
    for k in range(1, sweeps):
        weights[k] = 2.0 / (2.0 - r2) if k == 1 else 4.0 / (4.0 - r2 * weights[k - 1])
    return weights.astype(np.float32)


def chebyshev_rho_limit(sweeps: int) -> float:
    """The largest stable ``chebyshev_rho`` for ``sweeps`` sweeps (< 1; any for one sweep, which is never
    extrapolated). After ``K`` sweeps the Chebyshev iteration leaves ``1 / T_K(1 / rho)`` of the error a
    plain sweep removes at once (``T_K``: the Chebyshev polynomial), with alternating sign, and the Verlet
    step carries it into the next update as velocity. On the default sheet every setting measured with that
    factor at or below 0.33 settled and every one at 0.38 or above blew up, whatever the resolution
    (docs/physics.md, "Fewer sweeps"): the limit keeps it at or below :data:`CHEBYSHEV_RESIDUAL_MAX`."""
    if sweeps < 2:
        return CHEBYSHEV_RHO_MAX
    return min(CHEBYSHEV_RHO_MAX, 1.0 / math.cosh(math.acosh(1.0 / CHEBYSHEV_RESIDUAL_MAX) / sweeps))


@dataclass
class SheetGrid:
    """The rest (material) layout of the vertices: ``v = row * nx + col``, at ``(col * hx, row * hy)``."""

    nx: int
    ny: int
    width_mm: float
    height_mm: float
    material: np.ndarray = field(init=False, repr=False)
    """(ny * nx, 2) rest positions (mm)."""

    def __post_init__(self) -> None:
        self.nx, self.ny = (
            check_integer(f"SheetGrid.{name}", getattr(self, name), 2) for name in ("nx", "ny")
        )
        for name in ("width_mm", "height_mm"):
            _positive_mm(f"SheetGrid.{name}", getattr(self, name))
        xs = np.linspace(0.0, self.width_mm, self.nx)
        ys = np.linspace(0.0, self.height_mm, self.ny)
        gx, gy = np.meshgrid(xs, ys)
        self.material = np.stack([gx.ravel(), gy.ravel()], axis=1)

    @classmethod
    def from_config(cls, config: SimConfig) -> SheetGrid:
        return cls(config.nx, config.ny, config.width_mm, config.height_mm)

    @property
    def num_vertices(self) -> int:
        return self.nx * self.ny

    @property
    def spacing_mm(self) -> tuple[float, float]:
        return self.width_mm / (self.nx - 1), self.height_mm / (self.ny - 1)

    @property
    def vertex_area_mm2(self) -> float:
        """Area each vertex stands for when regions are counted in vertices (mm^2)."""
        hx, hy = self.spacing_mm
        return hx * hy

    def fixture_mask(self, fixture: str) -> np.ndarray:
        """(ny * nx,) bool: vertices held by the fixture."""
        mask = np.zeros((self.ny, self.nx), dtype=bool)
        if fixture == "corners":
            mask[[0, 0, -1, -1], [0, -1, 0, -1]] = True
        elif fixture == "rows":
            mask[[0, -1], :] = True
        else:
            check_choice("SheetGrid.fixture_mask", fixture, FIXTURES)
        return mask.ravel()

    def disc_mask(self, center_mm: np.ndarray, radius_mm: float) -> np.ndarray:
        """(ny * nx,) bool: vertices whose rest position lies within ``radius_mm`` of ``center_mm``."""
        return (
            np.linalg.norm(self.material - np.asarray(center_mm, dtype=np.float64)[:2], axis=1) <= radius_mm
        )


def randomize_ranges(
    names: Sequence[str] | str, ranges: dict[str, Sequence[float]] | None = None
) -> dict[str, tuple[float, float]]:
    """Each parameter in ``names`` (a list, or comma-separated; aliases such as ``noise`` allowed) with its
    range: ``ranges``' if given, else :data:`RANDOMIZE_RANGES`'. ``ValueError`` names the field and the fix
    for an unknown parameter, a bad range, or a range given for a parameter not randomised."""
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    if not isinstance(names, list | tuple) or not all(isinstance(n, str) for n in names):
        raise ValueError(f"randomize: give a list of parameter names (got {names!r:.80})")
    known = ", ".join([*RANDOMIZE_RANGES, *RANDOMIZE_ALIASES])
    if not isinstance(ranges, dict | type(None)):
        raise ValueError(f"randomize_ranges: give {{parameter: [low, high]}} (got {ranges!r:.80})")
    chosen: dict[str, tuple[float, float]] = {}
    given = dict(ranges or {})
    for raw in names:
        name = RANDOMIZE_ALIASES.get(raw, raw)
        if name not in RANDOMIZE_RANGES:
            raise ValueError(f"randomize: unknown parameter {raw!r}; choose from {known}")
        value = given.pop(name, given.pop(raw, RANDOMIZE_RANGES[name]))
        try:
            low, high = (float(v) for v in value)
        except (TypeError, ValueError):
            raise ValueError(f"randomize_ranges: {name}: give [low, high] (got {value!r:.80})") from None
        if not (np.isfinite(low) and np.isfinite(high) and low <= high):
            raise ValueError(f"randomize_ranges: {name}: give finite low <= high (got [{low:g}, {high:g}])")
        try:  # each end must be a value SimConfig accepts
            SimConfig(**{name: low}).validated(), SimConfig(**{name: high}).validated()
        except ConfigError as error:
            raise ValueError(f"randomize_ranges: {name}: [{low:g}, {high:g}]: {error.requirement}") from None
        chosen[name] = (low, high)
    if given:
        raise ValueError(
            f"randomize_ranges: {', '.join(sorted(given))} not randomised; add it to randomize, or drop "
            "its range"
        )
    return chosen


def sample_parameters(
    rng: np.random.Generator, ranges: dict[str, tuple[float, float]], num_envs: int
) -> dict[str, np.ndarray]:
    """One draw of every randomised parameter per env: uniform over :data:`RANDOMIZE_LEVELS` levels of its
    range."""
    levels = RANDOMIZE_LEVELS
    return {
        name: low + (high - low) * rng.integers(levels, size=num_envs) / (levels - 1)
        for name, (low, high) in ranges.items()
    }
