"""The rerun encoding of a recording: :class:`RerunWriter` turns the frames that the step callbacks copied
(:mod:`warpcut.viz.frames`) into rerun data in one ``.rrd`` file, in the recorder process, on the worker
thread or in the step callback itself (:mod:`warpcut.viz.transport`), and finishes the file.

A batch of frames is drawn all at once: one labelling for the separated error, shifted grid slices for the
strain, one sparse product for the contour, and columns built straight from numpy buffers
(:mod:`warpcut.viz.columns`). The cut is scored with :mod:`warpcut.scoring`'s functions.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from warpcut.contours import Contour, ring
from warpcut.fiducials import NUM_FIDUCIALS, sample_fiducials, visible
from warpcut.scoring import intended_mask, order_cut_path, path_errors, separation
from warpcut.sim.config import SheetGrid, SimConfig
from warpcut.sim.material import interpolate, material_cells
from warpcut.viz.colours import (
    CUTTING_RGBA,
    GRASP_RGB,
    HIDDEN_RGBA,
    STRAIN_FULL_SCALE,
    TRAVEL_RGBA,
    VISIBLE_RGBA,
    colour_legend,
    ramp_image,
    ramp_rgba,
    vertex_strain,
)
from warpcut.viz.columns import (
    column,
    cut_path_strips,
    cutting_runs,
    descriptors,
    float64_array,
    ragged_strip_array,
    strip_array,
    triangle_array,
    uint32_array,
    vec3_array,
)
from warpcut.viz.frames import EnvSetup, Frame, TaskSetup
from warpcut.viz.process import place_file

GRASP_DISC_MM = 1.0
"""Thickness of the grasp's disc as drawn (mm): the gripper's pad, of the grasp radius, centred on the grasped
vertices so that it shows above and below the sheet."""

LEGEND = "/legend"
"""Where a recording's colour bar (``/legend/colour_bar``, an image) and what its colours mean
(``/legend/colour_scale``, Markdown) are, logged once."""

Send = Callable[..., None]
"""``send(entity, columns, at=None)``: send one env's columns of ``entity`` at the batch's steps (or
``at``)."""


def import_rerun() -> None:
    """Import what :class:`RerunWriter` imports on first use (rerun, its blueprints, pyarrow, scipy.sparse):
    the recorder process does so while it starts, before it lowers its priority."""
    import pyarrow  # noqa: F401
    import rerun  # noqa: F401
    import rerun.blueprint  # noqa: F401
    from scipy import sparse  # noqa: F401

    descriptors()


@dataclass
class _EnvDrawing:
    """What the writer derives from one recorded env's setup when its episode starts, and what it carries
    from one batch of frames to the next."""

    setup: EnvSetup
    root: str
    """The env's entity path, ``/{method}/env_{env}``."""
    contour_matrix: object
    """(K, V) scipy.sparse bilinear weights of the contour's K points on the sheet's vertices."""
    intended: np.ndarray
    """(V,) bool: the vertices in the intended region (:func:`warpcut.scoring.intended_mask`)."""
    cut_runs: np.ndarray
    """:func:`~warpcut.viz.columns.cutting_runs` of the scissor trajectory."""
    fiducials: np.ndarray
    """(K, 2) material points of the fiducials drawn: the env's, or drawn for the recording."""
    fiducial_cells: tuple[np.ndarray, np.ndarray]
    """(1, K, 4) vertices and weights of the fiducials' cells
    (:func:`~warpcut.sim.material.material_cells`)."""
    path: np.ndarray | None
    """(T, 3) the traced cut path so far, filled batch by batch; None where the task does not trace it."""
    height_range: tuple[float, float] | None = None
    disc_origin: np.ndarray | None = None
    last_alive: np.ndarray | None = None
    last_error: float = 0.0


@dataclass
class _TaskDrawing:
    """The recorded envs of one episode, and what they share."""

    grid: SheetGrid
    config: SimConfig
    triangles: np.ndarray
    """:func:`grid_triangles` of the grid."""
    envs: list[_EnvDrawing]


@dataclass
class _EnvBatch:
    """One env's share of a batch of F frames."""

    steps: np.ndarray
    updates: np.ndarray
    positions: np.ndarray
    """(F, V, 3)"""
    alive: np.ndarray
    """(F, V) bool"""
    displacements: np.ndarray
    """(F, 3)"""
    action_steps: np.ndarray
    """The steps of the frames with an action."""
    actions: np.ndarray
    """(len(action_steps), 3)"""


class RerunWriter:
    """Turns what the step callbacks copied into rerun data in one ``.rrd`` file, and finishes the file.

    Args:
        tmp: The file written (the stream saves to it).
        path: Where :meth:`finish` moves it.
        application_id: Rerun application id.
        colour_by: What the sheet's vertex colours show (:data:`~warpcut.viz.colours.COLOUR_FIELDS`).
        background: Off the stepping thread: send the blueprint when an episode starts (else
            :meth:`finish` does).
    """

    def __init__(self, tmp: Path, path: Path, application_id: str, colour_by: str, background: bool):
        import rerun as rr

        self.tmp, self.path, self.colour_by = tmp, path, colour_by
        self.background = background
        self.stream = rr.RecordingStream(application_id)
        self.stream.save(tmp)
        self.stream.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self.stream.log(f"{LEGEND}/colour_bar", rr.Image(ramp_image()), static=True)
        self.stream.log(
            f"{LEGEND}/colour_scale",
            rr.TextDocument(colour_legend(colour_by), media_type=rr.MediaType.MARKDOWN),
            static=True,
        )
        self.episodes: dict[int, _TaskDrawing] = {}
        self._blueprint_roots: list[str] | None = None

    def finish(self, complete: bool = True, keep: bool = True) -> None:
        """Send the blueprint (if ``complete``: no frame batch failed), finish the file and move it into
        place; or, unless ``keep``, delete it (nothing was recorded)."""
        try:
            if complete and keep:
                self._send_blueprint()
                self.stream.flush()
        finally:
            self.stream.disconnect()
            place_file(self.tmp, self.path, keep)

    def start(self, key: int, method: str, task_setup: TaskSetup) -> None:
        """Per-env constants (contour cells, intended region, cutting runs) and the static entities of a
        new episode (``key``: its callback) of ``method``."""
        import rerun as rr

        root = "/" + rr.escape_entity_path_part(method)
        envs = [self._start_env(f"{root}/env_{setup.env}", setup, task_setup) for setup in task_setup.envs]
        grid = task_setup.grid
        self.episodes[key] = _TaskDrawing(grid, task_setup.config, grid_triangles(grid), envs)
        if self.background:
            self._send_blueprint()  # off the stepping thread; finish() sends it otherwise

    def _start_env(self, root: str, setup: EnvSetup, task_setup: TaskSetup) -> _EnvDrawing:
        import rerun as rr
        from scipy import sparse

        stream, grid = self.stream, task_setup.grid
        # Points every half spacing follow the deformed sheet closely enough; the contour's own points
        # would cost several times more to interpolate every frame.
        line = _polyline(setup.contour, 0.5 * min(grid.spacing_mm))
        vertices, weights = material_cells(line, grid)
        rows = np.repeat(np.arange(len(vertices)), vertices.shape[1])
        contour_matrix = sparse.csr_matrix(
            (weights.ravel(), (rows, vertices.ravel())), shape=(len(vertices), grid.num_vertices)
        )
        region = setup.contour.intended_region()
        runs = cutting_runs(setup.tip)
        fiducials = setup.fiducials
        if fiducials is None:
            pinch = setup.pinch[None] if setup.disc is not None else np.full((1, 2), np.nan)
            rng = np.random.default_rng(setup.env)
            fiducials = sample_fiducials(rng, NUM_FIDUCIALS, [setup.contour], pinch, task_setup.config)[0]
        env = _EnvDrawing(
            setup=setup,
            root=root,
            contour_matrix=contour_matrix,
            intended=intended_mask(region, grid),
            cut_runs=runs,
            fiducials=fiducials,
            fiducial_cells=material_cells(fiducials[None], grid),
            path=None if setup.arc is None else np.zeros((len(setup.arc), 3), dtype=np.float32),
        )
        stream.log(f"{root}/info", rr.TextDocument(self._info(setup)), static=True)
        if setup.disc is not None:
            stream.log(
                f"{root}/grasp/disc",
                rr.Cylinders3D.from_fields(
                    lengths=[GRASP_DISC_MM],
                    radii=[task_setup.config.grasp_radius],
                    colors=[GRASP_RGB],
                    fill_mode=rr.components.FillMode.Solid,
                ),
                static=True,
            )
            stream.log(
                f"{root}/grasp/vertices",
                rr.Points3D.from_fields(radii=[0.15 * min(grid.spacing_mm)], colors=[[110, 0, 95]]),
                static=True,
            )
        stream.log(f"{root}/action", rr.SeriesLines(names=["x", "y", "z"]), static=True)
        stream.log(
            f"{root}/separated_error_vertices",
            rr.SeriesLines(names="separated error (vertices)"),
            static=True,
        )
        if env.path is not None:
            stream.log(
                f"{root}/material_contour",
                rr.LineStrips3D([np.column_stack([line, np.zeros(len(line))])], colors=[[0, 0, 0]]),
                static=True,
            )
            stream.log(
                f"{root}/path_error_vertices", rr.SeriesLines(names="path error (vertices)"), static=True
            )
        return env

    def _info(self, setup: EnvSetup, height_range: tuple[float, float] | None = None) -> str:
        """An env's ``info`` text: its contour, pinch point and what its vertex colours show."""
        where = "none" if setup.disc is None else f"({setup.pinch[0]:.1f}, {setup.pinch[1]:.1f}) mm"
        scale = (
            "" if height_range is None else f", from z = {height_range[0]:.1f} to {height_range[1]:.1f} mm"
        )
        return f"contour {setup.contour.name}, pinch point {where}; vertex colours: {self.colour_by}{scale}"

    def _send_blueprint(self) -> None:
        """Send the layout of the envs recorded so far, unless it was sent already."""
        roots = [env.root for _, task in sorted(self.episodes.items()) for env in task.envs]
        if roots != self._blueprint_roots:
            self._blueprint_roots = roots
            self.stream.send_blueprint(_blueprint(roots))

    def frames(self, key: int, frames: list[Frame]) -> None:
        """Send a batch of frames of every recorded env of episode ``key``."""
        task = self.episodes[key]
        steps = np.array([f.step for f in frames])
        updates = np.array([f.update for f in frames])
        state = np.stack([f.state for f in frames], axis=1)  # (n, F, V, 4)
        positions, alive = np.ascontiguousarray(state[..., :3]), state[..., 3] != 0.0
        displacements = (
            np.stack([f.displacements for f in frames], axis=1)
            if frames[0].displacements is not None
            else np.zeros((len(task.envs), len(frames), 3))
        )
        acted = [f for f in frames if f.action is not None]
        action_steps = np.array([f.step for f in acted], dtype=np.int64)
        for k, env in enumerate(task.envs):
            if env.path is not None:
                for f in frames:
                    if f.path is not None:
                        env.path[f.path_start : f.path_start + f.path.shape[1]] = f.path[k]
            actions = np.array([f.action[k] for f in acted]).reshape(-1, 3)
            batch = _EnvBatch(steps, updates, positions[k], alive[k], displacements[k], action_steps, actions)
            self._send_env(task, env, batch)

    def _send_env(self, task: _TaskDrawing, env: _EnvDrawing, batch: _EnvBatch) -> None:
        """One env's share of a batch of frames, entity by entity."""
        import rerun as rr

        step_s = env.setup.step_s

        def timeline(at: np.ndarray) -> list:
            return [rr.TimeColumn("step", sequence=at), rr.TimeColumn("sim_time", duration=at * step_s)]

        every_frame = timeline(batch.steps)

        def send(entity: str, columns, at: np.ndarray | None = None) -> None:
            times = every_frame if at is None else timeline(at)
            self.stream.send_columns(f"{env.root}/{entity}", indexes=times, columns=columns, strict=True)

        if env.height_range is None:
            # Colours and the arrow's origin stay fixed at the episode's first frame (the settled sheet).
            z = batch.positions[0, :, 2]
            env.height_range = (float(z.min()), max(float(z.max()), float(z.min()) + 1.0))
            if env.setup.disc is not None:
                env.disc_origin = batch.positions[0, env.setup.disc].mean(axis=0)
            if self.colour_by == "height":  # the ramp's ends, now known
                info = rr.TextDocument(self._info(env.setup, env.height_range))
                self.stream.log(f"{env.root}/info", info, static=True)
        self._send_sheet(task, env, batch, send)
        if env.path is not None:
            _send_path(env, task.grid, batch.updates, send)
        # All frames' contours in one product: (K, V) @ (V, F * 3).
        frames = len(batch.steps)
        by_vertex = np.moveaxis(batch.positions, 0, 1).reshape(task.grid.num_vertices, frames * 3)
        contour = np.moveaxis((env.contour_matrix @ by_vertex).reshape(-1, frames, 3), 1, 0)
        send("contour", [column("LineStrips3D:strips", strip_array(contour))])
        _send_tip_and_fiducials(env, batch, send)
        _send_grasp_and_action(env, batch, send)

    def _send_sheet(self, task: _TaskDrawing, env: _EnvDrawing, batch: _EnvBatch, send: Send) -> None:
        """The sheet's mesh (positions, colours and, where the scissors removed vertices, its triangles)
        and the separated error."""
        positions, alive = batch.positions, batch.alive
        frames = len(batch.steps)
        if self.colour_by == "strain":
            strain = vertex_strain(positions, alive, task.grid, task.config.springs)
            colours = ramp_rgba(strain, 0.0, STRAIN_FULL_SCALE)
        else:
            colours = ramp_rgba(positions[..., 2], *env.height_range)
        rows = np.full(frames, task.grid.num_vertices)
        send(
            "sheet",
            [
                column("Mesh3D:vertex_positions", vec3_array(positions), rows),
                column("Mesh3D:vertex_colors", uint32_array(colours), rows),
            ],
        )
        # The topology and the error change only when the scissors remove vertices.
        changed = np.ones(frames, dtype=bool)
        changed[1:] = np.any(alive[1:] != alive[:-1], axis=1)
        if env.last_alive is not None:
            changed[0] = bool(np.any(alive[0] != env.last_alive))
        env.last_alive = alive[-1].copy()
        if changed.any():
            kept = alive[changed][:, task.triangles].all(axis=2)  # (changed frames, triangles)
            faces = task.triangles[np.nonzero(kept)[1]]
            send(
                "sheet",
                [column("Mesh3D:triangle_indices", triangle_array(faces), kept.sum(axis=1))],
                at=batch.steps[changed],
            )
            # Unchanged frames carry the last error forward.
            scored = separation(alive[changed], env.intended, task.grid).error_vertices
            errors = np.concatenate([[env.last_error], scored])[np.cumsum(changed)]
        else:
            errors = np.full(frames, env.last_error)
        env.last_error = float(errors[-1])
        send("separated_error_vertices", [column("Scalars:scalars", float64_array(errors))])


def _send_path(env: _EnvDrawing, grid: SheetGrid, updates: np.ndarray, send: Send) -> None:
    """The cut path so far in material coordinates, drawn on the rest plane (z = 0, above the sagging
    sheet), and its path score, frame by frame (one vectorised scoring of all frames)."""
    arc, contour = env.setup.arc, env.setup.contour
    ends = np.minimum(updates, len(arc))
    ordered = [order_cut_path(env.path[:end], arc[:end])[0] for end in ends]
    errors = path_errors(ordered, [contour] * len(ends), grid)[1]
    strips = []
    for end in ends:
        mapped = env.path[:end][env.path[:end, 2] > 0.5, :2]  # in cutting order
        strips.append(np.column_stack([mapped, np.zeros(len(mapped))]))
    send("path_error_vertices", [column("Scalars:scalars", float64_array(errors))])
    send("path", [column("LineStrips3D:strips", ragged_strip_array(strips), np.ones(len(strips)))])


def _send_tip_and_fiducials(env: _EnvDrawing, batch: _EnvBatch, send: Send) -> None:
    """The scissor tip (red while it cuts), the path it has cut so far, and the fiducials (green where
    the camera sees them)."""
    trajectory, updates = env.setup.tip, batch.updates
    current = np.clip(updates - 1, 0, len(trajectory) - 1)
    cutting = (trajectory[current, 3] > 0) & (updates <= len(trajectory))
    send(
        "tip",
        [
            column("Points3D:positions", vec3_array(trajectory[current, :3])),
            column("Points3D:colors", uint32_array(np.where(cutting, CUTTING_RGBA, TRAVEL_RGBA))),
        ],
    )
    strips, counts = cut_path_strips(trajectory, env.cut_runs, updates)
    send("cut_path", [column("LineStrips3D:strips", strips, counts)])
    if len(env.fiducials):
        frames = len(batch.steps)
        cells, weights = env.fiducial_cells
        world = interpolate(batch.positions, cells, np.broadcast_to(weights, (frames, *weights.shape[1:])))
        seen = visible(world, batch.alive, cells, trajectory[current], env.setup.shaft_radius_mm)
        per_frame = np.full(frames, len(env.fiducials))
        send(
            "fiducials",
            [
                column("Points3D:positions", vec3_array(world), per_frame),
                column("Points3D:colors", uint32_array(np.where(seen, VISIBLE_RGBA, HIDDEN_RGBA)), per_frame),
            ],
        )


def _send_grasp_and_action(env: _EnvDrawing, batch: _EnvBatch, send: Send) -> None:
    """The grasp (where the env is grasped): its disc, centred on the grasped vertices, those vertices and
    its displacement; and the actions."""
    import rerun as rr

    disc, frames = env.setup.disc, len(batch.steps)
    if disc is not None:
        held = batch.positions[:, disc]
        send("grasp/disc", rr.Cylinders3D.columns(centers=held.mean(axis=1)))
        send("grasp/vertices", [column("Points3D:positions", vec3_array(held), np.full(frames, disc.sum()))])
        send(
            "grasp/displacement",
            [
                column("Arrows3D:origins", vec3_array(np.broadcast_to(env.disc_origin, (frames, 3)))),
                column("Arrows3D:vectors", vec3_array(batch.displacements)),
            ],
        )
    if len(batch.action_steps):
        send(
            "action",
            [column("Scalars:scalars", float64_array(batch.actions), np.full(len(batch.actions), 3))],
            at=batch.action_steps,
        )


def grid_triangles(grid: SheetGrid) -> np.ndarray:
    """(2 * (nx - 1) * (ny - 1), 3) uint32 vertex indices: two counter-clockwise triangles per cell."""
    rows, cols = np.meshgrid(np.arange(grid.ny - 1), np.arange(grid.nx - 1), indexing="ij")
    v00 = (rows * grid.nx + cols).ravel()
    v10, v01 = v00 + 1, v00 + grid.nx
    v11 = v01 + 1
    return np.concatenate([np.stack([v00, v10, v11], axis=1), np.stack([v00, v11, v01], axis=1)]).astype(
        np.uint32
    )


def _polyline(contour: Contour, spacing_mm: float) -> np.ndarray:
    """The contour's points every ``spacing_mm`` (mm), a closed one ending where it starts."""
    return ring(contour.resample(spacing_mm), contour.closed)


def _blueprint(roots: list[str]):
    """A 3D view per recorded env side by side, above the errors and the actions over time."""
    import rerun.blueprint as rrb

    if not roots:
        return rrb.Blueprint(rrb.Spatial3DView(origin="/"))
    legend = rrb.Vertical(
        rrb.Spatial2DView(name="colour scale", origin=f"{LEGEND}/colour_bar"),
        rrb.TextDocumentView(name="colours", origin=f"{LEGEND}/colour_scale"),
        row_shares=[1, 3],
    )
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Grid(*[rrb.Spatial3DView(origin=r, name=r.strip("/").replace("/", " ")) for r in roots]),
            rrb.Horizontal(
                rrb.TimeSeriesView(
                    name="error (vertices)",
                    origin="/",
                    contents=[f"{r}/{e}_error_vertices" for r in roots for e in ("path", "separated")],
                ),
                rrb.TimeSeriesView(name="action (mm)", origin="/", contents=[f"{r}/action" for r in roots]),
                legend,
                column_shares=[2, 2, 1],
            ),
            row_shares=[3, 1],
        ),
        collapse_panels=True,
    )
