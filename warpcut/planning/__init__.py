"""Cut planning: segments the cutting arm can cut (:mod:`~warpcut.planning.segmentation`), where the
gripper may pinch the sheet (:mod:`~warpcut.planning.feasibility`), and the search for the best pinch point
and cutting order (:mod:`~warpcut.planning.search`, :func:`plan_cut`), and seeded random contours it can plan
(:mod:`~warpcut.planning.generate`, :func:`generate_contours`), beside the one resolver of every way a
contour is named (:func:`resolve_contour`, :func:`resolve_specs`).
"""

from warpcut.planning.feasibility import (
    CORNER_MARGIN_MM,
    ArmModel,
    InfeasiblePinch,
    ScissorPath,
    check_pinch,
    default_pinch,
    nearest_feasible,
    pinch_feasible,
    pinch_problems,
    pinch_rules,
    under_arm,
)
from warpcut.planning.generate import (
    EXTRA_KINDS,
    KINDS,
    SPLITS,
    generate_contours,
    resolve_contour,
    resolve_specs,
)
from warpcut.planning.search import Plan, pinch_candidates, plan_cut, search_orders
from warpcut.planning.segmentation import ORDER_LIMIT, Segment, is_monotone, segment_contour, segment_orders

__all__ = [
    "CORNER_MARGIN_MM",
    "ORDER_LIMIT",
    "ArmModel",
    "InfeasiblePinch",
    "EXTRA_KINDS",
    "KINDS",
    "Plan",
    "SPLITS",
    "ScissorPath",
    "Segment",
    "check_pinch",
    "default_pinch",
    "generate_contours",
    "is_monotone",
    "nearest_feasible",
    "pinch_candidates",
    "pinch_feasible",
    "pinch_problems",
    "pinch_rules",
    "plan_cut",
    "resolve_contour",
    "resolve_specs",
    "search_orders",
    "segment_contour",
    "segment_orders",
    "under_arm",
]
