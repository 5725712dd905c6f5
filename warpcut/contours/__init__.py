"""Cutting contours: the validated :class:`Contour` type, loading from files, and the built-in suite.

Units are millimetres, in material (rest) coordinates on the sheet: origin at its lower-left corner, x to
the right and y up. See :mod:`warpcut.contours.contour` for what a valid contour is and which simulation
grids resolve it, :mod:`warpcut.contours.loaders` for the file formats, :mod:`warpcut.contours.suite` for
the built-in shapes and :mod:`warpcut.contours.polyline` for arc-length resampling.
"""

from warpcut.contours.contour import (
    DEFAULT_SHEET_MM,
    EDGE_REACH_MM,
    Contour,
    ContourError,
    check_resolution,
    validate,
)
from warpcut.contours.loaders import SVG_CHORD_MM, contour_from_json, load_contour
from warpcut.contours.polyline import arc_lengths, polyline_length, resample_polyline, ring
from warpcut.contours.suite import BUILTIN_SPACING_MM, builtin_contours, builtin_names

__all__ = [
    "BUILTIN_SPACING_MM",
    "DEFAULT_SHEET_MM",
    "EDGE_REACH_MM",
    "SVG_CHORD_MM",
    "Contour",
    "ContourError",
    "arc_lengths",
    "builtin_contours",
    "check_resolution",
    "builtin_names",
    "contour_from_json",
    "load_contour",
    "polyline_length",
    "resample_polyline",
    "ring",
    "validate",
]
