"""Seeded random contours that the simulator resolves and the planner can plan: a source of shapes beyond
the built-in suite, with separate streams for training, validation and test.

Four kinds, drawn on the sheet at random sizes, places and turns (:data:`KINDS`):

- ``blob``: a closed curve whose radius is a few random harmonics about a centre;
- ``polygon``: a convex polygon of 3 to 7 corners, rounded (the grid is ~4 mm, the scissors' cut wider);
- ``notched``: a blob or polygon with a rounded notch bitten into its side (a concave shape);
- ``open``: a smooth curve that enters through one edge of the sheet and leaves through another (or the
  same one), as the built-in open contours do.

Two more are drawn only where asked (:data:`EXTRA_KINDS`, e.g. by ``warpcut teachers``), so the default
streams stay as they are:

- ``elongated``: a long, thin blob (2.2 to 4.5 times as long as it is wide) at any tilt, like the suite's
  tilted ellipse;
- ``edge``: a blob or polygon that hugs one edge of the sheet (3 to 6 mm from it), like the suite's cuts near
  the clips.

Contour ``i`` of split ``s`` under ``seed`` is drawn from its own random stream, seeded by
``(seed, s, i)``: the same triple gives the same contour on any machine, contours of different splits never
share a stream, and asking for more contours of a split keeps the first ones. A draw the simulator would not
resolve (:func:`~warpcut.contours.check_resolution`) or the planner could not plan (no segments within
:data:`~warpcut.planning.segmentation.ORDER_LIMIT`, or no feasible pinch point) is drawn again from the same
stream, so every contour returned is usable as it is.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from typing import Any

import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon

from warpcut.contours import (
    BUILTIN_SPACING_MM,
    Contour,
    ContourError,
    builtin_names,
    check_resolution,
    contour_from_json,
    load_contour,
    validate,
)
from warpcut.contours.polyline import arc_lengths, resample_polyline
from warpcut.io import safe_name
from warpcut.planning.feasibility import default_pinch
from warpcut.planning.segmentation import ORDER_LIMIT, segment_contour
from warpcut.sim.config import SimConfig
from warpcut.validation import is_number

SPLITS = ("train", "validation", "test")
"""The streams of generated contours, never mixed: each draws from seeds of its own."""

KINDS = ("blob", "polygon", "notched", "open")
"""The kinds of generated contour, drawn in turn (contour ``i`` is of kind ``KINDS[i % 4]``)."""

EXTRA_KINDS = ("elongated", "edge")
"""Kinds drawn only where ``kinds`` names them (module docstring); contour ``i`` of a stream drawn with
``kinds`` is of kind ``kinds[i % len(kinds)]``, and its name says which."""

EDGE_MARGIN_MM = (3.0, 6.0)
"""How far an ``edge`` contour keeps from the edge it hugs (mm, drawn in this range)."""

MARGIN_MM = 10.0
"""Closed shapes keep at least this far from the sheet's edges (the built-in ones keep >= 8 mm)."""

MAX_DRAWS = 200
"""Draws tried per contour before giving up (a sheet or grid on which almost nothing is plannable)."""

_DENSE = 2048

MAX_CONTOURS = 10_000
"""The most contours one call draws (the names' four-digit index): each is drawn, resolved and planned
(tenths of a second), and a batch holds them all, so a count beyond would run for days or take the memory."""

GENERATED_SPEC = re.compile(
    r"gen-(?P<split>[a-z]+)-(?P<seed>\d+)(?::(?P<count>\d+)|-(?P<index>\d+)-(?P<kind>[a-z]+))"
)
"""A generated contour by name, ``gen-SPLIT-SEED-INDEX-KIND`` (e.g. ``gen-test-0-0003-open``), or the first
N of a split, ``gen-SPLIT-SEED:N`` (e.g. ``gen-test-0:24``): what ``warpcut evaluate --contours`` and the
other commands' ``--contour`` take besides built-in names and files."""


def generate_contours(
    count: int,
    split: str = "train",
    seed: int = 0,
    config: SimConfig | None = None,
    kinds: Sequence[str] = KINDS,
) -> list[Contour]:
    """``count`` random contours of ``split``, each resolvable on ``config``'s grid and plannable.

    Args:
        count: How many, >= 0.
        split: ``train``, ``validation`` or ``test`` (:data:`SPLITS`).
        seed: The generator's seed, an integer >= 0.
        config: The physics whose sheet, grid and grasp the contours must suit (default: ``SimConfig()``).
        kinds: The kinds to draw, in turn (:data:`KINDS`).

    Returns:
        The contours, named ``gen-SPLIT-SEED-INDEX-KIND`` (e.g. ``gen-test-0-0003-open``).

    Raises:
        ValueError: an argument out of range (named), or a contour not drawn in :data:`MAX_DRAWS` tries.
    """
    if split not in SPLITS:
        raise ValueError(f"split: one of {', '.join(SPLITS)} (got {split!r})")
    for name, value in (("count", count), ("seed", seed)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
            raise ValueError(f"{name}: an integer >= 0 (got {value!r})")
    if count > MAX_CONTOURS:
        raise ValueError(f"count: at most {MAX_CONTOURS} contours of a split (got {count}); give fewer")
    kinds = list(kinds)
    unknown = [k for k in kinds if k not in KINDS + EXTRA_KINDS]
    if not kinds or unknown:
        raise ValueError(f"kinds: a non-empty list of {', '.join(KINDS + EXTRA_KINDS)} (got {kinds!r})")
    config = SimConfig() if config is None else config
    return [_contour(i, split, int(seed), config, kinds[i % len(kinds)]) for i in range(int(count))]


def _contour(index: int, split: str, seed: int, config: SimConfig, kind: str) -> Contour:
    rng = np.random.default_rng([seed, SPLITS.index(split), index])
    width, height = config.width_mm, config.height_mm
    name = f"gen-{split}-{seed}-{index:04d}-{kind}"
    for _ in range(MAX_DRAWS):
        try:
            closed, dense = _DRAW[kind](rng, width, height)
            length = arc_lengths(dense, closed)[-1]
            points = resample_polyline(dense, length / math.ceil(length / BUILTIN_SPACING_MM), closed)
            if closed:  # start where scissors coming from +x meet the shape first, as the built-ins do
                points = np.roll(points, -int(np.argmax(points[:, 0])), axis=0)
            contour = validate(name, closed, points, (width, height))
            check_resolution(contour, config.spacing_mm)
            if len(segment_contour(contour)) > ORDER_LIMIT:
                continue
            default_pinch(contour, config)  # a feasible pinch point exists
            return contour
        except (ContourError, ValueError):
            continue
    raise ValueError(
        f"{name}: no resolvable, plannable contour in {MAX_DRAWS} draws on a {width:g} x {height:g} mm "
        "sheet at this resolution; use a finer resolution or a larger sheet"
    )


def _place(rng: np.random.Generator, shape: Polygon, width: float, height: float) -> Polygon | None:
    """``shape`` (about the origin) turned at random and moved to a random place at least
    :data:`MARGIN_MM` from the edges; None where it does not fit."""
    shape = shapely.affinity.rotate(shape, float(rng.uniform(0, 360)), origin=(0, 0))
    x0, y0, x1, y1 = shape.bounds
    room_x, room_y = width - 2 * MARGIN_MM - (x1 - x0), height - 2 * MARGIN_MM - (y1 - y0)
    if room_x < 0 or room_y < 0:
        return None
    dx = MARGIN_MM - x0 + float(rng.uniform(0, room_x))
    dy = MARGIN_MM - y0 + float(rng.uniform(0, room_y))
    return shapely.affinity.translate(shape, dx, dy)


def _outline(region) -> np.ndarray | None:
    """The exterior of ``region`` if it is one simple polygon without holes, else None."""
    if not isinstance(region, Polygon) or region.is_empty or region.interiors or not region.is_valid:
        return None
    return np.asarray(region.exterior.coords)[:-1]


def _rounded(region, radius: float):
    """Opening then closing by ``radius`` (mm): no tip or inner corner sharper than the grid resolves."""
    opened = region.buffer(-radius, quad_segs=16).buffer(radius, quad_segs=16)
    return opened.buffer(radius, quad_segs=16).buffer(-radius, quad_segs=16)


def _blob_shape(rng: np.random.Generator, scale: float) -> Polygon:
    r0 = scale * float(rng.uniform(14, 34))
    terms = [(k, float(rng.uniform(0, 0.12)) * r0, float(rng.uniform(0, 2 * np.pi))) for k in range(2, 6)]
    t = np.linspace(0, 2 * np.pi, _DENSE, endpoint=False)
    r = r0 + sum(a * np.cos(k * t + phase) for k, a, phase in terms)
    aspect = float(rng.uniform(0.6, 1.0))
    return Polygon(np.stack([r * np.cos(t), aspect * r * np.sin(t)], axis=1))


def _polygon_shape(rng: np.random.Generator, scale: float) -> Polygon:
    corners = int(rng.integers(3, 8))
    angles = np.sort(rng.uniform(0, 2 * np.pi, corners))
    radius = scale * float(rng.uniform(18, 38))
    aspect = float(rng.uniform(0.55, 1.0))
    hull = shapely.convex_hull(
        shapely.MultiPoint(np.stack([radius * np.cos(angles), aspect * radius * np.sin(angles)], axis=1))
    )
    return _rounded(hull, float(rng.uniform(3, 6))) if isinstance(hull, Polygon) else Polygon()


def _blob(rng: np.random.Generator, width: float, height: float) -> tuple[bool, np.ndarray]:
    return True, _closed(rng, _blob_shape(rng, min(width, height) / 100), width, height)


def _polygon(rng: np.random.Generator, width: float, height: float) -> tuple[bool, np.ndarray]:
    return True, _closed(rng, _polygon_shape(rng, min(width, height) / 100), width, height)


def _notched(rng: np.random.Generator, width: float, height: float) -> tuple[bool, np.ndarray]:
    scale = min(width, height) / 100
    body = _blob_shape(rng, scale) if rng.random() < 0.5 else _polygon_shape(rng, scale)
    if body.is_empty:
        raise ContourError("no body")
    x0, y0, x1, y1 = body.bounds
    size = min(x1 - x0, y1 - y0)
    angle = float(rng.uniform(0, 2 * np.pi))
    edge = shapely.ops.nearest_points(body.exterior, Point(np.cos(angle) * 1e3, np.sin(angle) * 1e3))[0]
    depth = float(rng.uniform(0.2, 0.4)) * size
    notch = Point(edge.x, edge.y).buffer(depth, quad_segs=16)
    return True, _closed(rng, _rounded(body - notch, float(rng.uniform(3, 5))), width, height)


def _elongated(rng: np.random.Generator, width: float, height: float) -> tuple[bool, np.ndarray]:
    scale = min(width, height) / 100
    r0 = scale * float(rng.uniform(20, 38))
    terms = [(k, float(rng.uniform(0, 0.06)) * r0, float(rng.uniform(0, 2 * np.pi))) for k in range(2, 5)]
    t = np.linspace(0, 2 * np.pi, _DENSE, endpoint=False)
    r = r0 + sum(a * np.cos(k * t + phase) for k, a, phase in terms)
    aspect = 1.0 / float(rng.uniform(2.2, 4.5))
    shape = Polygon(np.stack([r * np.cos(t), aspect * r * np.sin(t)], axis=1))
    return True, _closed(rng, shape, width, height)


def _edge(rng: np.random.Generator, width: float, height: float) -> tuple[bool, np.ndarray]:
    scale = min(width, height) / 100
    body = _blob_shape(rng, 0.8 * scale) if rng.random() < 0.5 else _polygon_shape(rng, 0.8 * scale)
    outline = _outline(body)
    placed = None if outline is None else _place(rng, Polygon(outline), width, height)
    if placed is None:
        raise ContourError("does not fit")
    x0, y0, x1, y1 = placed.bounds
    gap = float(rng.uniform(*EDGE_MARGIN_MM))
    side = int(rng.integers(4))  # bottom, right, top, left
    dx = (0.0, width - gap - x1, 0.0, gap - x0)[side]
    dy = (gap - y0, 0.0, height - gap - y1, 0.0)[side]
    points = _outline(shapely.affinity.translate(placed, dx, dy))
    if points is None:
        raise ContourError("does not fit")
    return True, points


def _closed(rng: np.random.Generator, shape, width: float, height: float) -> np.ndarray:
    outline = _outline(shape)
    placed = None if outline is None else _place(rng, Polygon(outline), width, height)
    points = None if placed is None else _outline(placed)
    if points is None:
        raise ContourError("does not fit")
    return points


def _open(rng: np.random.Generator, width: float, height: float) -> tuple[bool, np.ndarray]:
    """A cubic Bezier from a point on one edge to a point on another (or the same, far enough along),
    bending through the sheet."""

    def on_edge(side: int) -> np.ndarray:
        u = float(rng.uniform(0.15, 0.85))
        return np.array([(u * width, 0.0), (width, u * height), (u * width, height), (0.0, u * height)][side])

    first = int(rng.integers(4))
    second = int(rng.integers(4))
    p0, p3 = on_edge(first), on_edge(second)
    if np.linalg.norm(p3 - p0) < 0.3 * min(width, height):
        raise ContourError("ends too close")
    inward = {0: (0, 1), 1: (-1, 0), 2: (0, -1), 3: (1, 0)}
    depth = float(rng.uniform(0.2, 0.5)) * min(width, height)
    p1 = p0 + depth * np.array(inward[first]) + rng.uniform(-15, 15, 2)
    p2 = p3 + depth * np.array(inward[second]) + rng.uniform(-15, 15, 2)
    t = np.linspace(0, 1, _DENSE)[:, None]
    curve = (1 - t) ** 3 * p0 + 3 * (1 - t) ** 2 * t * p1 + 3 * (1 - t) * t**2 * p2 + t**3 * p3
    on_sheet = (curve >= 0).all() and (curve <= [width, height]).all()
    middle = curve[_DENSE // 20 : -_DENSE // 20]  # clear of the edges but where it enters and leaves
    clear = (middle > 1.0).all() and (middle < [width - 1.0, height - 1.0]).all()
    if not (on_sheet and clear) or not LineString(curve).is_simple:
        raise ContourError("leaves the sheet or crosses itself")
    return False, curve


_DRAW = {
    "blob": _blob, "polygon": _polygon, "notched": _notched, "open": _open, "elongated": _elongated,
    "edge": _edge,
}  # fmt: skip


def generated(spec: str, config: SimConfig | None = None) -> list[Contour] | None:
    """The contours a generated spec names (:data:`GENERATED_SPEC`: one contour, or the first N of a split),
    drawn on ``config``'s sheet; None where ``spec`` is not one.

    Raises:
        ValueError: a generated spec with an unknown split, or a kind that is not its index's.
    """
    match = GENERATED_SPEC.fullmatch(spec.strip()) if isinstance(spec, str) else None
    if match is None:
        return None
    split, seed = match["split"], int(match["seed"])
    if split not in SPLITS:
        raise ValueError(f"contour {spec!r}: the split is one of {', '.join(SPLITS)} (got {split!r})")
    config = config or SimConfig()
    if match["count"] is not None:
        if int(match["count"]) > MAX_CONTOURS:
            raise ValueError(
                f"contour {spec!r}: at most {MAX_CONTOURS} contours of a split (gen-{split}-{seed}:"
                f"{MAX_CONTOURS}); give fewer"
            )
        return generate_contours(int(match["count"]), split, seed, config)
    index, kind = int(match["index"]), match["kind"]
    if kind in EXTRA_KINDS:  # drawn where asked: any index
        return [_contour(index, split, seed, config, kind)]
    if kind != KINDS[index % len(KINDS)]:
        raise ValueError(
            f"contour {spec!r}: contour {index} of a split is a {KINDS[index % len(KINDS)]} "
            f"(gen-{split}-{seed}-{index:04d}-{KINDS[index % len(KINDS)]})"
        )
    return [_contour(index, split, seed, config, kind)]


def resolve_contour(spec: Any, config: SimConfig | None = None, where: str = "contour") -> Contour:
    """The one contour ``spec`` names, wherever a contour is given (a job, the env's options, a run's saved
    settings):

    - a :class:`~warpcut.contours.Contour`: itself;
    - its JSON object ``{name, closed, points[, sheet_size]}``: read (its sheet: ``sheet_size``, else
      ``config``'s; errors name ``where``);
    - a generated contour's name (:data:`GENERATED_SPEC`, one contour): drawn on ``config``'s sheet;
    - a built-in name or a ``.json``/``.svg`` file: :func:`~warpcut.contours.load_contour`.

    ``config`` defaults to the default sheet.
    """
    if isinstance(spec, Contour):
        return spec
    if isinstance(spec, dict):
        config = config or SimConfig()
        sheet = spec.get("sheet_size", (config.width_mm, config.height_mm))
        if not (isinstance(sheet, list | tuple) and len(sheet) == 2 and all(is_number(v) for v in sheet)):
            raise ValueError(f"{where}: sheet_size: give [width_mm, height_mm] (got {sheet!r})")
        return contour_from_json(spec, where, tuple(float(v) for v in sheet))
    drawn = generated(spec, config)
    if drawn is None:
        return load_contour(spec)
    if len(drawn) != 1:
        raise ValueError(
            f"{where}: {spec!r} names {len(drawn)} contours; give one (gen-SPLIT-SEED-INDEX-KIND)"
        )
    return drawn[0]


def resolve_specs(specs: str | Sequence[str], config: SimConfig | None = None) -> list[tuple[str, Contour]]:
    """``(spec, contour)`` for each contour that ``specs`` names (one string or several, comma-separated
    allowed), in order: built-in names, contour files, ``all`` (the built-in suite, after any other given) and
    generated specs (:data:`GENERATED_SPEC`: one contour, or the first N of a split, drawn on ``config``'s
    sheet). Two contours of one name are refused: their runs and plots would share files."""
    specs = [specs] if isinstance(specs, str) else specs
    names = [s.strip() for arg in specs for s in arg.split(",") if s.strip()]
    if not names:
        raise ValueError("contours: give at least one contour name or file, or 'all'")
    drawn = {name: generated(name, config) for name in names}
    if not any(drawn.values()):
        return _named_contours(names)  # its own checks: 'all', two contours of one name
    out: list[tuple[str, Contour]] = []
    for name in names:
        out += [(c.name, c) for c in drawn[name]] if drawn[name] is not None else _named_contours([name])
    seen: set[str] = set()
    for _, contour in out:
        if contour.name in seen:
            raise ValueError(f"contours: {contour.name!r} is given twice; give it once")
        seen.add(contour.name)
    return out


def _named_contours(names: list[str]) -> list[tuple[str, Contour]]:
    """``(name, contour)`` for built-in names and contour files; ``all``: the built-in suite (after any
    other given)."""
    if "all" in names:
        names = [s for s in names if s != "all"] + [n for n in builtin_names() if n not in names]
    if not names:
        raise ValueError("contours: give at least one contour name or file, or 'all'")
    named = [(s, load_contour(s)) for s in names]
    seen: dict[str, str] = {}
    for spec, contour in named:
        key = safe_name(contour.name)
        if key in seen:
            fix = "give it once" if spec == seen[key] else "rename one in its file"
            raise ValueError(
                f"contours: {seen[key]!r} and {spec!r} are both named {contour.name!r} (their runs and plots "
                f"would share files); {fix}"
            )
        seen[key] = spec
    return named
