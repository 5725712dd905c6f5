"""The search for a cut plan, the paper's Fig. 2 pipeline up to the policy: segments, pinch candidates, order.

:func:`plan_cut` runs it for one contour:

1. split the contour into segments the cutting arm can cut
   (:func:`~warpcut.planning.segmentation.segment_contour`);
2. sample candidate pinch points uniformly from the feasible region, plus the contour's centroid when it is
   feasible (:func:`pinch_candidates`, Problem 2a);
3. simulate every (candidate, cutting order) pair with fixed tension, all of them as one
   :class:`~warpcut.task.CuttingTask` batch, and keep the order and the pinch point with the lowest error
   (:func:`search_orders`, the paper's ``exhaustive_search``, Problem 1).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from warpcut.contours import Contour
from warpcut.planning.feasibility import (
    ArmModel,
    ScissorPath,
    default_pinch,
    material_points,
    no_pinch_error,
    pinch_feasible,
    pinch_rules,
)
from warpcut.planning.segmentation import ORDER_LIMIT, Segment, segment_contour, segment_orders
from warpcut.sim.config import PINCH_CANDIDATES, SEGMENT_TOLERANCE_MM, SimConfig
from warpcut.sim.memory import batch_named, check_batch_memory
from warpcut.task import CuttingTask, divergence_error


def pinch_candidates(
    contour: Contour,
    config: SimConfig,
    segments: ScissorPath | None = None,
    num: int = PINCH_CANDIDATES,
    rng: np.random.Generator | None = None,
    arm: ArmModel = ArmModel(),
) -> np.ndarray:
    """The paper's candidate pinch points (Problem 2a): the contour's centroid first when it is feasible,
    then ``num`` points drawn uniformly (rejection sampling) from the feasible region, where the gripper
    collides neither with the sheet's fixture nor with the cutting ``arm`` sweeping ``segments`` (default:
    the whole contour; see :func:`~warpcut.planning.feasibility.pinch_feasible`).

    Returns:
        (K, 2) material points (mm), K <= num + 1; K < num only where the feasible region is too small to
        hit ``num`` times in 100 rounds of draws.

    Raises:
        ValueError: for a bad ``num``, or naming the contour when the feasible region is empty.
    """
    if not isinstance(num, int | np.integer) or isinstance(num, bool) or num < 0:
        raise ValueError(f"num: must be a non-negative integer (got {num!r})")
    rng = rng if rng is not None else np.random.default_rng(0)

    def feasible(p: np.ndarray) -> np.ndarray:
        return pinch_feasible(p, contour, config, segments, arm)

    chosen: list[np.ndarray] = []
    if feasible(contour.centroid)[0]:
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
        raise no_pinch_error(contour, config, segments, arm)
    return np.asarray(chosen)


def search_orders(
    contour: Contour,
    config: SimConfig,
    segments: Sequence[Segment],
    candidates: np.ndarray,
    device: str | None = None,
    seed: int = 0,
    limit: int = ORDER_LIMIT,
    arm: ArmModel = ArmModel(),
) -> tuple[list[tuple[int, ...]], np.ndarray]:
    """The paper's ``exhaustive_search``: cut ``segments`` in every order from every candidate pinch point.

    All (candidate, order) pairs are simulated as one :class:`~warpcut.task.CuttingTask` batch with fixed
    tension (the grasp pinches and holds still: no actions) and without process noise, so the search is
    deterministic. Up to ``limit`` segments the orders are all K! permutations; beyond, the heuristic list
    of :func:`~warpcut.planning.segmentation.segment_orders`, with a warning.

    Args:
        candidates: (C, 2) pinch points (mm), feasible with the cutting ``arm``
            (:class:`~warpcut.planning.feasibility.InfeasiblePinch` otherwise).

    Returns:
        ``(orders, errors)``: the O orders tried and the (C, O) errors in vertices.
    """
    candidates = material_points("candidates", candidates)
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
        arm=arm,
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
    arm: ArmModel = ArmModel()
    """The cutting arm the plan's feasibility assumed."""
    config: SimConfig = field(default_factory=SimConfig)
    """The simulation parameters the plan was made with (sheet size, grasp radius: feasibility)."""

    def ranked(self, keep: int | None = None) -> list[dict]:
        """The candidates, best by fixed tension first (the first is :attr:`chosen`; the first ``keep``;
        None: all), each as ``pinch`` (a list), ``order`` (its best) and ``fixed_error_vertices``."""
        ranked = sorted(range(len(self.candidates)), key=lambda c: self.candidates[c]["error_vertices"])
        return [
            {
                "pinch": [float(v) for v in c["point"]],
                "order": [int(k) for k in c["best_order"]],
                "fixed_error_vertices": float(c["error_vertices"]),
            }
            for c in (self.candidates[k] for k in ranked[:keep])
        ]

    @property
    def heuristic_orders(self) -> bool:
        """Whether fewer than all K! orders were searched."""
        return len(self.orders) < math.factorial(len(self.segments))

    @property
    def analytic_pinch(self) -> np.ndarray:
        """Where the analytic policy pinches under this plan: the default pinch
        (:func:`~warpcut.planning.feasibility.default_pinch`) with the plan's segments and arm; a centroid
        under the cutting arm or on the cut line is a grasp the robot cannot make."""
        return default_pinch(self.contour, self.config, self.arm, segments=self.segments)

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
            "errors_vertices": self.errors.tolist(),
            "heuristic_orders": self.heuristic_orders,
            "arm_radius_mm": self.arm.radius_mm,
            "arm_length_mm": None if math.isinf(self.arm.length_mm) else self.arm.length_mm,
        }

    @classmethod
    def from_json(cls, data: dict, contour: Contour, config: SimConfig) -> Plan:
        """The plan :meth:`to_json` wrote (read back from JSON), for ``contour`` as planned with ``config``:
        the same segments, candidates, orders and errors, bit for bit (JSON's floats round-trip).

        Raises:
            ValueError: when ``data`` is not a plan of ``contour`` with everything :meth:`to_json` writes
                (a plan written before ``errors_vertices`` was added, for one: plan again).
        """
        try:
            if data["contour"] != contour.name:
                raise ValueError(f"it is {data['contour']!r}'s plan, not {contour.name!r}'s")
            listed = data["pinch_candidates"]
            length = data["arm_length_mm"]
            plan = cls(
                contour=contour,
                segments=[Segment(np.asarray(s["points"], dtype=np.float64)) for s in data["segments"]],
                order=tuple(int(k) for k in data["order"]),
                candidates=[
                    {
                        "point": np.asarray(c["point"], dtype=np.float64),
                        "feasible": True,
                        "error_vertices": float(c["error_vertices"]),
                        "best_order": tuple(int(k) for k in c["best_order"]),
                    }
                    for c in listed
                    if c["feasible"]
                ],
                chosen={
                    "pinch": np.asarray(data["chosen"]["pinch"], dtype=np.float64),
                    "order": tuple(int(k) for k in data["chosen"]["order"]),
                    "error_vertices": float(data["chosen"]["error_vertices"]),
                },
                orders=[tuple(int(k) for k in o) for o in data["orders_searched"]],
                errors=np.asarray(data["errors_vertices"], dtype=np.float64),
                rejected=[
                    {
                        "point": np.asarray(c["point"], dtype=np.float64),
                        "feasible": False,
                        "violates": c["violates"],
                    }
                    for c in listed
                    if not c["feasible"]
                ],
                arm=ArmModel(
                    radius_mm=data["arm_radius_mm"], length_mm=math.inf if length is None else length
                ),
                config=config,
            )
        except (KeyError, TypeError, ValueError) as exc:
            what = f"missing {exc}" if isinstance(exc, KeyError) else str(exc)
            raise ValueError(f"plan: not a warpcut plan of {contour.name!r} ({what}); plan it again") from exc
        if plan.errors.shape != (len(plan.candidates), len(plan.orders)):
            raise ValueError(
                f"plan: errors_vertices has shape {plan.errors.shape}, not (candidates, orders) = "
                f"({len(plan.candidates)}, {len(plan.orders)}); plan {contour.name!r} again"
            )
        return plan


def plan_cut(
    contour: Contour,
    config: SimConfig,
    *,
    num_candidates: int = PINCH_CANDIDATES,
    seed: int = 0,
    device: str | None = None,
    tolerance_mm: float = SEGMENT_TOLERANCE_MM,
    arm: ArmModel = ArmModel(),
) -> Plan:
    """Plan the cut of ``contour``: segments, pinch candidates, and the best (pinch point, order) pair.

    Args:
        contour: The contour to cut (material mm).
        config: Simulation parameters; the search runs them without process noise.
        num_candidates: Pinch points sampled from the feasible region (paper N = 30), >= 1; the centroid is
            added when feasible.
        seed: Seeds the candidate sampling and the simulator.
        device: Warp device for the search batch.
        tolerance_mm: Segmentation tolerance (mm), > 0 (see
            :func:`~warpcut.planning.segmentation.segment_contour`).
        arm: The cutting arm whose footprint pinch points must avoid (see
            :func:`~warpcut.planning.feasibility.under_arm`).

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
    if not isinstance(arm, ArmModel):
        raise ValueError(f"arm: expected an ArmModel, got {type(arm).__name__}")
    segments = segment_contour(contour, tolerance_mm=tolerance_mm)
    rng = np.random.default_rng(seed)
    with batch_named(
        "the planner's batch (pinch candidates x segment orders)",
        "plan fewer pinch candidates (the candidates setting; plan: --candidates) or lower the resolution",
        default=True,  # a caller without a candidates setting names its own fix
    ):
        check_batch_memory(num_candidates + 1, config.nx * config.ny)  # one order each at least: first
        points = pinch_candidates(contour, config, segments, num_candidates, rng, arm)
        orders, errors = search_orders(contour, config, segments, points, device=device, seed=seed, arm=arm)
    if not np.all(np.isfinite(errors)):  # diverged simulations: no candidate may be chosen by a NaN
        raise divergence_error([contour], ~np.isfinite(errors.reshape(1, -1)), config)
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
    rules = pinch_rules(contour.centroid, contour, config, segments, arm)
    violates = [name for name, ok in rules.items() if not ok[0]]
    rejected = [{"point": contour.centroid, "feasible": False, "violates": violates}] if violates else []
    return Plan(contour, segments, chosen["order"], candidates, chosen, orders, errors, rejected, arm, config)


def _xy(point: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(point, dtype=np.float64)]
