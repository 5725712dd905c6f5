"""Loading contours from files, or the built-in suite by name.

* ``.json``: ``{"name": "my-shape", "closed": true, "points": [[x_mm, y_mm], ...]}``; ``name`` is optional
  (default: the file stem).
* ``.svg``: the first shape drawn, in document order: a ``<path>`` (one subpath), ``<circle>``,
  ``<ellipse>``, ``<rect>`` (rounded corners too), ``<polygon>``, ``<polyline>`` or ``<line>``, read with
  `svgelements <https://github.com/meerk40t/svgelements>`_: transforms, ``<use>``, nested ``<svg>``, arcs
  and lengths with units all apply. A path ending with ``Z`` and the closed shapes (circle, ellipse, rect,
  polygon) are closed contours. Millimetres:

  - the root ``<svg>`` with a ``viewBox`` and a ``width`` and ``height`` both in a physical unit (mm, cm,
    Q, in, pt, pc): the viewBox maps onto that size as SVG says (``preserveAspectRatio`` too; lengths with
    units inside follow CSS, 96 px per inch). ``width="100mm" height="100mm" viewBox="0 0 200 200"``: a
    user unit is 0.5 mm.
  - otherwise (no viewBox, or width/height missing, unitless, in px or %): one user unit is one mm, the
    viewBox's origin is the sheet's corner and its size is ignored; a length given with a unit inside is
    converted to mm (``r="5mm"`` is 5, ``r="1in"`` 25.4).

  The page's top-left corner is the sheet's top-left corner, and y is flipped (``y_mm = sheet_height -
  y_page_mm``) because SVG's y axis points down. Curves and arcs are flattened into segments of at most
  :data:`SVG_CHORD_MM`; a curve that leaves the sheet is refused first, so that huge coordinates never
  make many points. Path data is read to its end: a command cut short or unknown is an error, never a
  silently shorter contour.

Every loaded contour goes through :func:`~warpcut.contours.contour.validate`.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import stat
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from warpcut.contours.contour import (
    DEFAULT_SHEET_MM,
    MAX_POINTS,
    Contour,
    ContourError,
    check_sheet_size,
    validate,
)
from warpcut.contours.suite import builtin_contours, builtin_names

SVG_CHORD_MM = 0.5
"""Longest segment an SVG curve is flattened into (mm)."""
MAX_FILE_BYTES = 64 * 2**20
"""Largest contour file read (64 MiB): a contour sampled every 0.1 mm along 10 m, as JSON, is ~2.5 MB; a
larger file is refused before it is read (a 4 GB one would take seconds and gigabytes of memory)."""


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
    kind = file_kind(path)
    if kind == "file" and suffix in (".json", ".svg"):
        _check_file_size(path)
    if kind == "file" and suffix == ".json":
        return _load_json(path, sheet_size)
    if kind == "file" and suffix == ".svg":
        return _load_svg(path, sheet_size)
    if kind not in (None, "file", "directory"):  # never opened: a FIFO would block, /dev/zero never end
        raise ContourError(
            f"contour {key!r} is not a regular file ({kind}); give a built-in name or a path to a .json or "
            ".svg contour file"
        )
    why = {
        None: "no such file",
        "file": f"'{path.suffix}' is not a supported file type",
        "directory": "a directory, not a contour file",
    }[kind]
    raise ContourError(
        f"unknown contour {key!r}: not a built-in name (known: {', '.join(builtin_names())}) and {why}; "
        "give a built-in name or a path to a .json or .svg contour"
    )


def file_kind(path: Path) -> str | None:
    """What ``path`` is, following symbolic links: ``"file"`` (a regular file), ``"directory"``, another
    kind in words (``"a FIFO"``, ``"a character device"``, ...: never opened, so reading a FIFO cannot block
    and ``/dev/zero`` is not read forever), or None where nothing is there (or it cannot be looked at)."""
    try:
        mode = path.stat().st_mode
    except (OSError, ValueError):  # ValueError: a NUL byte in the name
        return None
    if stat.S_ISREG(mode):
        return "file"
    if stat.S_ISDIR(mode):
        return "directory"
    kinds = {
        stat.S_ISFIFO: "a FIFO",
        stat.S_ISCHR: "a character device",
        stat.S_ISBLK: "a block device",
        stat.S_ISSOCK: "a socket",
    }
    return next((name for test, name in kinds.items() if test(mode)), "not a file")


def _check_file_size(path: Path) -> None:
    """Refuse a contour file larger than :data:`MAX_FILE_BYTES`, before reading it."""
    try:
        size = path.stat().st_size
    except OSError:
        return  # said when it is read
    if size > MAX_FILE_BYTES:
        raise ContourError(
            f"contour file {str(path)!r}: {size / 2**20:,.0f} MiB, larger than the "
            f"{MAX_FILE_BYTES // 2**20} MiB a contour file may be (not read); give the contour sampled more "
            "coarsely"
        )


def _load_json(path: Path, sheet_size: tuple[float, float]) -> Contour:
    try:
        with open(path, "rb") as f:  # at most the limit: a file that grew since it was checked is refused
            raw = f.read(MAX_FILE_BYTES + 1)
        if len(raw) > MAX_FILE_BYTES:
            _check_file_size(path)
        data = json.loads(raw.decode("utf-8"))
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
    box = _view_box(where, root)
    size = _physical_size(where, root)
    if box is not None and size is not None:  # the viewBox maps onto a physical size, as SVG says
        if box[2] <= 0 or box[3] <= 0:
            raise ContourError(
                f"{where}: viewBox {root.get('viewBox')!r} has a width or height <= 0; give positive sizes"
            )
        scale, offset = _view_box_transform(box, size, root.get("preserveAspectRatio"))
        ppi = 96.0  # CSS: lengths with units inside the drawing, in user units
    else:  # one user unit is one mm; the viewBox's origin is the sheet's corner, its size is ignored
        scale, offset = np.ones(2), -np.array(box[:2] if box is not None else (0.0, 0.0))
        ppi = 25.4  # a length given in mm inside the drawing is that many user units
    # svgelements reads the drawing in the root's user units; the root's mapping to mm is applied here.
    for name in ("width", "height", "viewBox", "preserveAspectRatio"):
        root.attrib.pop(name, None)
    viewport = None if box is None else box[2:]
    _check_expanded_size(where, root)
    _check_point_count(where, root)
    for element in root.iter():
        if _local_tag(element.tag) == "path" and element.get("d"):
            _check_path_data(where, element.get("d"))
        _check_sizes(where, element)
        _check_transform(where, element)
    shape = _first_shape(where, root, ppi, viewport)
    pieces, closed = _shape_pieces(where, shape)
    width, height = check_sheet_size(sheet_size)
    points = []
    for piece in pieces:
        with np.errstate(over="ignore", invalid="ignore"):
            xy = (piece * scale + offset) * [1.0, -1.0] + [0.0, height]  # y is flipped: SVG's points down
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


def _view_box(where: str, root: ET.Element) -> tuple[float, float, float, float] | None:
    """The root's ``viewBox`` (min-x, min-y, width, height), or None without one."""
    if not root.get("viewBox"):
        return None
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
    if 0 < min(numbers[2:]) < _TINIEST_VIEW_BOX:
        raise ContourError(
            f"{where}: viewBox {root.get('viewBox')!r} is too small to compute with (a width or height under "
            f"{_TINIEST_VIEW_BOX:g} user units: the squares of its lengths underflow); scale the drawing up"
        )
    return numbers[0], numbers[1], numbers[2], numbers[3]


_TINIEST_VIEW_BOX = 1e-100
"""The smallest viewBox width or height read: the geometry squares lengths, which underflow below 1e-154."""


_MM_PER = {"mm": 1.0, "cm": 10.0, "q": 0.25, "in": 25.4, "pt": 25.4 / 72.0, "pc": 25.4 / 6.0}
"""Millimetres per physical CSS unit (``width="100mm"``); px and plain numbers are not physical."""
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
"""A number as SVG writes one."""
_LENGTH = re.compile(rf"\s*({_NUMBER})\s*([A-Za-z]+)\s*")


_SCREEN_UNITS = ("px", "em", "ex", "rem", "ch", "vw", "vh", "vmin", "vmax")
"""CSS's units that are not physical lengths: the drawing's user units are taken as mm."""


def _physical_size(where: str, root: ET.Element) -> tuple[float, float] | None:
    """The root's ``width`` and ``height`` in mm where both are in a physical unit (mm, cm, Q, in, pt, pc);
    None otherwise. A unit CSS does not have (``0.1m``) is refused, not ignored."""
    size = []
    for name in ("width", "height"):
        match = _LENGTH.fullmatch(root.get(name) or "")
        unit = match.group(2).lower() if match is not None else None
        if unit is not None and unit not in _MM_PER and unit not in _SCREEN_UNITS:
            units = ", ".join(u if u != "q" else "Q" for u in _MM_PER)
            raise ContourError(
                f"{where}: the svg's {name} {root.get(name)!r} has a unit SVG does not have "
                f"({match.group(2)!r}); give it in {units} (or px: a user unit is a mm)"
            )
    for name in ("width", "height"):
        match = _LENGTH.fullmatch(root.get(name) or "")
        if match is None or match.group(2).lower() not in _MM_PER:
            return None
        value = float(match.group(1)) * _MM_PER[match.group(2).lower()]
        if not (math.isfinite(value) and value > 0):
            raise ContourError(f"{where}: the svg's {name} {root.get(name)!r} must be a positive length")
        size.append(value)
    return size[0], size[1]


def _view_box_transform(
    box: tuple[float, float, float, float], size: tuple[float, float], aspect: str | None
) -> tuple[np.ndarray, np.ndarray]:
    """``(scale, offset)``: user units to mm on the page, ``mm = user * scale + offset``, for a viewBox
    shown in a ``size`` (mm) viewport with ``preserveAspectRatio`` ``aspect`` (SVG 2, 8.2; an unreadable
    value is the default, ``xMidYMid meet``)."""
    (x, y, w, h), (width, height) = box, size
    scale = np.array([width / w, height / h])
    words = (aspect or "").replace(",", " ").split()
    words = words[1:] if words[:1] == ["defer"] else words
    align = words[0] if words else "xMidYMid"
    aligns = [f"x{a}Y{b}" for a in ("Min", "Mid", "Max") for b in ("Min", "Mid", "Max")]
    if align not in ("none", *aligns):
        align, words = "xMidYMid", []
    if align != "none":
        scale[:] = scale.max() if words[1:2] == ["slice"] else scale.min()
    offset = -np.array([x, y]) * scale
    spare = np.array([width, height]) - np.array([w, h]) * scale
    for axis, name in enumerate(("x", "Y")):
        share = {"Min": 0.0, "Mid": 0.5, "Max": 1.0}.get(align.partition(name)[2][:3], 0.0)
        offset[axis] += share * spare[axis]
    return scale, offset


_SIZES = {"circle": ("r",), "ellipse": ("rx", "ry"), "rect": ("width", "height", "rx", "ry")}
"""The shapes' size attributes, which must be lengths >= 0 (svgelements would take a negative radius's
absolute value, and skip an unreadable one without a word)."""
_SIZE = re.compile(rf"\s*({_NUMBER})\s*([A-Za-z]*|%)\s*")


def _check_sizes(where: str, element: ET.Element) -> None:
    """Refuse a circle, ellipse or rect whose size attribute is negative or not a length."""
    tag = _local_tag(element.tag)
    for name in _SIZES.get(tag, ()):
        value = element.get(name)
        if value is None or value.strip() == "auto":
            continue
        match = _SIZE.fullmatch(value)
        if match is None:
            raise ContourError(
                f"{where}: <{tag}> {name}={value!r} is not a length; give a number (with a unit)"
            )
        if float(match.group(1)) < 0:
            raise ContourError(
                f"{where}: <{tag}> {name}={value!r} is negative; a {tag}'s {name} must be >= 0"
            )


_TRANSFORM = re.compile(r"\s*(matrix|translate|scale|rotate|skewX|skewY)\s*\(([^)]*)\)\s*,?")
_TRANSFORM_ARGS = {
    "matrix": (6,),
    "translate": (1, 2),
    "scale": (1, 2),
    "rotate": (1, 3),
    "skewX": (1,),
    "skewY": (1,),
}
"""How many numbers each SVG transform function takes."""
_NUMBERS = re.compile(_NUMBER)


def _check_transform(where: str, element: ET.Element) -> None:
    """Refuse a ``transform`` that is not a list of SVG transform functions with numbers (svgelements fails
    on one deep inside, or skips it), or that collapses the drawing (a zero scale or a singular matrix)."""
    value = element.get("transform")
    if value is None:
        return
    tag, pos = _local_tag(element.tag), 0
    fix = "give matrix(), translate(), scale(), rotate(), skewX() or skewY() with numbers"
    while pos < len(value.rstrip()):
        match = _TRANSFORM.match(value, pos)
        numbers = None if match is None else _NUMBERS.findall(match.group(2))
        only_numbers = match is not None and re.fullmatch(r"[\s,]*", _NUMBERS.sub(" ", match.group(2)))
        if not only_numbers or len(numbers) not in _TRANSFORM_ARGS[match.group(1)]:
            raise ContourError(f"{where}: <{tag}> transform={value!r} cannot be read; {fix}")
        name, args = match.group(1), [float(v) for v in numbers]
        a, b, c, d = (
            args[:4] if name == "matrix" else (args[0], 0, 0, args[-1]) if name == "scale" else (1, 0, 0, 1)
        )
        if a * d - b * c == 0:
            raise ContourError(
                f"{where}: <{tag}> transform={value!r} collapses the drawing to a line or a point"
            )
        pos = match.end()


def _check_path_data(where: str, d: str) -> None:
    """Refuse malformed path data, which svgelements would cut short without a word: its own lexer, run
    to the end of ``d``."""
    import svgelements as se

    text = d.strip(" \t\n\r\f")
    if text[:1] not in ("M", "m", ""):
        raise ContourError(f"{where}: path data must start with a moveto (M or m), not {text[:12]!r}")
    lexer = se.SVGLexicalParser()
    try:
        lexer.parse(se.Path(), d)
        failed = False
    except Exception:  # svgelements' lexer raises ValueError, or worse on odd input: all are bad data
        failed = True
    rest = d[lexer.pos :]
    if failed or rest.strip(" \t\n\r\f,"):
        near = rest.lstrip(" \t\n\r\f,")[:16] or d[max(0, lexer.pos - 16) : lexer.pos]
        raise ContourError(
            f"{where}: cannot read the path data at character {lexer.pos} (near {near!r}): a command is cut "
            "short or unknown; give SVG path commands (M, L, H, V, C, S, Q, T, A, Z) with their numbers"
        )


MAX_SVG_ELEMENTS = 20_000
"""The most elements an SVG contour file may draw once its ``<use>`` references are instantiated: nested
``<use>`` (7 levels of 10 in 2 kB) expand to millions, which the parser would take hours to instantiate
(20,000 take it about 3 s)."""


def _check_expanded_size(where: str, root: ET.Element) -> None:
    """Refuse a drawing whose ``<use>`` references, instantiated, would make more than
    :data:`MAX_SVG_ELEMENTS` elements, or refer to themselves, before anything is instantiated."""
    by_id = {e.get("id"): e for e in root.iter() if e.get("id")}
    sizes: dict[int, int] = {}
    open_: set[int] = set()
    pending: list[tuple[ET.Element, bool]] = [(root, False)]
    while pending:  # post-order without recursion: a file may nest deeper than Python recurses
        element, children_done = pending.pop()
        key = id(element)
        if key in sizes:
            continue
        href = element.get("href") or element.get("{http://www.w3.org/1999/xlink}href") or ""
        target = by_id.get(href[1:]) if _local_tag(element.tag) == "use" and href.startswith("#") else None
        parts = [*element, *([target] if target is not None else [])]
        if not children_done:
            if key in open_:
                raise ContourError(f"{where}: a <use> refers to an element that holds it; draw it out")
            open_.add(key)
            pending.append((element, True))
            pending.extend((part, False) for part in parts)
            continue
        sizes[key] = 1 + sum(sizes[id(part)] for part in parts)
        if sizes[key] > MAX_SVG_ELEMENTS:
            raise ContourError(
                f"{where}: its <use> references expand to more than {MAX_SVG_ELEMENTS:,} elements; draw the "
                "contour as one shape"
            )


def _check_point_count(where: str, root: ET.Element) -> None:
    """Refuse, before the parser reads them, path data and point lists whose numbers alone make more than
    :data:`~warpcut.contours.contour.MAX_POINTS` points (each point takes at most six numbers, a cubic
    curve's): the contour would be refused after seconds of parsing and flattening."""
    for element in root.iter():
        for name in ("d", "points"):
            numbers = sum(1 for _ in re.finditer(_NUMBER, element.get(name) or ""))
            if numbers > 6 * MAX_POINTS:
                raise ContourError(
                    f"{where}: a <{_local_tag(element.tag)}> holds {numbers:,} numbers, more than "
                    f"{MAX_POINTS:,} points' worth (the most warpcut plans); resample the contour (e.g. a "
                    "point every 0.5 mm)"
                )


def _first_shape(where: str, root: ET.Element, ppi: float, viewport: tuple[float, float] | None):
    """The first shape drawn (in document order, transforms applied, ``<use>`` instantiated), read by
    svgelements from ``root``."""
    import svgelements as se

    source = io.BytesIO(ET.tostring(root))
    extent = {} if viewport is None else {"width": viewport[0], "height": viewport[1]}
    try:
        svg = se.SVG.parse(source, reify=True, ppi=ppi, **extent)
        shape = next((e for e in svg.elements() if isinstance(e, se.Shape)), None)
    except Exception as exc:  # any failure of the third-party parser on this input: unreadable
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ContourError(f"{where}: cannot read the drawing ({reason})") from None
    if shape is None:
        raise ContourError(
            f"{where}: no shape to read (<path>, <circle>, <ellipse>, <rect>, <polygon>, <polyline> or "
            "<line>, drawn: not in <defs> nor hidden); draw the contour as one"
        )
    return shape


def _shape_pieces(where: str, shape) -> tuple[list[np.ndarray], bool]:
    """One subpath of ``shape`` (user units, y down) as pieces, and whether it is closed.

    Each piece is a (1, 2) array, the next vertex, or the (3, 2) or (4, 2) control points of a quadratic or
    cubic Bezier curve from the current point (arcs become cubic curves), flattened by the caller.
    Coordinates may be infinite or NaN where the numbers are out of range.
    """
    import svgelements as se

    path = se.Path(shape)
    path.reify()  # a rect or an ellipse under a rotation keeps its transform until it is a path
    pieces: list[np.ndarray] = []
    closed = False
    for segment in path:
        if isinstance(segment, se.Close):
            closed = bool(pieces)
            continue
        if closed or (isinstance(segment, se.Move) and pieces):
            raise ContourError(
                f"{where}: the path has several subpaths; give one contour per file (split the path)"
            )
        if isinstance(segment, se.Move | se.Line):
            pieces.append(_xy([segment.end]))
        elif isinstance(segment, se.QuadraticBezier):
            pieces.append(_xy([segment.start, segment.control, segment.end]))
        elif isinstance(segment, se.CubicBezier):
            pieces.append(_xy([segment.start, segment.control1, segment.control2, segment.end]))
        elif isinstance(segment, se.Arc):
            pieces.extend(_arc_pieces(segment))
    if not pieces:
        raise ContourError(f"{where}: the path has no points")
    return pieces, closed


def _arc_pieces(arc) -> list[np.ndarray]:
    """An elliptical arc as cubic Bezier pieces (at most 30 degrees each: a dozen for a whole ellipse), or
    a straight line (SVG's rule for a zero radius); an arc whose parameters overflow (radii beyond about
    1e150) is one non-finite piece, which the caller refuses as out of range."""
    parameters = _xy([arc.start, arc.end, arc.center, arc.prx, arc.pry])
    if not (np.isfinite(parameters).all() and math.isfinite(arc.sweep)):
        return [np.full((4, 2), np.inf)]  # refused by the caller: a coordinate too large
    curves = list(arc.as_cubic_curves())
    if not curves:
        return [_xy([arc.end])]
    return [_xy([c.start, c.control1, c.control2, c.end]) for c in curves]


def _xy(points) -> np.ndarray:
    """svgelements points as an (N, 2) float64 array (None, a missing point, is NaN)."""
    return np.array([(np.nan, np.nan) if p is None else (p.x, p.y) for p in points], dtype=np.float64)


def _local_tag(tag: str) -> str:
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


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
