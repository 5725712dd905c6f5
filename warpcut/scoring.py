"""Cut quality: the symmetric difference between the intended and the achieved region, two ways.

Both are measured in *material* coordinates (the sheet's rest layout, :attr:`SheetGrid.material`), so a
cut is judged by which material it went through, however the tensioned sheet was deformed while it was
cut. Errors are areas in mm^2 and in vertices (mm^2 over :attr:`SheetGrid.vertex_area_mm2`, the paper's
unit). The intended region X is the inside of a closed contour, or the piece an open contour cuts off
the sheet (:meth:`warpcut.contours.Contour.intended_region`).

* **path** (the paper's, Section III-B, and the default): Y is the region enclosed by the *cut path*,
  where the scissors actually went through the material. The simulator maps the tip of every cutting
  update into material coordinates (:meth:`warpcut.sim.simulator.Simulator.trace_path`); the points are put
  in contour order (by the arc length of the contour point each was meant to cut), gaps bridged with
  straight lines, and closed: as a ring for a closed contour, for an open one along the sheet's edges on
  the intended side. Self-intersections are repaired (``shapely.make_valid``). The error is the area of
  X xor Y: graded (a cut that wanders by d costs about perimeter x d) and independent of whether the
  piece came free. Tip positions off the sheet or over a hole are dropped (``dropped_fraction``).
* **separated**: Y is the material that actually came free. The alive vertices are split into pieces by
  4-connectivity; the piece holding the most alive vertices outside X is the sheet and every other alive
  vertex is separated. Removed vertices (the kerf) take the label of their nearest alive vertex. Regions
  are vertex sets; each vertex stands for an ``hx * hy`` cell. Nearly all-or-nothing: a cut that misses
  by one vertex leaves the piece attached and scores its whole area. ``separated`` says whether the
  intended piece came free (at least half of X's vertices were separated).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from concurrent import futures
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import shapely
from scipy import ndimage

from warpcut.sim.config import SCORES, SheetGrid

Region = shapely.Polygon | shapely.MultiPolygon


@dataclass
class Separation:
    """Separated-material error per env; ``B`` envs on a grid of ``V = ny * nx`` vertices."""

    error_vertices: np.ndarray
    """(B,) float64: vertices in exactly one of the intended and separated regions."""
    error_mm2: np.ndarray
    """(B,) float64: ``error_vertices * grid.vertex_area_mm2`` (mm^2)."""
    missed_vertices: np.ndarray
    """(B,) float64: vertices intended but not separated."""
    excess_vertices: np.ndarray
    """(B,) float64: vertices separated but not intended."""
    achieved: np.ndarray
    """(B, V) bool: vertices separated from the sheet."""
    intended: np.ndarray
    """(V,) bool for one region shared by all envs, or (B, V) bool for one region per env."""

    @property
    def separated(self) -> np.ndarray:
        """(B,) bool: the intended piece came free (at least half of its vertices were separated)."""
        intended = np.broadcast_to(self.intended, self.achieved.shape)
        return (self.achieved & intended).sum(axis=1) >= 0.5 * intended.sum(axis=1)


@dataclass
class Score:
    """Per-env cut error under both scores; ``error_*`` is the one ``metric`` names (tables, rewards)."""

    metric: str
    """``"path"`` or ``"separated"``: what ``error_vertices`` and ``error_mm2`` measure."""
    error_vertices: np.ndarray
    """(B,) float64: the ``metric``'s error in vertices (mm^2 / vertex area)."""
    error_mm2: np.ndarray
    """(B,) float64: the ``metric``'s error (mm^2)."""
    path_error_mm2: np.ndarray
    """(B,) float64: the path score, area of X xor (region enclosed by the cut path) (mm^2)."""
    path_error_vertices: np.ndarray
    """(B,) float64: ``path_error_mm2`` in vertices."""
    dropped_fraction: np.ndarray
    """(B,) float64: share of the cutting updates whose tip lay off the sheet or over a hole (dropped
    from the path and bridged); NaN for an env that never cut."""
    cut_paths: list[np.ndarray]
    """Per env, the (K, 2) material points the scissors went through, in contour order (mm)."""
    cut_regions: list
    """Per env, the region the cut path encloses (a shapely geometry, possibly empty)."""
    separation: Separation
    """The separated-material score (``missed_vertices``, ``achieved`` ...)."""
    diverged: np.ndarray | None = None
    """(B,) bool: the env's simulation diverged (:meth:`warpcut.task.CuttingTask.diverged`), so it was not
    scored: its errors are NaN (never a number to average in); None: all fine."""

    def mark_diverged(self, diverged: np.ndarray) -> Score:
        """This score with the envs ``diverged`` (B,) bool blanked: their errors, missed and excess
        vertices and dropped fraction NaN, nothing achieved (``separated`` False), ``diverged`` True."""
        diverged = np.asarray(diverged, dtype=bool).reshape(-1)
        if not diverged.any():
            return dataclasses.replace(self, diverged=diverged)

        def blank(values: np.ndarray) -> np.ndarray:
            return np.where(diverged, np.nan, np.asarray(values, dtype=np.float64))

        sep = self.separation
        achieved = sep.achieved.copy()
        achieved[diverged] = False
        return dataclasses.replace(
            self,
            error_vertices=blank(self.error_vertices),
            error_mm2=blank(self.error_mm2),
            path_error_mm2=blank(self.path_error_mm2),
            path_error_vertices=blank(self.path_error_vertices),
            dropped_fraction=blank(self.dropped_fraction),
            separation=Separation(
                blank(sep.error_vertices),
                blank(sep.error_mm2),
                blank(sep.missed_vertices),
                blank(sep.excess_vertices),
                achieved,
                sep.intended,
            ),
            diverged=diverged,
        )

    @property
    def separated_error_vertices(self) -> np.ndarray:
        """(B,) float64: the separated-material error in vertices."""
        return self.separation.error_vertices

    @property
    def separated_error_mm2(self) -> np.ndarray:
        """(B,) float64: the separated-material error (mm^2)."""
        return self.separation.error_mm2

    @property
    def separated(self) -> np.ndarray:
        """(B,) bool: the intended piece came free."""
        return self.separation.separated

    @property
    def missed_vertices(self) -> np.ndarray:
        return self.separation.missed_vertices

    @property
    def excess_vertices(self) -> np.ndarray:
        return self.separation.excess_vertices

    @property
    def achieved(self) -> np.ndarray:
        return self.separation.achieved

    @property
    def intended(self) -> np.ndarray:
        return self.separation.intended

    def select(self, envs: Sequence[int]) -> Score:
        """The score of the envs ``envs`` only, in that order."""
        envs = list(envs)
        sep = self.separation
        intended = sep.intended if sep.intended.ndim == 1 else sep.intended[envs]
        return Score(
            metric=self.metric,
            error_vertices=self.error_vertices[envs],
            error_mm2=self.error_mm2[envs],
            path_error_mm2=self.path_error_mm2[envs],
            path_error_vertices=self.path_error_vertices[envs],
            dropped_fraction=self.dropped_fraction[envs],
            cut_paths=[self.cut_paths[e] for e in envs],
            cut_regions=[self.cut_regions[e] for e in envs],
            separation=Separation(
                sep.error_vertices[envs],
                sep.error_mm2[envs],
                sep.missed_vertices[envs],
                sep.excess_vertices[envs],
                sep.achieved[envs],
                intended,
            ),
            diverged=None if self.diverged is None else self.diverged[envs],
        )

    def info(self) -> dict[str, np.ndarray]:
        """The (B,) per-env figures by name (env ``info``, results files)."""
        return {
            "error_vertices": self.error_vertices,
            "error_mm2": self.error_mm2,
            "path_error_vertices": self.path_error_vertices,
            "path_error_mm2": self.path_error_mm2,
            "separated_error_vertices": self.separated_error_vertices,
            "separated_error_mm2": self.separated_error_mm2,
            "separated": self.separated,
            "dropped_fraction": self.dropped_fraction,
            "missed_vertices": self.missed_vertices,
            "excess_vertices": self.excess_vertices,
            "diverged": (
                np.zeros(len(self.error_vertices), dtype=bool) if self.diverged is None else self.diverged
            ),
        }


def intended_mask(region: Region, grid: SheetGrid) -> np.ndarray:
    """Vertices whose rest position lies in ``region`` (boundary included).

    Args:
        region: Intended region in material coordinates (mm), a shapely ``Polygon`` or ``MultiPolygon``.
        grid: The sheet's rest layout.

    Returns:
        (ny * nx,) bool mask.

    Raises:
        TypeError: ``region`` is not polygonal.
    """
    if not isinstance(region, Region):
        raise TypeError(f"region: expected a shapely Polygon or MultiPolygon, got {type(region).__name__}")
    # An open contour's region is bounded by the sheet's edges, where whole rows and columns of vertices
    # lie exactly on the boundary; a tolerance far below the spacing keeps them in despite round-off.
    tolerance = 1e-9 * min(grid.spacing_mm)
    x, y = grid.material.T
    return shapely.intersects_xy(region.buffer(tolerance), x, y)


def achieved_mask(alive: np.ndarray, intended: np.ndarray, grid: SheetGrid) -> np.ndarray:
    """Vertices the cut separated from the sheet, kerf included.

    Two alive vertices belong to the same piece when they are joined by a path of alive grid
    4-neighbours. Diagonal (shear) springs are ignored, which assumes the cut radius is at least one
    spacing ``h`` (the default): two diagonal neighbours fall into different pieces only if the scissor
    path crossed the segment between them, and every point of that segment lies within ``h / sqrt(2)`` of
    one of them, so one of the two was removed and their spring is gone with it.

    The sheet is the piece with the most alive vertices outside the intended region (ties: the larger
    piece, then the one whose first vertex comes first in ``v = row * nx + col`` order); every other alive
    vertex is separated. Each removed vertex takes the label of its nearest alive vertex in rest-position
    distance (physical spacings ``hx``, ``hy``; ties are broken by scipy's Euclidean distance transform).
    An env with no alive vertex has separated nothing.

    Args:
        alive: (B, ny * nx) or (ny * nx,) bool; False where the scissors removed the vertex.
        intended: (ny * nx,) bool shared by all envs, or (B, ny * nx) bool, from :func:`intended_mask`.
        grid: The sheet's rest layout.

    Returns:
        (B, ny * nx) bool; ``B = 1`` for a 1-D ``alive``.

    Raises:
        ValueError: ``alive`` or ``intended`` has the wrong shape.
    """
    alive = _batch_mask(alive, "alive", grid)
    outside = ~np.broadcast_to(_batch_mask(intended, "intended", grid, alive.shape[0]), alive.shape)
    hx, hy = grid.spacing_mm
    achieved = np.zeros(alive.shape, dtype=bool)
    # One labelling of the whole batch, envs never joined: raster order numbers env k's pieces right after
    # env k - 1's, in the order labelling env k alone would (tests/test_scoring.py checks it).
    joins = np.zeros((3, 3, 3), dtype=bool)
    joins[1] = ndimage.generate_binary_structure(2, 1)
    labels = ndimage.label(alive.reshape(-1, grid.ny, grid.nx), joins)[0].reshape(alive.shape)
    counts = labels.max(axis=1)
    first = np.concatenate([[0], np.maximum.accumulate(counts)[:-1]])  # pieces of the envs before
    counts = np.where(counts > 0, counts - first, 0)
    for env, (env_alive, env_outside) in enumerate(zip(alive, outside, strict=True)):
        count = int(counts[env])
        if count <= 1:  # no alive vertex, or the sheet is still one piece: nothing separated
            continue
        pieces = np.where(env_alive, labels[env] - first[env], 0)
        size = np.bincount(pieces, minlength=count + 1)[1:]
        size_outside = np.bincount(pieces[env_outside], minlength=count + 1)[1:]
        # size <= V, so this key orders by size_outside first and size second; argmax takes the first
        # (lowest) label among equal keys.
        sheet = 1 + np.argmax(size_outside * (grid.num_vertices + 1) + size)
        separated = (env_alive & (pieces != sheet)).reshape(grid.ny, grid.nx)
        nearest_alive = ndimage.distance_transform_edt(
            ~env_alive.reshape(grid.ny, grid.nx),
            sampling=(hy, hx),
            return_distances=False,
            return_indices=True,
        )
        achieved[env] = separated[nearest_alive[0], nearest_alive[1]].ravel()
    return achieved


def symmetric_difference(
    alive: np.ndarray, region_or_regions: Region | Sequence[Region], grid: SheetGrid
) -> Separation:
    """The separated-material score of a batch of cuts against the intended region(s).

    Args:
        alive: (B, ny * nx) or (ny * nx,) bool; False where the scissors removed the vertex.
        region_or_regions: The intended region in material coordinates (mm), one polygon for all envs or
            a sequence of ``B`` polygons, one per env.
        grid: The sheet's rest layout.

    Returns:
        The :class:`Separation` of each env (``B = 1`` for a 1-D ``alive``).

    Raises:
        ValueError: ``alive`` has the wrong shape, or the number of regions is not ``B``.
        TypeError: A region is not polygonal.
    """
    alive = _batch_mask(alive, "alive", grid)
    if isinstance(region_or_regions, shapely.Geometry):
        intended = intended_mask(region_or_regions, grid)
    else:
        regions = list(region_or_regions)
        if len(regions) != alive.shape[0]:
            raise ValueError(
                f"region_or_regions: got {len(regions)} regions for {alive.shape[0]} envs; "
                "give one polygon for all envs or one per env"
            )
        masks: dict[int, np.ndarray] = {}  # envs cutting the same contour share its region object
        for region in regions:
            if id(region) not in masks:
                masks[id(region)] = intended_mask(region, grid)
        intended = np.stack([masks[id(region)] for region in regions])
    return separation(alive, intended, grid)


def separation(alive: np.ndarray, intended: np.ndarray, grid: SheetGrid) -> Separation:
    """:func:`symmetric_difference` against intended vertex masks already made (:func:`intended_mask`):
    ``intended`` (ny * nx,) shared by all envs or (B, ny * nx), e.g. to score many frames of one cut."""
    alive = _batch_mask(alive, "alive", grid)
    _batch_mask(intended, "intended", grid, alive.shape[0])
    intended = np.asarray(intended, dtype=bool)
    achieved = achieved_mask(alive, intended, grid)
    missed = (intended & ~achieved).sum(axis=1).astype(np.float64)
    excess = (achieved & ~intended).sum(axis=1).astype(np.float64)
    error = missed + excess
    return Separation(
        error_vertices=error,
        error_mm2=error * grid.vertex_area_mm2,
        missed_vertices=missed,
        excess_vertices=excess,
        achieved=achieved,
        intended=intended,
    )


def _batch_mask(mask: np.ndarray, name: str, grid: SheetGrid, batch: int | None = None) -> np.ndarray:
    """``mask`` as a (B, V) bool array, (1, V) for a 1-D mask; with ``batch`` given, B must be 1 or it."""
    mask = np.asarray(mask, dtype=bool)
    batched = mask[None] if mask.ndim == 1 else mask
    num_vertices = grid.num_vertices
    if (
        batched.ndim != 2
        or batched.shape[1] != num_vertices
        or (batch is not None and batched.shape[0] not in (1, batch))
    ):
        envs = "B" if batch is None else str(batch)
        raise ValueError(
            f"{name}: expected shape ({envs}, {num_vertices}) or ({num_vertices},) for a "
            f"{grid.ny} x {grid.nx} grid (ny x nx), got {mask.shape}"
        )
    return batched


# ---------------------------------------------------------------------------------------------- path
def order_cut_path(path: np.ndarray, arc_mm: np.ndarray) -> tuple[np.ndarray, float]:
    """One env's traced tips in contour order.

    Args:
        path: (T, 3) per update ``(mx, my, status)`` from :attr:`warpcut.sim.simulator.Simulator.path`: status
            1 mapped, 0 dropped, -1 not cutting.
        arc_mm: (T,) arc length along the contour of the point each update meant to cut (NaN while the
            scissors travel).

    Returns:
        ``(points, dropped_fraction)``: (K, 2) mapped material points sorted by ``arc_mm`` (stable), and
        the share of cutting updates that were dropped (NaN if none cut).
    """
    points, dropped = order_cut_paths(np.asarray(path)[None], np.asarray(arc_mm)[None])
    return points[0], float(dropped[0])


def order_cut_paths(paths: np.ndarray, arc_mm: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """:func:`order_cut_path` of a batch, ``paths`` (B, T, 3) and ``arc_mm`` (B, T), sorted in one call:
    ``(points, dropped_fraction)``, a list of B (K_b, 2) arrays and (B,) shares."""
    status = paths[..., 2]
    cutting = (status >= 0.0) & np.isfinite(arc_mm)
    mapped = cutting & (status > 0.5)
    total = np.count_nonzero(cutting, axis=1)
    count = np.count_nonzero(mapped, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        dropped = np.where(total > 0, (total - count) / np.maximum(total, 1), np.nan)
    # Unmapped updates sort last; a stable sort keeps the mapped ones as a stable sort of them alone would.
    order = np.argsort(np.where(mapped, arc_mm, np.inf), axis=1, kind="stable")
    xy = np.take_along_axis(paths[..., :2], order[..., None], axis=1).astype(np.float64)
    return [xy[env, :k] for env, k in enumerate(count.tolist())], dropped


def path_region(points: np.ndarray, contour) -> shapely.Geometry:
    """The region a cut path encloses, closed as the contour's intended region is.

    Args:
        points: (K, 2) material points in contour order (mm), e.g. from :func:`order_cut_path`.
        contour: The :class:`~warpcut.contours.Contour` being cut (closed or open, its sheet size).

    Returns:
        A polygonal shapely geometry (empty for fewer than 3 points, or 2 for an open contour). Closed: the
        ring through the points. Open: the path, its ends carried straight onto the sheet edges the
        contour's ends lie on, closed along the sheet's edges on the intended side.
    """
    return path_regions([points], [contour])[0]


def path_regions(points: Sequence[np.ndarray], contours: Sequence) -> list[shapely.Geometry]:
    """:func:`path_region` of each env, ``points[k]`` cut along ``contours[k]``; the closed contours' rings
    are made valid in one vectorised shapely call (a scored batch's cost, docs/performance.md)."""
    regions: list = [None] * len(points)
    rings, closed = [], []
    for k, (env_points, contour) in enumerate(zip(points, contours, strict=True)):
        env_points = np.asarray(env_points, dtype=np.float64).reshape(-1, 2)
        if not contour.closed:
            regions[k] = _open_path_region(env_points, contour)
        elif len(env_points) < 3:
            regions[k] = shapely.Polygon()
        else:
            rings.append(env_points)
            closed.append(k)
    if rings:
        owner = np.repeat(np.arange(len(rings)), [len(r) for r in rings])
        polygons = shapely.polygons(shapely.linearrings(np.concatenate(rings), indices=owner))
        valid = shapely.make_valid(polygons, method="structure", keep_collapsed=False)
        for k, region in zip(closed, valid, strict=True):
            regions[k] = region
    return regions


def _open_path_region(points: np.ndarray, contour) -> shapely.Geometry:
    """:func:`path_region` of an open contour: the path carried onto the sheet's edges and closed along
    them on the intended side."""
    if len(points) < 2:
        return shapely.Polygon()
    width, height = contour.sheet_size
    ends = np.asarray(contour.points)[[0, -1]]
    start = _onto_edge(points[0], ends[0], width, height)
    stop = _onto_edge(points[-1], ends[1], width, height)
    ccw = _intended_side_ccw(contour)
    chain = _boundary_corners(
        _perimeter(stop, width, height), _perimeter(start, width, height), ccw, width, height
    )
    ring = np.vstack([start, points, stop, *chain]) if chain else np.vstack([start, points, stop])
    polygon = shapely.make_valid(shapely.Polygon(ring), method="structure", keep_collapsed=False)
    return shapely.intersection(polygon, shapely.box(0.0, 0.0, width, height))


def path_errors(
    points: Sequence[np.ndarray], contours: Sequence, grid: SheetGrid
) -> tuple[np.ndarray, np.ndarray, list]:
    """The path score of a batch: ``(error_mm2 (B,), error_vertices (B,), regions)``.

    Args:
        points: Per env, (K, 2) cut-path points in contour order (:func:`order_cut_path`).
        contours: Per env, the contour being cut.
        grid: The sheet's rest layout (for the vertex area).
    """
    regions = path_regions(points, contours)
    intended = np.array([c.intended_region() for c in contours], dtype=object)
    error = shapely.area(shapely.symmetric_difference(np.array(regions, dtype=object), intended))
    error = np.asarray(error, dtype=np.float64)
    return error, error / grid.vertex_area_mm2, regions


def score_cut(
    metric: str,
    paths: np.ndarray | None,
    arc_mm: np.ndarray,
    alive: np.ndarray,
    contours: Sequence,
    grid: SheetGrid,
) -> Score:
    """Both scores of a batch of finished cuts.

    Args:
        metric: ``"path"`` or ``"separated"``: which one ``Score.error_*`` holds.
        paths: (B, T, 3) traced tips (:attr:`warpcut.sim.simulator.Simulator.path`), or None where the path
            was not traced: the path fields are then NaN, and ``metric`` must be ``"separated"``.
        arc_mm: (B, T) arc length along each env's contour of the point each update meant to cut.
        alive: (B, V) bool alive masks after the cut.
        contours: Per env, the contour cut.
        grid: The sheet's rest layout.
    """
    if metric not in SCORES:
        raise ValueError(f"metric: choose one of {SCORES} (got {metric!r})")
    if paths is None and metric == "path":
        raise ValueError("paths: the path score needs the traced cut path (Simulator.trace_path)")
    intended = [c.intended_region() for c in contours]
    # The separated score on a second thread while this one scores the paths: shapely's GEOS calls, most
    # of the path score's time, release the GIL (an episode's end costs two thirds; the same values).
    separating = _scoring_thread().submit(symmetric_difference, alive, intended, grid)
    try:
        points, regions, dropped, error_mm2, error_vertices = _path_score(paths, arc_mm, contours, grid)
    except BaseException:
        futures.wait([separating])  # never leave the thread working on a batch the caller may change
        raise
    separation = separating.result()
    chosen = (
        (error_mm2, error_vertices) if metric == "path" else (separation.error_mm2, separation.error_vertices)
    )
    return Score(
        metric=metric,
        error_vertices=chosen[1],
        error_mm2=chosen[0],
        path_error_mm2=error_mm2,
        path_error_vertices=error_vertices,
        dropped_fraction=dropped,
        cut_paths=points,
        cut_regions=regions,
        separation=separation,
    )


@functools.cache
def _scoring_thread() -> ThreadPoolExecutor:
    """The one worker thread :func:`score_cut` scores separated material on (made at the first score)."""
    return ThreadPoolExecutor(1, thread_name_prefix="warpcut-scoring")


def _path_score(paths, arc_mm, contours, grid):
    """:func:`score_cut`'s path half: ``(points, regions, dropped_fraction, error_mm2, error_vertices)``, NaN
    where ``paths`` is None."""
    if paths is None:
        nan = np.full(len(contours), np.nan)
        return [np.zeros((0, 2))] * len(contours), [None] * len(contours), nan, nan, nan
    points, dropped = order_cut_paths(paths, arc_mm)
    error_mm2, error_vertices, regions = path_errors(points, contours, grid)
    return points, regions, dropped, error_mm2, error_vertices


def _onto_edge(point: np.ndarray, edge_point: np.ndarray, width: float, height: float) -> np.ndarray:
    """``point`` carried straight onto the sheet edge that ``edge_point`` lies on (the nearest one)."""
    x, y = edge_point
    gaps = np.array([x, width - x, y, height - y])
    edge = int(np.argmin(gaps))
    out = np.clip(np.asarray(point, dtype=np.float64), 0.0, [width, height])
    out[edge // 2] = (0.0, width, 0.0, height)[edge]
    return out


def _perimeter(point: np.ndarray, width: float, height: float) -> float:
    """Position of a point on the sheet's boundary, counter-clockwise from (0, 0) (mm)."""
    x, y = point
    gaps = np.array([y, width - x, height - y, x])  # bottom, right, top, left
    edge = int(np.argmin(gaps))
    return float((x, width + y, 2 * width + height - x, 2 * (width + height) - y)[edge])


def _boundary_corners(t_from: float, t_to: float, ccw: bool, width: float, height: float) -> list:
    """The sheet corners passed walking its boundary from ``t_from`` to ``t_to`` (perimeter positions)."""
    total = 2.0 * (width + height)
    corners = [
        (0.0, (0.0, 0.0)),
        (width, (width, 0.0)),
        (width + height, (width, height)),
        (2 * width + height, (0.0, height)),
    ]
    sign = 1.0 if ccw else -1.0
    span = (sign * (t_to - t_from)) % total
    passed = [(sign * (t - t_from)) % total for t, _ in corners]
    inside = sorted((d, c) for d, (_, c) in zip(passed, corners, strict=True) if 0.0 < d < span)
    return [np.array(c) for _, c in inside]


def _intended_side_ccw(contour) -> bool:
    """Whether the open contour's intended region closes from its end back to its start counter-clockwise
    along the sheet's boundary."""
    width, height = contour.sheet_size
    pts = np.asarray(contour.points, dtype=np.float64)
    start, stop = pts[0], pts[-1]
    chain = _boundary_corners(
        _perimeter(stop, width, height), _perimeter(start, width, height), True, width, height
    )
    ccw = shapely.Polygon(np.vstack([pts, *chain]) if chain else pts)
    # The same piece, not one of the same area: a contour that halves the sheet has two.
    return shapely.area(shapely.symmetric_difference(ccw, contour.intended_region())) <= 1e-6 * width * height
