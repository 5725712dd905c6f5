"""Loading contours from files, or the built-in suite by name.

* ``.json``: ``{"name": "my-shape", "closed": true, "points": [[x_mm, y_mm], ...]}``; ``name`` is optional
  (default: the file stem).
* ``.svg``: the ``d`` attribute of the first ``<path>`` element. User units are millimetres and y is
  flipped (``y_mm = sheet_height - y_svg``) because SVG's y axis points down. A path ending with ``Z`` is
  closed. Curves are flattened into segments of at most :data:`SVG_CHORD_MM` (one that leaves the sheet
  is refused first); arcs (``A``) are not supported. The ``viewBox`` origin is the sheet's corner; its
  size is ignored.

Every loaded contour goes through :func:`~warpcut.contours.contour.validate`.
"""

from __future__ import annotations

import json
import math
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from warpcut.contours.contour import DEFAULT_SHEET_MM, Contour, ContourError, check_sheet_size, validate
from warpcut.contours.suite import builtin_contours, builtin_names

SVG_CHORD_MM = 0.5
"""Longest segment an SVG curve is flattened into (mm)."""


def load_contour(
    name_or_path: str | os.PathLike, sheet_size: tuple[float, float] = DEFAULT_SHEET_MM
) -> Contour:
    """A built-in contour by name, or one read from a ``.json`` or ``.svg`` file.

    Args:
        name_or_path: A name from :func:`builtin_names` (checked first) or a path to a contour file.
        sheet_size: Sheet width and height (mm).

    Raises:
        ContourError: for an unknown name, a missing or unsupported file, or an invalid contour.
    """
    key = os.fspath(name_or_path)
    if key in builtin_names():
        return builtin_contours(sheet_size)[key]
    path = Path(key)
    suffix = path.suffix.lower()
    if path.is_file() and suffix == ".json":
        return _load_json(path, sheet_size)
    if path.is_file() and suffix == ".svg":
        return _load_svg(path, sheet_size)
    why = "no such file" if not path.is_file() else f"'{path.suffix}' is not a supported file type"
    raise ContourError(
        f"unknown contour {key!r}: not a built-in name (known: {', '.join(builtin_names())}) and {why}; "
        "give a built-in name or a path to a .json or .svg contour"
    )


def _load_json(path: Path, sheet_size: tuple[float, float]) -> Contour:
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:  # recursion: too deep
        raise ContourError(f"contour file {str(path)!r}: cannot read it as JSON ({exc})") from None
    return contour_from_json(data, f"contour file {str(path)!r}", sheet_size, default_name=path.stem)


def contour_from_json(
    data: object,
    where: str,
    sheet_size: tuple[float, float] = DEFAULT_SHEET_MM,
    default_name: str | None = None,
) -> Contour:
    """A contour from its JSON object (``{"name", "closed", "points"}``: a contour file, or what
    :meth:`Contour.to_json` writes), validated; errors name ``where``.

    Raises:
        ContourError: naming the field and the fix.
    """
    if not isinstance(data, dict):
        raise ContourError(
            f'{where}: expected a JSON object {{"name": ..., "closed": true/false, "points": [[x, y], ...]}}'
        )
    name = data.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise ContourError(f"{where}: field 'name' must be a non-empty string (got {name!r})")
    if not isinstance(data.get("closed"), bool):
        raise ContourError(
            f"{where}: field 'closed' is required and must be true or false "
            f"(got {data.get('closed', 'nothing')!r})"
        )
    points = data.get("points")
    if not isinstance(points, list) or not all(
        isinstance(p, list) and len(p) == 2 and all(_is_number(v) for v in p) for p in points
    ):
        raise ContourError(
            f"{where}: field 'points' is required and must be a list of [x_mm, y_mm] number pairs"
        )
    if len(points) < 3:
        raise ContourError(
            f"{where}: field 'points' has {len(points)} point(s); give at least 3 [x_mm, y_mm] pairs"
        )
    try:
        xy = np.array(points, dtype=np.float64)
    except OverflowError:  # an integer beyond float range; floats that large already read as inf
        raise ContourError(f"{where}: field 'points' has a number too large for a coordinate in mm") from None
    return _validated(where, name, data["closed"], xy, sheet_size)


def _validated(
    where: str, name: str, closed: bool, points: np.ndarray, sheet_size: tuple[float, float]
) -> Contour:
    """:func:`validate`, its errors prefixed with ``where`` (the file or field the contour came from)."""
    try:
        return validate(name, closed, points, sheet_size)
    except ContourError as exc:
        raise ContourError(f"{where}: {exc}") from None


def _is_number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _load_svg(path: Path, sheet_size: tuple[float, float]) -> Contour:
    where = f"contour file {str(path)!r}"
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError, LookupError, ValueError) as exc:  # lookup: an unknown encoding
        raise ContourError(f"{where}: cannot read it as SVG/XML ({exc})") from None
    parents = {child: parent for parent in root.iter() for child in parent}
    element = next((e for e in root.iter() if _local_tag(e.tag) == "path"), None)
    if element is None or not element.get("d"):
        raise ContourError(f"{where}: no <path> element with a 'd' attribute; draw the contour as a path")
    node = element
    while node is not None:
        # Coordinates are read as written, so a transform would silently move or distort the contour.
        if node.get("transform"):
            raise ContourError(
                f"{where}: the path or a group around it has a transform ({node.get('transform')!r}), which "
                "is not supported; apply it to the path first (Inkscape: ungroup, then Path > Object to Path)"
            )
        node = parents.get(node)

    origin = np.zeros(2)
    if root.get("viewBox"):
        box = re.split(r"[\s,]+", root.get("viewBox").strip())
        try:
            numbers = [float(v) for v in box]
        except ValueError:
            numbers = []
        if len(numbers) != 4 or not all(math.isfinite(v) for v in numbers):
            raise ContourError(
                f"{where}: cannot read viewBox {root.get('viewBox')!r}; give four numbers: "
                "min-x min-y width height"
            )
        origin = np.array(numbers[:2])
    pieces, closed = _parse_path(where, element.get("d"))
    width, height = check_sheet_size(sheet_size)
    points = []
    for piece in pieces:
        with np.errstate(over="ignore", invalid="ignore"):
            xy = (piece - origin) * [1.0, -1.0] + [0.0, height]  # y is flipped: SVG's points down
        if not np.isfinite(xy).all():
            raise ContourError(
                f"{where}: the path reaches a coordinate too large to be a number of mm; keep it on the sheet"
            )
        if len(xy) > 1:  # a Bezier curve's control points, from the current point
            _check_curve_on_sheet(where, xy, width, height)
            points.extend(_bezier(xy)[1:])
        else:
            points.append(xy[0])
    return _validated(where, path.stem, closed, np.array(points), sheet_size)


def _check_curve_on_sheet(where: str, control: np.ndarray, width: float, height: float) -> None:
    """Refuse a curve that leaves the sheet by more than :data:`SVG_CHORD_MM` before it is flattened: its
    points could be too many to hold. Smaller excursions are flattened, and :func:`validate` judges them."""
    extremes = _bezier_extremes(control)
    outside = np.maximum(-extremes, extremes - [width, height]).max(axis=1)
    worst = int(np.argmax(outside))
    if outside[worst] > SVG_CHORD_MM:
        x, y = extremes[worst]
        raise ContourError(
            f"{where}: a curve of the path leaves the sheet by {outside[worst]:.3g} mm, reaching "
            f"({x:.6g}, {y:.6g}) mm; move it into [0, {width:g}] x [0, {height:g}] mm"
        )


def _local_tag(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


_PATH_TOKEN = re.compile(r"[A-Za-z]|[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_PATH_ARGS = {"M": 2, "L": 2, "H": 1, "V": 1, "C": 6, "S": 4, "Q": 4, "T": 2, "Z": 0}


def _parse_path(where: str, d: str) -> tuple[list[np.ndarray], bool]:
    """One SVG subpath (SVG user units, y down) as pieces and whether it ends with Z.

    Each piece is a (1, 2) array, the next vertex, or the (3, 2) or (4, 2) control points of a quadratic or
    cubic Bezier curve from the current point, flattened by the caller. Coordinates may be infinite or NaN
    where the numbers are out of range.
    """
    tokens = _PATH_TOKEN.findall(d)
    pieces: list[np.ndarray] = []
    closed = False
    pos = np.zeros(2)
    last_cubic = last_quad = None  # previous curve's last control point, reflected by S and T
    command = ""
    i = 0
    while i < len(tokens):
        if tokens[i].isalpha():
            command = tokens[i]
            i += 1
        elif command in ("", "Z", "z"):
            raise ContourError(f"{where}: path data has a number ({tokens[i]!r}) where a command is expected")
        kind = command.upper()
        if kind == "A":
            raise ContourError(
                f"{where}: SVG arcs (A/a commands) are unsupported; convert them to cubic Bezier curves "
                "first (e.g. Inkscape: Path > Object to Path, or your editor's 'convert to cubic' option)"
            )
        if kind not in _PATH_ARGS:
            raise ContourError(f"{where}: unknown SVG path command {command!r}")
        if (kind == "M" and pieces) or (kind != "M" and closed):
            raise ContourError(
                f"{where}: the path has several subpaths; give one contour per file (split the path)"
            )
        if kind != "M" and not pieces:
            raise ContourError(f"{where}: path data must start with a moveto (M or m)")
        if kind == "Z":
            closed = True
            continue
        count = _PATH_ARGS[kind]
        numbers = tokens[i : i + count]
        if len(numbers) != count or any(t.isalpha() for t in numbers):
            raise ContourError(
                f"{where}: command {command!r} needs {count} numbers; the path data is cut short"
            )
        i += count
        with np.errstate(over="ignore", invalid="ignore"):  # out-of-range numbers: the caller refuses them
            values = np.array(numbers, dtype=np.float64)
            offset = pos if command.islower() else np.zeros(2)
            if kind in ("H", "V"):
                axis = int(kind == "V")
                given = pos[None].copy()
                given[0, axis] = values[0] + offset[axis]
            else:
                given = values.reshape(-1, 2) + offset
            if kind == "S":
                given = np.vstack([pos if last_cubic is None else 2 * pos - last_cubic, given])
            elif kind == "T":
                given = np.vstack([pos if last_quad is None else 2 * pos - last_quad, given])
        pieces.append(np.vstack([pos, given]) if kind in ("C", "S", "Q", "T") else given[-1:])
        if kind == "M":
            # Pairs after a moveto are implicit linetos.
            command = "l" if command.islower() else "L"
        last_cubic = given[-2] if kind in ("C", "S") else None
        last_quad = given[-2] if kind in ("Q", "T") else None
        pos = given[-1]
    if not pieces:
        raise ContourError(f"{where}: the path has no points")
    return pieces, closed


def _bezier(control: np.ndarray) -> np.ndarray:
    """Points on a Bezier curve, from its first to its last control point, at most SVG_CHORD_MM apart."""
    degree = len(control) - 1
    # |B'(t)| <= degree * (longest control leg), which bounds each piece's arc length and so its chord.
    longest = float(np.linalg.norm(np.diff(control, axis=0), axis=1).max())
    return _bezier_at(control, np.linspace(0.0, 1.0, max(1, math.ceil(degree * longest / SVG_CHORD_MM)) + 1))


def _bezier_extremes(control: np.ndarray) -> np.ndarray:
    """The points of a quadratic or cubic Bezier curve where x or y is extremal, and its two ends; exact
    (from the roots of the derivative) and free of overflow for finite control points of any size."""
    scale = float(np.abs(control).max()) or 1.0
    unit = control / scale
    legs = np.diff(unit, axis=0)  # the derivative's control points, over the degree
    t = [0.0, 1.0]
    for d in legs.T:
        # The derivative in powers of t, highest first: linear for a quadratic, quadratic for a cubic.
        power = [d[1] - d[0], d[0]] if len(d) == 2 else [d[0] - 2 * d[1] + d[2], 2 * (d[1] - d[0]), d[0]]
        # Real parts of complex roots too: an extra point on the curve does no harm, a missed extreme would.
        t.extend(np.clip(np.roots(power).real, 0.0, 1.0))
    return _bezier_at(unit, np.array(t)) * scale


def _bezier_at(control: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(T, 2) points of the Bezier curve with these control points at the parameters ``t`` (T,)."""
    degree = len(control) - 1
    t = t[:, None]
    weights = [math.comb(degree, k) * t**k * (1 - t) ** (degree - k) for k in range(degree + 1)]
    return sum(w * c for w, c in zip(weights, control, strict=True))
