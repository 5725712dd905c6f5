"""Pinch feasibility: where the gripper may hold the sheet while the scissors cut a contour.

Feasible pinch points (:func:`pinch_feasible`) keep the gripper clear of the sheet's edges, the corner clips,
the fixture, the contour, and the cutting arm sweeping the cut (:func:`under_arm`, :class:`ArmModel`). All
of it is judged on the rest sheet, in material coordinates (mm), ignoring how the sheet sags and moves
during the cut.

With the arm's footprint reaching all the way to +x (the default), the arm sweeps the whole inside of a
closed contour, so no point inside it is feasible: the piece being cut out cannot be held. A finite
:attr:`ArmModel.length_mm` models an arm that only collides near its tip.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import shapely

from warpcut.contours import Contour, ring
from warpcut.planning.segmentation import Segment
from warpcut.sim.config import ARM_LENGTH_MM, ARM_RADIUS_MM, RESOLUTION_RANGE, SheetGrid, SimConfig

CORNER_MARGIN_MM = 15.0
"""Pinch points stay this far from a corner clip (mm): the clip and the gripper would collide."""

FEASIBLE_GRID_MM = 0.5
"""Spacing of the grid of points :func:`nearest_feasible` searches (mm)."""


ScissorPath = np.ndarray | Segment | Sequence[np.ndarray | Segment]
"""The scissors' path: one (P, 2) polyline, a :class:`~warpcut.planning.segmentation.Segment`, or a sequence
of them (material mm)."""


@dataclass(frozen=True)
class ArmModel:
    """The cutting arm as the planner sees it from above.

    The arm approaches from +x: a cylinder of radius :attr:`radius_mm` from the scissor tip toward +x,
    reaching :attr:`length_mm` from the tip (``inf``: to the sheet's edge and beyond; a finite length models
    the part of an arm coming down at an angle that is low enough to collide).

    Raises:
        ValueError: naming the field, for a negative or NaN value or an infinite radius.
    """

    radius_mm: float = ARM_RADIUS_MM
    """Radius of the arm (mm), finite and >= 0."""
    length_mm: float = ARM_LENGTH_MM
    """How far the arm reaches from the tip toward +x (mm), >= 0; ``inf``: all the way."""

    def __post_init__(self) -> None:
        for name, allow_inf in (("radius_mm", False), ("length_mm", True)):
            value = getattr(self, name)
            number = isinstance(value, int | float | np.number) and not isinstance(value, bool)
            if not number or math.isnan(value) or value < 0 or (math.isinf(value) and not allow_inf):
                need = ">= 0 mm (inf: all the way)" if allow_inf else "finite and >= 0 mm"
                raise ValueError(f"arm.{name}: must be {need} (got {value!r})")
            object.__setattr__(self, name, float(value))

    def to_json(self) -> dict:
        """``{"radius_mm", "length_mm"}`` as JSON holds them (an infinite length as null)."""
        length = None if math.isinf(self.length_mm) else self.length_mm
        return {"radius_mm": self.radius_mm, "length_mm": length}

    @classmethod
    def from_json(cls, data: ArmModel | dict | None, where: str = "arm") -> ArmModel:
        """The arm :meth:`to_json` wrote (a null length: all the way), an ``ArmModel`` as it is, or None: the
        paper's.

        Raises:
            ValueError: naming ``where`` for anything else.
        """
        if data is None or isinstance(data, ArmModel):
            return data or cls()
        if not isinstance(data, dict) or set(data) - {"radius_mm", "length_mm"}:
            raise ValueError(
                f"{where}: give {{radius_mm, length_mm}} (mm; length null: all the way), got {data!r:.80}"
            )
        length = data.get("length_mm", ARM_LENGTH_MM)
        try:
            return cls(data.get("radius_mm", ARM_RADIUS_MM), math.inf if length is None else length)
        except ValueError as error:
            raise ValueError(f"{where}.{str(error).removeprefix('arm.')}") from None


def under_arm(points: np.ndarray, path: ScissorPath, arm: ArmModel = ArmModel()) -> np.ndarray:
    """Which material points lie under the cutting arm at some time while the scissors follow ``path``.

    Seen from above, the arm covers the points within ``arm.radius_mm`` of the stretch
    ``tip -> tip + (arm.length_mm, 0)`` (the rounded end covers the blades ahead of the tip). Swept over the
    path, it covers the points within ``arm.radius_mm`` of the union of those stretches: for each piece
    ``a -> b`` of the path, the parallelogram ``a, b, b + (L, 0), a + (L, 0)``. Only the cutting is swept,
    not the travel between segments, which depends on the order. Everything is in rest-sheet material
    coordinates (mm).

    Args:
        points: (M, 2) or (2,) material points (mm).
        path: The scissors' path (mm).
        arm: The cutting arm.

    Returns:
        (M,) bool: True under the arm.

    Raises:
        ValueError: for an ``arm`` that is not an :class:`ArmModel` or an empty or malformed ``path``.
    """
    if not isinstance(arm, ArmModel):
        raise ValueError(f"arm: expected an ArmModel, got {type(arm).__name__}")
    pts = material_points("points", points)
    lines = _polylines(path)
    # An infinite arm stops just past every point asked about: the same answer, a finite polygon.
    beyond = max(max(float(line[:, 0].max()) for line in lines), float(pts[:, 0].max(initial=0.0))) + 1.0
    quads = []
    for line in lines:
        if len(line) == 1:
            line = np.vstack([line, line])
        a, b = line[:-1], line[1:]
        far_a = np.column_stack([np.minimum(a[:, 0] + arm.length_mm, beyond), a[:, 1]])
        far_b = np.column_stack([np.minimum(b[:, 0] + arm.length_mm, beyond), b[:, 1]])
        quads.append(np.stack([a, b, far_b, far_a], axis=1))
    quads = np.concatenate(quads)
    hulls = shapely.convex_hull(
        shapely.multipoints(quads.reshape(-1, 2), indices=np.repeat(np.arange(len(quads)), 4))
    )  # a degenerate (horizontal) piece's hull is a line, which still counts
    footprint = shapely.union_all(hulls)
    shapely.prepare(footprint)
    return shapely.dwithin(footprint, shapely.points(pts), arm.radius_mm)


def pinch_rules(
    points: np.ndarray,
    contour: Contour,
    config: SimConfig,
    segments: ScissorPath | None = None,
    arm: ArmModel = ArmModel(),
) -> dict[str, np.ndarray]:
    """Each feasibility rule for material points (M, 2) as a (M,) bool mask, True where it holds.

    Rules: ``edges`` (at least one grasp radius inside the sheet), ``corners`` (at least
    :data:`CORNER_MARGIN_MM` from a corner), ``fixture`` (more than a grasp radius from every fixture
    vertex), ``contour`` (the gripped disc never reaches the scissors' cut: at least grasp radius + cut
    radius from the contour) and ``arm`` (not :func:`under_arm` while the scissors follow ``segments``;
    default: the whole contour, which the arm sweeps the same way however it is split or wherever it
    starts).
    """
    points = material_points("points", points)
    w, h = config.width_mm, config.height_mm
    edge = config.grasp_radius
    x, y = points[:, 0], points[:, 1]
    rules = {"edges": (x >= edge) & (x <= w - edge) & (y >= edge) & (y <= h - edge)}
    corners = np.array([[0.0, 0.0], [w, 0.0], [0.0, h], [w, h]])
    rules["corners"] = _min_distance(points, corners) >= CORNER_MARGIN_MM
    grid = SheetGrid.from_config(config)
    rules["fixture"] = _min_distance(points, grid.material[grid.fixture_mask(config.fixture)]) > edge
    line = shapely.LinearRing(contour.points) if contour.closed else shapely.LineString(contour.points)
    rules["contour"] = shapely.distance(shapely.points(points), line) >= edge + config.cut_radius
    path = segments if segments is not None else ring(np.asarray(contour.points), contour.closed)
    rules["arm"] = ~under_arm(points, path, arm)
    return rules


def pinch_feasible(
    points: np.ndarray,
    contour: Contour,
    config: SimConfig,
    segments: ScissorPath | None = None,
    arm: ArmModel = ArmModel(),
) -> np.ndarray:
    """Which material points (M, 2) (mm) are feasible pinch points for cutting ``contour``.

    Feasible = every rule of :func:`pinch_rules` holds: on the sheet at least one grasp radius from its
    edges, at least :data:`CORNER_MARGIN_MM` from the corners, not on fixture vertices, far enough from the
    contour that the gripped disc never reaches the scissors' cut (grasp radius + cut radius), and not under
    the cutting ``arm`` while it cuts ``segments`` (default: the whole contour).

    Returns:
        (M,) bool.
    """
    rules = pinch_rules(points, contour, config, segments, arm)
    return np.logical_and.reduce(list(rules.values()))


ALLOW_INFEASIBLE = (
    "allow_infeasible_pinch=True (CLI: --set allow_infeasible_pinch=true) runs it anyway, its results marked "
    "infeasible"
)
"""How to run an infeasible pinch point all the same, as the refusal says it."""


class InfeasiblePinch(ValueError):
    """A pinch point the gripper cannot hold (:func:`pinch_problems`), refused: the message names the rule it
    breaks and the fix, in one line.

    Attributes:
        point: The pinch point (mm).
        problem: The rule it breaks, in words (:func:`pinch_problems`).
    """

    def __init__(self, point: np.ndarray, contour: Contour, problem: str, fix: str | None = None):
        self.point = np.asarray(point, dtype=np.float64)
        self.problem = problem
        x, y = (float(v) for v in self.point)
        if _SETTING_FORM.get() is None:  # from Python: both forms, as ALLOW_INFEASIBLE says them
            omit, allow = " (--pinch)", ALLOW_INFEASIBLE
        else:  # a command's: only what it has
            flag = (_given("pinch", "X,Y") or "").split(" ")[0]
            omit = f" ({flag})" if flag.startswith("--") and flag != "--set" else ""
            allow = _given("allow_infeasible_pinch", "true")
            allow = allow and f"{allow} runs it anyway, its results marked infeasible"
        fix = fix or (
            f"omit it{omit} for the default pinch point, feasible by construction, or choose a point clear "
            "of the cut and of the arm ('warpcut plan' lists feasible candidates)"
        )
        super().__init__(
            f"pinch point ({x:.1f}, {y:.1f}) mm is not a feasible grasp for {contour.name}: {problem}; "
            f"{fix}" + (f"; {allow}" if allow else "")
        )


def pinch_problems(
    points: np.ndarray,
    contour: Contour,
    config: SimConfig,
    segments: ScissorPath | None = None,
    arm: ArmModel = ArmModel(),
) -> list[str | None]:
    """Why the gripper cannot hold the sheet at each material point (M, 2) (mm): one line naming every rule
    of :func:`pinch_rules` it breaks, with the figures that decide it, or None where it is feasible
    (:func:`pinch_feasible`)."""
    points = material_points("points", points)
    rules = pinch_rules(points, contour, config, segments, arm)
    w, h, grasp, cut = config.width_mm, config.height_mm, config.grasp_radius, config.cut_radius
    line = shapely.LinearRing(contour.points) if contour.closed else shapely.LineString(contour.points)
    distance = shapely.distance(shapely.points(points), line)
    reach = "to the sheet's edge" if math.isinf(arm.length_mm) else f"for {arm.length_mm:g} mm"
    problems: list[str | None] = []
    for k, (x, y) in enumerate(points):
        broken = []
        if not rules["edges"][k]:
            on_sheet = 0.0 <= x <= w and 0.0 <= y <= h
            broken.append(
                f"closer to the sheet's edge than the grasp radius ({grasp:.1f} mm)"
                if on_sheet
                else f"lies off the {w:g} x {h:g} mm sheet"
            )
        if not rules["corners"][k]:
            broken.append(f"within {CORNER_MARGIN_MM:g} mm of a corner clip")
        if not rules["fixture"][k]:
            broken.append(f"on the fixture (within the grasp radius, {grasp:.1f} mm, of a held vertex)")
        if not rules["contour"][k]:
            where = "on the cut line" if distance[k] < cut else "too near the cut line"
            broken.append(
                f"{where} ({distance[k]:.1f} mm from the contour, nearer than the grasp radius plus the cut "
                f"radius, {grasp:.1f} + {cut:.1f} mm: the scissors would cut into the gripped disc)"
            )
        if not rules["arm"][k]:
            broken.append(
                f"under the cutting arm (its footprint, {arm.radius_mm:g} mm wide either side, reaches from "
                f"the scissor tip toward +x {reach} and sweeps over it during the cut)"
            )
        problems.append("; ".join(broken) or None)
    return problems


def pinch_problems_per_env(
    points: np.ndarray,
    contours: Sequence[Contour],
    segments: Sequence[ScissorPath],
    config: SimConfig,
    arm: ArmModel | None = None,
) -> list[str | None]:
    """Each env's pinch problem (:func:`pinch_problems` with its own contour and segments) for a batch's
    (B, 2) pinch ``points`` (a row of NaN: no grasp, no problem), judged once per distinct contour, cut (in
    any order: the arm sweeps the same footprint) and point."""
    arm = ArmModel() if arm is None else arm
    groups: dict[tuple, list[int]] = {}
    for env in np.flatnonzero(np.all(np.isfinite(points), axis=1)):
        cut = frozenset(np.ascontiguousarray(p, dtype=np.float64).tobytes() for p in segments[env])
        groups.setdefault((id(contours[env]), cut), []).append(int(env))
    problems: list[str | None] = [None] * len(points)
    for envs in groups.values():
        distinct, which = np.unique(points[envs], axis=0, return_inverse=True)
        found = pinch_problems(distinct, contours[envs[0]], config, segments[envs[0]], arm)
        for env, k in zip(envs, which.reshape(-1), strict=True):
            problems[env] = found[k]
    return problems


def check_pinch(
    point: np.ndarray,
    contour: Contour,
    config: SimConfig,
    segments: ScissorPath | None = None,
    arm: ArmModel = ArmModel(),
    *,
    allow: bool = False,
    fix: str | None = None,
) -> str | None:
    """Why ``point`` (2,) is not a feasible pinch point (:func:`pinch_problems`), or None where it is.

    Raises:
        InfeasiblePinch: an infeasible ``point`` unless ``allow``: the rule it breaks, ``fix`` (default:
            omit the point, or choose a feasible one) and how to allow it.
    """
    problem = pinch_problems(point, contour, config, segments, arm)[0]
    if problem is not None and not allow:
        raise InfeasiblePinch(point, contour, problem, fix)
    return problem


def nearest_feasible(
    point: np.ndarray,
    contour: Contour,
    config: SimConfig,
    segments: ScissorPath | None = None,
    arm: ArmModel = ArmModel(),
) -> np.ndarray:
    """``point`` itself if it is feasible (:func:`pinch_feasible`), else the nearest feasible point of a
    grid :data:`FEASIBLE_GRID_MM` apart over the sheet.

    Raises:
        ValueError: naming the contour when no point is feasible.
    """
    point = np.asarray(point, dtype=np.float64)
    if pinch_feasible(point, contour, config, segments, arm)[0]:
        return point
    grid = _sheet_points(config)
    grid = grid[pinch_feasible(grid, contour, config, segments, arm)]
    if not len(grid):
        raise no_pinch_error(contour, config, segments, arm)
    return grid[np.argmin(np.linalg.norm(grid - point, axis=1))]


_SETTING_FORM: contextvars.ContextVar[Callable[[str, str], str | None] | None] = contextvars.ContextVar(
    "setting_form", default=None
)
"""How the caller gives a setting (a command: its flag, or ``--set KEY=VALUE``), for advice in errors."""


@contextlib.contextmanager
def setting_forms(form: Callable[[str, str], str | None]) -> Iterator[None]:
    """Inside the block, advice names a setting (``sim.resolution``, ``arm.radius_mm``, ``pinch``,
    ``allow_infeasible_pinch``) as ``form(key, value)`` says it is given (e.g. ``--resolution 12``, ``--set
    sim.resolution=12``), or leaves it out where ``form`` returns None (the caller has no such setting)."""
    token = _SETTING_FORM.set(form)
    try:
        yield
    finally:
        _SETTING_FORM.reset(token)


def _given(key: str, value: str) -> str | None:
    """The setting ``key`` with ``value`` as the caller gives it (:func:`setting_forms`; by default
    ``key=value``), or None where the caller has no such setting."""
    form = _SETTING_FORM.get()
    return f"{key}={value}" if form is None else form(key, value)


def _own_pinch() -> str:
    """The advice to pinch a point of the user's choosing, where the caller can, else nothing."""
    pinch, allow = _given("pinch", "X,Y"), _given("allow_infeasible_pinch", "true")
    return f", or pinch an infeasible point of your choosing ({pinch} {allow})" if pinch and allow else ""


def no_pinch_error(
    contour: Contour,
    config: SimConfig,
    segments: ScissorPath | None = None,
    arm: ArmModel = ArmModel(),
) -> ValueError:
    """The error for a contour that leaves no feasible pinch point (:func:`pinch_feasible`), naming the cause.

    The grasp radius and the cut radius default to multiples of the grid spacing, so on a coarse grid they
    can cover the whole sheet whatever the contour: when a finer grid would leave a feasible point, the
    error blames ``config.resolution`` and names the coarsest square resolution that works (searched by
    bisection, a few feasibility maps); otherwise it blames the contour and the arm.
    """

    def pinchable(grid: SimConfig) -> bool:
        return bool(pinch_feasible(_sheet_points(grid), contour, grid, segments, arm).any())

    def square(resolution: int) -> SimConfig:
        return config.replace(resolution=resolution)

    coarse = min(config.nx, config.ny)  # no coarser than the grid given along either side
    if pinchable(config):  # rejection sampling missed a feasible region this small
        pinch = _given("pinch", "X,Y")
        return ValueError(
            f"contour {contour.name!r}: the feasible pinch region is too small to sample candidates "
            "from; "
            + (f"give a pinch point explicitly ({pinch}), or " if pinch else "")
            + "move the contour "
            "to leave the gripper room"
        )
    if coarse < RESOLUTION_RANGE[1] and pinchable(square(RESOLUTION_RANGE[1])):
        lo, hi = coarse, RESOLUTION_RANGE[1]  # pinchable at hi, not at lo (or so the search assumes)
        while hi - lo > 1:
            mid = (lo + hi) // 2
            lo, hi = (lo, mid) if pinchable(square(mid)) else (mid, hi)
        spacing = max(config.spacing_mm)
        finer = _given("sim.resolution", str(hi))
        return ValueError(
            f"resolution: {config.resolution!r} is too coarse to pinch the sheet for contour "
            f"{contour.name!r}: with {spacing:.3g} mm between vertices, the grasp radius "
            f"({config.grasp_radius:.3g} mm) and the cut radius ({config.cut_radius:.3g} mm) leave no point "
            "clear of the sheet's edges, corners, fixture and the contour, nor under the cutting arm; use "
            f"resolution {hi} or finer" + (f" ({finer})" if finer else "") + _own_pinch()
        )
    points = _sheet_points(config)
    rules = pinch_rules(points, contour, config, segments, arm)
    if not (
        rules["edges"] & rules["corners"] & rules["fixture"]
    ).any():  # the sheet alone: no contour, no arm
        larger = [g for g in (_given("sim.width_mm", "W"), _given("sim.height_mm", "H")) if g]
        return ValueError(
            f"sheet: {config.width_mm:g} x {config.height_mm:g} mm is too small to grasp: no point of it is "
            f"a grasp radius ({config.grasp_radius:.3g} mm) inside its edges and fixture and "
            f"{CORNER_MARGIN_MM:g} mm from its corners, whatever the contour and the arm; use a larger sheet"
            + (f" ({' '.join(larger)})" if larger else "")
            + _own_pinch()
        )
    thinner = [g for g in (_given("arm.radius_mm", "R"), _given("arm.length_mm", "L")) if g]
    return ValueError(
        f"contour {contour.name!r}: no feasible pinch point on the sheet: no point is clear of its "
        f"edges, corners, fixture and the contour, nor under the cutting arm (arm.radius_mm "
        f"{arm.radius_mm:g}); "
        + (f"use a thinner arm or a shorter footprint ({' or '.join(thinner)}), " if thinner else "")
        + "move the contour to leave the gripper room"
        + _own_pinch()
    )


def default_pinch(
    contour: Contour,
    config: SimConfig,
    arm: ArmModel = ArmModel(),
    *,
    segments: ScissorPath | None = None,
) -> np.ndarray:
    """The default pinch point: the contour's centroid, or the feasible point nearest to it
    (:func:`nearest_feasible`) when the gripper cannot hold it there (under the cutting arm, on the cut
    line, ...).

    Args:
        segments: The cut the arm sweeps (default: the whole contour, the same footprint however it is
            split).

    Raises:
        ValueError: naming the contour when no point is feasible.
    """
    return nearest_feasible(contour.centroid, contour, config, segments, arm)


def material_points(name: str, points: np.ndarray) -> np.ndarray:
    """``points`` as an (M, 2) float array of material points; a single (2,) point becomes (1, 2).

    Raises:
        ValueError: naming the argument ``name`` for any other shape.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape == (2,):
        pts = pts[None]
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"{name}: expected (M, 2) or (2,) material points (mm), got shape {pts.shape}")
    return pts


def _sheet_points(config: SimConfig) -> np.ndarray:
    """(M, 2) points of a grid :data:`FEASIBLE_GRID_MM` apart over the sheet (mm), the pinch points tried."""
    xs = np.arange(0.0, config.width_mm + 1e-9, FEASIBLE_GRID_MM)
    ys = np.arange(0.0, config.height_mm + 1e-9, FEASIBLE_GRID_MM)
    return np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)


def _polylines(path: ScissorPath) -> list[np.ndarray]:
    """``path`` as a list of (P, 2) float arrays."""
    items = [path] if isinstance(path, Segment) or (isinstance(path, np.ndarray) and path.ndim == 2) else path
    lines = [np.asarray(p.points if isinstance(p, Segment) else p, dtype=np.float64) for p in items]
    if not lines or any(line.ndim != 2 or line.shape[1] != 2 or len(line) == 0 for line in lines):
        raise ValueError("path: expected a (P, 2) polyline (mm), a Segment, or a non-empty list of them")
    return lines


def _min_distance(points: np.ndarray, others: np.ndarray) -> np.ndarray:
    if not len(others):
        return np.full(len(points), np.inf)
    return np.min(np.linalg.norm(points[:, None] - others[None], axis=2), axis=1)
