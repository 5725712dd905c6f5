"""Cut planning, the paper's Fig. 2 pipeline up to the policy (Section V): segments, pinch candidates, order.

:func:`plan_cut` runs it for one contour:

1. split the contour into segments the cutting arm can cut (:func:`warpcut.planning.segmentation.segment_contour`);
2. sample candidate pinch points uniformly from the feasible region, plus the contour's centroid when it is
   feasible (:func:`pinch_candidates`, Problem 2a);
3. simulate every (candidate, cutting order) pair with fixed tension, all of them as one
   :class:`~warpcut.task.CuttingTask` batch, and keep the order and the pinch point with the lowest error
   (:func:`search_orders`, the paper's ``exhaustive_search``, Problem 1).

Feasible pinch points (:func:`pinch_feasible`) keep the gripper clear of the sheet's edges, the corner clips,
the fixture, the contour, and, given the segments, the cutting arm (:func:`under_arm`). All of it is planned
on the rest sheet, in material coordinates (mm), ignoring how the sheet sags and moves during the cut.

With the arm's footprint reaching all the way to +x (the default, :data:`ARM_LENGTH_MM`), the arm sweeps the
whole inside of a closed contour, so every candidate lies outside it: the piece being cut out cannot be
held. Pass a finite ``arm_length_mm`` to model an arm that only collides near its tip.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely

from warpcut.contours import Contour
from warpcut.planning.segmentation import Segment, segment_contour, segment_orders
from warpcut.sim.config import ARM_LENGTH_MM, ARM_RADIUS_MM, SheetGrid, SimConfig
from warpcut.task import CuttingTask, default_segments

CORNER_MARGIN_MM = 15.0
"""Pinch points stay this far from a corner clip (mm): the clip and the gripper would collide."""

ORDER_LIMIT = 6
"""Up to this many segments every order is simulated (K! of them); beyond it a heuristic list."""

Path = np.ndarray | Segment | Sequence[np.ndarray | Segment]


def under_arm(
    points: np.ndarray, path: Path, radius_mm: float = ARM_RADIUS_MM, length_mm: float = ARM_LENGTH_MM
) -> np.ndarray:
    """Which material points lie under the cutting arm at some time while the scissors follow ``path``.

    The arm approaches from +x: it is a cylinder of radius ``radius_mm`` from the scissor tip toward +x
    (to the sheet's edge and beyond by default; ``length_mm`` shortens it, e.g. to the part of an arm
    that comes down at an angle which is low enough to collide). Seen from above, it covers the points
    within ``radius_mm`` of the stretch ``tip -> tip + (length_mm, 0)`` (the rounded end covers the blades
    ahead of the tip). Swept over the path, it covers the points within ``radius_mm`` of the union of those
    stretches: for each piece ``a -> b`` of the path, the parallelogram ``a, b, b + (L, 0), a + (L, 0)``.
    Only the cutting is swept, not the travel between segments, which depends on the order. Everything is
    in rest-sheet material coordinates (mm).

    Args:
        points: (M, 2) or (2,) material points (mm).
        path: The scissors' path: one (P, 2) polyline, a :class:`~warpcut.planning.segmentation.Segment`, or a
            sequence of them (mm).
        radius_mm: The arm's radius (mm), >= 0.
        length_mm: How far the arm reaches from the tip toward +x (mm), >= 0; ``inf``: all the way.

    Returns:
        (M,) bool: True under the arm.

    Raises:
        ValueError: for a negative or NaN ``radius_mm``/``length_mm`` or an empty or malformed ``path``.
    """
    radius = _mm("radius_mm", radius_mm)
    length = _mm("length_mm", length_mm, allow_inf=True)
    pts = _points("points", points)
    lines = _polylines(path)
    # An infinite arm stops just past every point asked about: the same answer, a finite polygon.
    beyond = max(max(float(line[:, 0].max()) for line in lines), float(pts[:, 0].max(initial=0.0))) + 1.0
    quads = []
    for line in lines:
        if len(line) == 1:
            line = np.vstack([line, line])
        a, b = line[:-1], line[1:]
        far_a = np.column_stack([np.minimum(a[:, 0] + length, beyond), a[:, 1]])
        far_b = np.column_stack([np.minimum(b[:, 0] + length, beyond), b[:, 1]])
        quads.append(np.stack([a, b, far_b, far_a], axis=1))
    quads = np.concatenate(quads)
    hulls = shapely.convex_hull(
        shapely.multipoints(quads.reshape(-1, 2), indices=np.repeat(np.arange(len(quads)), 4))
    )  # a degenerate (horizontal) piece's hull is a line, which still counts
    footprint = shapely.union_all(hulls)
    shapely.prepare(footprint)
    return shapely.dwithin(footprint, shapely.points(pts), radius)


def pinch_rules(
    points: np.ndarray,
    contour: Contour,
    config: SimConfig,
    segments: Path | None = None,
    arm_radius_mm: float = ARM_RADIUS_MM,
    arm_length_mm: float = ARM_LENGTH_MM,
) -> dict[str, np.ndarray]:
    """Each feasibility rule for material points (M, 2) as a (M,) bool mask, True where it holds.

    Rules: ``edges`` (at least one grasp radius inside the sheet), ``corners`` (at least
    :data:`CORNER_MARGIN_MM` from a corner), ``fixture`` (more than a grasp radius from every fixture
    vertex), ``contour`` (the gripped disc never reaches the scissors' cut: at least grasp radius + cut
    radius from the contour) and ``arm`` (not :func:`under_arm` while the scissors follow ``segments``;
    default: the whole contour, :func:`warpcut.task.default_segments`, which the arm sweeps the same way
    however it is split).
    """
    points = _points("points", points)
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
    path = segments if segments is not None else default_segments(contour)
    rules["arm"] = ~under_arm(points, path, arm_radius_mm, arm_length_mm)
    return rules


def pinch_feasible(
    points: np.ndarray,
    contour: Contour,
    config: SimConfig,
    segments: Path | None = None,
    arm_radius_mm: float = ARM_RADIUS_MM,
    arm_length_mm: float = ARM_LENGTH_MM,
) -> np.ndarray:
    """Which material points (M, 2) (mm) are feasible pinch points for cutting ``contour``.

    Feasible = every rule of :func:`pinch_rules` holds: on the sheet at least one grasp radius from its
    edges, at least :data:`CORNER_MARGIN_MM` from the corners, not on fixture vertices, far enough from the
    contour that the gripped disc never reaches the scissors' cut (grasp radius + cut radius), and not under
    the cutting arm of radius ``arm_radius_mm`` while it cuts ``segments`` (default: the whole contour).

    Returns:
        (M,) bool.
    """
    rules = pinch_rules(points, contour, config, segments, arm_radius_mm, arm_length_mm)
    return np.logical_and.reduce(list(rules.values()))


def sample_pinch_candidates(
    contour: Contour,
    config: SimConfig,
    num: int = 30,
    rng: np.random.Generator | None = None,
    include_centroid: bool = True,
    segments: Path | None = None,
    arm_radius_mm: float = ARM_RADIUS_MM,
    arm_length_mm: float = ARM_LENGTH_MM,
) -> np.ndarray:
    """``num`` feasible pinch points drawn uniformly (rejection sampling), plus the contour's centroid
    first when it is feasible (the paper's candidate set). Returns (K, 2) material mm, K <= num + 1; K < num
    only where the feasible region is too small to hit ``num`` times in 100 rounds of draws.

    Raises:
        ValueError: when no feasible point is found.
    """
    if not isinstance(num, int | np.integer) or isinstance(num, bool) or num < 0:
        raise ValueError(f"num: must be a non-negative integer (got {num!r})")
    rng = rng if rng is not None else np.random.default_rng(0)

    def feasible(p: np.ndarray) -> np.ndarray:
        return pinch_feasible(p, contour, config, segments, arm_radius_mm, arm_length_mm)

    chosen: list[np.ndarray] = []
    if include_centroid and feasible(contour.centroid)[0]:
        chosen.append(np.asarray(contour.centroid, dtype=np.float64))
    need = int(num)
    for _ in range(100):
        if need <= 0:
            break
        draws = rng.uniform([0.0, 0.0], [config.width_mm, config.height_mm], size=(max(4 * need, 64), 2))
        good = draws[feasible(draws)][:need]
        chosen.extend(good)
        need -= len(good)
    if not chosen:
        arm = f", nor under the cutting arm (radius {arm_radius_mm:g} mm)" if segments is not None else ""
        raise ValueError(
            f"contour {contour.name!r}: no feasible pinch point on the sheet: no point is clear of its "
            f"edges, corners, fixture and the contour{arm}; give a pinch point explicitly (--pinch), use "
            "a smaller arm_radius_mm, or move the contour to leave the gripper room"
        )
    return np.asarray(chosen)


def pinch_candidates(
    contour: Contour,
    config: SimConfig,
    segments: Path,
    num: int = 30,
    rng: np.random.Generator | None = None,
    arm_radius_mm: float = ARM_RADIUS_MM,
    arm_length_mm: float = ARM_LENGTH_MM,
) -> np.ndarray:
    """The paper's candidate pinch points (Problem 2a): ``num`` points drawn uniformly from the feasible
    region, where the gripper collides neither with the sheet's fixture nor with the cutting arm sweeping
    ``segments``, preceded by the contour's centroid when it is feasible.

    Returns:
        (K, 2) material points (mm).

    Raises:
        ValueError: naming the contour when the feasible region is empty.
    """
    return sample_pinch_candidates(contour, config, num, rng, True, segments, arm_radius_mm, arm_length_mm)


def nearest_feasible(
    point: np.ndarray,
    contour: Contour,
    config: SimConfig,
    segments: Path | None = None,
    arm_radius_mm: float = ARM_RADIUS_MM,
    arm_length_mm: float = ARM_LENGTH_MM,
) -> np.ndarray:
    """The feasible grid of 0.5 mm points' member nearest to ``point`` (the point itself if feasible)."""
    point = np.asarray(point, dtype=np.float64)
    if pinch_feasible(point, contour, config, segments, arm_radius_mm, arm_length_mm)[0]:
        return point
    xs = np.arange(0.0, config.width_mm + 1e-9, 0.5)
    ys = np.arange(0.0, config.height_mm + 1e-9, 0.5)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    grid = grid[pinch_feasible(grid, contour, config, segments, arm_radius_mm, arm_length_mm)]
    if not len(grid):
        raise ValueError(f"contour {contour.name!r}: no feasible pinch point on the sheet")
    return grid[np.argmin(np.linalg.norm(grid - point, axis=1))]


def feasible_centroid(
    contour: Contour,
    config: SimConfig,
    segments: Path | None = None,
    arm_radius_mm: float = ARM_RADIUS_MM,
    arm_length_mm: float = ARM_LENGTH_MM,
) -> np.ndarray:
    """The contour's centroid when it is a feasible pinch point (:func:`pinch_feasible`), else the feasible
    point nearest to it (0.5 mm grid): the default pinch of the analytic policy and of RL without a plan.

    Raises:
        ValueError: naming the contour when no point is feasible.
    """
    return nearest_feasible(contour.centroid, contour, config, segments, arm_radius_mm, arm_length_mm)


def search_orders(
    contour: Contour,
    config: SimConfig,
    segments: Sequence[Segment],
    candidates: np.ndarray,
    device: str | None = None,
    seed: int = 0,
    limit: int = ORDER_LIMIT,
) -> tuple[list[tuple[int, ...]], np.ndarray]:
    """The paper's ``exhaustive_search``: cut ``segments`` in every order from every candidate pinch point.

    All (candidate, order) pairs are simulated as one :class:`~warpcut.task.CuttingTask` batch with fixed
    tension (the grasp pinches and holds still: no actions) and without process noise, so the search is
    deterministic. Up to ``limit`` segments the orders are all K! permutations; beyond, the heuristic list
    of :func:`~warpcut.planning.segmentation.segment_orders`, with a warning.

    Args:
        candidates: (C, 2) pinch points (mm).

    Returns:
        ``(orders, errors)``: the O orders tried and the (C, O) errors in vertices.
    """
    candidates = _points("candidates", candidates)
    if not segments:
        raise ValueError("segments: need at least one segment to order")
    notches = np.array([s.notch for s in segments])
    orders, heuristic = segment_orders(len(segments), limit=limit, notches=notches)
    if heuristic:
        warnings.warn(
            f"contour {contour.name!r}: {len(segments)} segments would need {math.factorial(len(segments))} "
            f"orders per pinch point; searching only {len(orders)} heuristic orders (along the contour, "
            "reversed, by notch x and y), so the best order may be missed",
            stacklevel=2,
        )
    num_c, num_o = len(candidates), len(orders)
    polylines = [[segments[k].points for k in order] for order in orders] * num_c  # env = c * O + o
    task = CuttingTask(
        config.replace(noise_std=0.0),
        contour,
        num_envs=num_c * num_o,
        pinch_points=np.repeat(candidates, num_o, axis=0),
        segments=polylines,
        device=device,
        seed=seed,
    )
    return orders, task.run(None).error_vertices.reshape(num_c, num_o)


@dataclass
class Plan:
    """The plan for cutting one contour: its segments, the pinch candidates and the chosen pinch and order.

    Points are material coordinates (mm); errors are symmetric differences in vertices, with fixed tension.
    """

    contour: Contour
    segments: list[Segment]
    order: tuple[int, ...]
    """Best cutting order overall: indices into :attr:`segments`."""
    candidates: list[dict]
    """Feasible candidates: ``point`` (2,), ``feasible`` (True), ``error_vertices`` (with the candidate's
    best order), ``best_order``."""
    chosen: dict
    """The best candidate: ``pinch`` (2,), ``order``, ``error_vertices``."""
    orders: list[tuple[int, ...]] = field(default_factory=list)
    """The orders simulated for every candidate."""
    errors: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """(C, O) error in vertices for candidate c cut in order o."""
    rejected: list[dict] = field(default_factory=list)
    """Infeasible points worth reporting (the centroid when infeasible): ``point``, ``feasible`` (False),
    ``violates`` (the broken rules of :func:`pinch_rules`)."""
    arm_radius_mm: float = ARM_RADIUS_MM
    arm_length_mm: float = ARM_LENGTH_MM
    config: SimConfig = field(default_factory=SimConfig)
    """The simulation parameters the plan was made with (sheet size, grasp radius: feasibility)."""

    @property
    def heuristic_orders(self) -> bool:
        """Whether fewer than all K! orders were searched."""
        return len(self.orders) < math.factorial(len(self.segments))

    @property
    def analytic_pinch(self) -> np.ndarray:
        """Where the analytic policy pinches under this plan: the contour's centroid (the paper's choice) when
        it is feasible, else the feasible point nearest to it (:func:`feasible_centroid`): a centroid under
        the cutting arm or on the cut line is a grasp the robot cannot make."""
        return feasible_centroid(
            self.contour, self.config, self.segments, self.arm_radius_mm, self.arm_length_mm
        )

    def ordered_segments(self, order: Sequence[int] | None = None) -> list[np.ndarray]:
        """The segments' polylines (mm) in cutting ``order`` (default: the chosen one), for
        ``CuttingTask(segments=[plan.ordered_segments()])``."""
        order = self.order if order is None else tuple(order)
        if sorted(order) != list(range(len(self.segments))):
            raise ValueError(f"order: must be a permutation of 0..{len(self.segments) - 1} (got {order!r})")
        return [self.segments[k].points for k in order]

    def to_json(self) -> dict:
        """A JSON-serialisable dict: ``segments``, ``order``, ``pinch_candidates`` (feasible ones, then the
        rejected points with ``error_vertices`` null), ``chosen``, and context."""
        listed = [
            {
                "point": _xy(c["point"]),
                "feasible": True,
                "error_vertices": float(c["error_vertices"]),
                "best_order": [int(k) for k in c["best_order"]],
            }
            for c in self.candidates
        ]
        listed += [
            {
                "point": _xy(r["point"]),
                "feasible": False,
                "error_vertices": None,
                "violates": list(r["violates"]),
            }
            for r in self.rejected
        ]
        return {
            "contour": self.contour.name,
            "segments": [
                {"points": s.points.tolist(), "notch": _xy(s.notch), "termination": _xy(s.termination)}
                for s in self.segments
            ],
            "order": [int(k) for k in self.order],
            "pinch_candidates": listed,
            "chosen": {
                "pinch": _xy(self.chosen["pinch"]),
                "order": [int(k) for k in self.chosen["order"]],
                "error_vertices": float(self.chosen["error_vertices"]),
            },
            "orders_searched": [[int(k) for k in o] for o in self.orders],
            "heuristic_orders": self.heuristic_orders,
            "arm_radius_mm": float(self.arm_radius_mm),
            "arm_length_mm": None if math.isinf(self.arm_length_mm) else float(self.arm_length_mm),
        }


def plan_cut(
    contour: Contour,
    config: SimConfig,
    num_candidates: int = 30,
    seed: int = 0,
    device: str | None = None,
    tolerance_mm: float = 1.0,
    arm_radius_mm: float = ARM_RADIUS_MM,
    arm_length_mm: float = ARM_LENGTH_MM,
) -> Plan:
    """Plan the cut of ``contour``: segments, pinch candidates, and the best (pinch point, order) pair.

    Args:
        contour: The contour to cut (material mm).
        config: Simulation parameters; the search runs them without process noise.
        num_candidates: Pinch points sampled from the feasible region (paper N = 30), >= 1; the centroid is
            added when feasible.
        seed: Seeds the candidate sampling and the simulator.
        device: Warp device for the search batch.
        tolerance_mm: Segmentation tolerance (mm), > 0 (see :func:`~warpcut.planning.segmentation.segment_contour`).
        arm_radius_mm: Cutting arm radius (mm), >= 0 (see :func:`under_arm`).
        arm_length_mm: Reach of the arm's footprint from the scissor tip toward +x (mm), default all the
            way (see :func:`under_arm`).

    Raises:
        ValueError: for an invalid argument (named) or a contour that leaves no feasible pinch point.
    """
    if not isinstance(contour, Contour):
        raise ValueError(
            f"contour: expected a warpcut Contour (load_contour(...)), got {type(contour).__name__}"
        )
    if not isinstance(config, SimConfig):
        raise ValueError(f"config: expected a SimConfig, got {type(config).__name__}")
    count_ok = isinstance(num_candidates, int | np.integer) and not isinstance(num_candidates, bool)
    if not count_ok or num_candidates < 1:
        raise ValueError(f"num_candidates: must be a positive integer (got {num_candidates!r})")
    arm = {"arm_radius_mm": _mm("arm_radius_mm", arm_radius_mm)}
    arm["arm_length_mm"] = _mm("arm_length_mm", arm_length_mm, allow_inf=True)
    segments = segment_contour(contour, tolerance_mm=tolerance_mm)
    rng = np.random.default_rng(seed)
    points = pinch_candidates(contour, config, segments, num_candidates, rng, **arm)
    orders, errors = search_orders(contour, config, segments, points, device=device, seed=seed)
    best = np.argmin(errors, axis=1)  # each candidate's best order: the first among ties
    candidates = [
        {
            "point": p,
            "feasible": True,
            "error_vertices": float(errors[c, best[c]]),
            "best_order": orders[best[c]],
        }
        for c, p in enumerate(points)
    ]
    winner = int(np.argmin(errors[np.arange(len(points)), best]))  # the first candidate among ties
    chosen = {"pinch": points[winner], "order": orders[best[winner]], "error_vertices": float(errors.min())}
    # The centroid is the paper's default pinch point: say why it is not a candidate when it is not.
    rules = pinch_rules(contour.centroid, contour, config, segments, **arm)
    violates = [name for name, ok in rules.items() if not ok[0]]
    rejected = [{"point": contour.centroid, "feasible": False, "violates": violates}] if violates else []
    return Plan(
        contour, segments, chosen["order"], candidates, chosen, orders, errors, rejected, **arm, config=config
    )


def _polylines(path: Path) -> list[np.ndarray]:
    """``path`` as a list of (P, 2) float arrays."""
    items = [path] if isinstance(path, Segment) or (isinstance(path, np.ndarray) and path.ndim == 2) else path
    lines = [np.asarray(p.points if isinstance(p, Segment) else p, dtype=np.float64) for p in items]
    if not lines or any(line.ndim != 2 or line.shape[1] != 2 or len(line) == 0 for line in lines):
        raise ValueError("path: expected a (P, 2) polyline (mm), a Segment, or a non-empty list of them")
    return lines


def _points(name: str, points: np.ndarray) -> np.ndarray:
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape == (2,):
        pts = pts[None]
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"{name}: expected (M, 2) or (2,) material points (mm), got shape {pts.shape}")
    return pts


def _min_distance(points: np.ndarray, others: np.ndarray) -> np.ndarray:
    if not len(others):
        return np.full(len(points), np.inf)
    return np.min(np.linalg.norm(points[:, None] - others[None], axis=2), axis=1)


def _mm(name: str, value: float, allow_inf: bool = False) -> float:
    number = isinstance(value, int | float | np.number) and not isinstance(value, bool)
    ok = number and (math.isfinite(value) or (allow_inf and value == math.inf))
    if not ok or value < 0:
        raise ValueError(f"{name}: must be a non-negative number of mm (got {value!r})")
    return float(value)


def _xy(point: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(point, dtype=np.float64)]
