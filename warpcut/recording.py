"""Rerun recordings of cutting episodes, and what a recording holds when read back.

A :class:`Recorder` writes one ``.rrd`` file. Every method recorded into it gets its own entity tree,
``/{method}/env_{k}/...`` for the first ``envs`` envs of its task, so methods cut on the same contour
can be compared side by side in one viewer (the recording carries a blueprint that lays them out so):

* ``sheet``: the sheet as a triangle mesh (two triangles per grid cell, faces touching a cut vertex
  dropped), vertex colours by strain (default: the mean relative stretch of each vertex's live springs,
  which shows where the grasp and the clips pull) or by height (``colour_by``);
* ``contour``: the intended contour carried along with the material (bilinear lookup on the sheet);
* ``tip`` and ``cut_path``: the scissor tip (red while cutting) and the path it has cut so far;
* ``grasp/disc`` and ``grasp/displacement``: the grasped vertices and the grasp's displacement;
* ``action``: the tensioning action (mm) as three scalar series;
* ``error_vertices``: the running symmetric difference between the intended and the separated region.

Frames are on the ``step`` timeline (0 after the reset, then one per env step) and on ``sim_time``
(simulated seconds). Recording must not slow the stepping loop down, so the step callback only copies
the recorded envs' state, and only theirs (:meth:`~warpcut.simulator.Simulator.read_envs`, a few
microseconds); the frames are scored and turned into rerun columns (``send_columns``) in batches, all
frames of a batch at once (one labelling for the errors, shifted grid slices for the strain, one sparse
product for the contour): on a worker thread where a core is free, every :data:`WORKER_BATCH_FRAMES`
frames, else in the step callback every :data:`FLUSH_FRAMES` frames (``background``). Without a step
callback (``on_step=None``) :meth:`CuttingTask.run` does none of this. ``every=k`` keeps only every k-th
step (plus the first and the last) for long runs or big sheets. ``docs/performance.md`` has the measured
overhead (``scripts/recording_overhead.py``).

The file is written beside its target under a temporary name and renamed when the recorder closes,
also when an exception or Ctrl-C ends the run early, so a readable recording of what happened so far
always remains. Use it as a context manager::

    with Recorder("logs/run/recording.rrd", envs=2) as recorder:
        task.run(policy, on_step=recorder.on_step("fixed"))
"""

from __future__ import annotations

import math
import os
import queue
import tempfile
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import rerun as rr
import rerun.blueprint as rrb
from scipy import ndimage, sparse

from warpcut.config import SheetGrid
from warpcut.contours import Contour
from warpcut.io import plain_file_mode
from warpcut.scoring import achieved_mask, intended_mask
from warpcut.simulator import spring_colours
from warpcut.task import CuttingTask, material_cells

StepCallback = Callable[[CuttingTask, "np.ndarray | None"], None]
"""``on_step(task, action)`` as :meth:`CuttingTask.run` calls it."""

FLUSH_FRAMES = 128
"""Frames buffered per method before they are scored and sent to the file in the step callback (without
a worker thread). Each batch costs ~3 ms on top of ~0.1 ms per frame (25 x 25 sheet), so few large
batches are cheapest; 128 frames of a 25 x 25 sheet hold ~1 MB per recorded env."""

WORKER_BATCH_FRAMES = 32
"""Frames handed to the worker thread at a time (and the rest when the episode ends): smaller batches
than :data:`FLUSH_FRAMES`, so that little work is left for :meth:`Recorder.close` to wait for."""

COLOUR_FIELDS = ("strain", "height")
"""What the sheet's vertex colours can show (``Recorder(colour_by=...)``)."""

STRAIN_FULL_SCALE = 0.05
"""Strain at the top of the colour ramp: a vertex whose live springs are stretched or compressed by 5% on
average is drawn yellow. A settled 25 x 25 sheet's vertices sit at ~1.4% (median) to ~9% (99th
percentile, next to the corner clips); a grasp pulling the sheet raises its neighbourhood further."""

# Vertex colours, low (dark blue) to high (yellow): viridis, from five stops to 256 entries, as rerun's
# packed 0xRRGGBBAA (cheaper to convert than RGB triples).
_VIRIDIS_STOPS = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]])
_RAMP_RGB = np.stack(
    [np.interp(np.linspace(0, 4, 256), np.arange(5), _VIRIDIS_STOPS[:, c]) for c in range(3)], axis=1
).astype(np.uint32)
_RAMP_RGBA = (_RAMP_RGB[:, 0] << 24) | (_RAMP_RGB[:, 1] << 16) | (_RAMP_RGB[:, 2] << 8) | 0xFF
_CUTTING_RGB, _TRAVEL_RGB = (230, 40, 40), (150, 150, 150)


class Recorder:
    """Records cutting episodes into one ``.rrd`` file.

    Args:
        path: The ``.rrd`` file to write (its folder is created).
        envs: How many envs (the first ones) of each task to record.
        application_id: Rerun application id; the viewer groups recordings by it.
        every: Record every ``every``-th env step only (the reset and the last step always).
        colour_by: What the sheet's vertex colours show: ``"strain"`` (the default: the mean relative
            stretch ``|length / rest - 1|`` of the vertex's live springs, see :func:`vertex_strain`, from 0
            to :data:`STRAIN_FULL_SCALE`; it shows where the grasp and the clips pull the gauze, which the
            mesh's shape does not) or ``"height"`` (z over the settled sheet's range, which the 3D view
            shows anyway).
        background: Where the copied frames are scored and turned into rerun columns: ``True`` on a
            worker thread, so that the stepping loop only pays for copying the recorded envs' state;
            ``False`` in the step callback itself, every :data:`FLUSH_FRAMES` frames; ``None`` (default):
            on a worker thread when the machine has a core to spare, i.e. more cores than the simulator
            steps the recorded task with (:attr:`~warpcut.simulator.Simulator.threads`). On a machine
            whose cores are all busy a worker costs a little more than doing the work in the callback.

    Raises:
        ValueError: ``envs`` or ``every`` is not a positive integer, or ``colour_by`` is not one of
            :data:`COLOUR_FIELDS`.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        envs: int = 1,
        application_id: str = "warpcut",
        every: int = 1,
        colour_by: str = "strain",
        background: bool | None = None,
    ):
        for name, value in (("envs", envs), ("every", every)):
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"{name}: must be a positive integer (got {value!r})")
        if colour_by not in COLOUR_FIELDS:
            raise ValueError(f"colour_by: choose one of {COLOUR_FIELDS} (got {colour_by!r})")
        self.path = Path(path)
        self.envs, self.every, self.colour_by, self.background = envs, every, colour_by, background
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=self.path.parent, prefix=f".{self.path.name}.", suffix=".tmp")
        os.fchmod(fd, plain_file_mode())
        os.close(fd)
        self._tmp = Path(tmp)
        self.stream = rr.RecordingStream(application_id)
        self.stream.save(self._tmp)
        self.stream.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._episodes: dict[str, _Episode] = {}
        self._jobs: queue.SimpleQueue | None = None
        self._worker: threading.Thread | None = None
        self._failure: BaseException | None = None
        self._blueprint_roots: list[str] | None = None
        self.closed = False

    def on_step(self, method: str) -> StepCallback:
        """A callback recording one episode of ``method`` under ``/{method}``, for
        ``task.run(policy, on_step=recorder.on_step(method))``. Use a new method name per episode: a
        second run through the same callback would write over the first one's steps.

        Raises:
            ValueError: ``method`` was already recorded, or the recorder is closed.
        """
        if self.closed:
            raise ValueError(f"on_step: the recorder of {self.path} is closed")
        if method in self._episodes:
            raise ValueError(f"on_step: method {method!r} is already recorded in {self.path}")
        episode = _Episode(self, method)
        self._episodes[method] = episode
        return episode

    def close(self) -> Path:
        """Send the buffered frames (waiting for the worker thread to finish them) and the blueprint,
        finish the file and move it into place.

        Raises:
            Exception: Whatever failed on the worker thread, after the file was moved into place.
        """
        if self.closed:
            return self.path
        self.closed = True
        try:
            for episode in self._episodes.values():
                episode.flush()
            self._join()
            self._send_blueprint()
            self.stream.flush()
        finally:
            self._join()
            self.stream.disconnect()
            os.replace(self._tmp, self.path)
        if self._failure is not None:
            raise self._failure
        return self.path

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def _threaded(self, task: CuttingTask) -> bool:
        """Whether the episodes of ``task`` are sent from the worker thread (see ``background``)."""
        if self.background is None:
            return (os.cpu_count() or 1) > task.sim.threads
        return bool(self.background)

    def _submit(self, job: Callable[[], None], threaded: bool) -> None:
        """Run ``job`` on the worker thread (in submission order), or here unless ``threaded``."""
        if self._failure is not None:
            raise self._failure
        if not threaded:
            job()
            return
        if self._worker is None:
            self._jobs = queue.SimpleQueue()
            self._worker = threading.Thread(target=self._work, name="warpcut-recorder", daemon=True)
            self._worker.start()
        self._jobs.put(job)

    def _work(self) -> None:
        while (job := self._jobs.get()) is not None:
            if self._failure is None:  # after a failure, drain the queue without running the rest
                try:
                    job()
                except BaseException as exc:  # noqa: BLE001 - handed to the main thread
                    self._failure = exc

    def _join(self) -> None:
        """Wait until the worker thread has run every submitted job, and end it."""
        if self._worker is not None:
            self._jobs.put(None)
            self._worker.join()
            self._worker = None

    def _send_blueprint(self) -> None:
        """Send the layout of the envs recorded so far, unless it was sent already. Each episode's setup
        sends it on the worker thread, so that closing the recorder seldom has to."""
        roots = [root for e in list(self._episodes.values()) for root in e.env_roots]
        if roots != self._blueprint_roots:
            self._blueprint_roots = roots
            self.stream.send_blueprint(self._blueprint(roots))

    def _blueprint(self, roots: list[str]) -> rrb.Blueprint:
        """A 3D view per recorded env side by side, above the errors and the actions over time."""
        if not roots:
            return rrb.Blueprint(rrb.Spatial3DView(origin="/"))
        return rrb.Blueprint(
            rrb.Vertical(
                rrb.Grid(*[rrb.Spatial3DView(origin=r, name=r.strip("/").replace("/", " ")) for r in roots]),
                rrb.Horizontal(
                    rrb.TimeSeriesView(
                        name="error (vertices)", origin="/", contents=[f"{r}/error_vertices" for r in roots]
                    ),
                    rrb.TimeSeriesView(
                        name="action (mm)", origin="/", contents=[f"{r}/action" for r in roots]
                    ),
                ),
                row_shares=[3, 1],
            ),
            collapse_panels=True,
        )


@dataclass
class _Frame:
    """What one step callback copies out of the task: the recorded envs' state after a step."""

    step: int
    update: int
    positions: np.ndarray
    """(n, V, 3) float32."""
    alive: np.ndarray
    """(n, V) bool."""
    displacements: np.ndarray | None
    """(n, 3), None when no recorded env is grasped."""
    action: np.ndarray | None
    """(n, 3), or None at the reset and for policies that return no moves."""


@dataclass
class _EnvSetup:
    """One recorded env of one task: what its frames are drawn with, copied from the task when the
    episode starts (so that the worker thread never reads a task that the caller goes on changing)."""

    root: str
    contour: Contour
    tip: np.ndarray
    """(T, 4) the scissor trajectory."""
    pinch: np.ndarray
    disc: np.ndarray | None
    """(V,) bool grasped vertices, None without a grasp."""
    step_s: float
    """Simulated seconds per env step."""
    # Filled in on the worker thread by _Episode._prepare, then updated frame batch by frame batch:
    contour_matrix: sparse.csr_matrix | None = None
    """(K, V) bilinear weights of the contour's K points on the sheet's vertices."""
    intended: np.ndarray | None = None
    cut_runs: np.ndarray | None = None
    height_range: tuple[float, float] | None = None
    disc_origin: np.ndarray | None = None
    last_alive: np.ndarray | None = None
    last_error: float = 0.0


@dataclass
class _TaskSetup:
    """What every recorded env of one task shares."""

    grid: SheetGrid
    springs: tuple[str, ...]
    triangles: np.ndarray
    """:func:`grid_triangles`, built once per task."""
    envs: list[_EnvSetup]


class _Episode:
    """The step callback of one method. In the stepping loop it only copies the recorded envs' state
    (only theirs: :meth:`~warpcut.simulator.Simulator.read_envs`); every :data:`WORKER_BATCH_FRAMES`
    frames it hands the batch to the recorder's worker, which scores it and sends it as rerun columns
    (or, without a worker, does that itself every :data:`FLUSH_FRAMES` frames)."""

    def __init__(self, recorder: Recorder, method: str):
        self.recorder = recorder
        self.root = "/" + rr.escape_entity_path_part(method)
        self.task: CuttingTask | None = None
        self.envs = np.zeros(0, dtype=np.intp)
        self.env_roots: list[str] = []
        self.frames: list[_Frame] = []
        self.threaded = self.grasped = False

    def __call__(self, task: CuttingTask, action: np.ndarray | None) -> None:
        if task is not self.task:
            self._start(task)
        step = task.step_index
        if step % self.recorder.every and not task.done:
            return
        envs = self.envs
        positions, alive = task.sim.read_envs(envs)
        self.frames.append(
            _Frame(
                step,
                task.update_index,
                positions,
                alive,
                task.sim.displacement.numpy()[envs] if self.grasped else None,
                None if action is None else np.asarray(action, dtype=np.float64).reshape(-1, 3)[envs],
            )
        )
        if self.threaded:
            if len(self.frames) >= WORKER_BATCH_FRAMES or task.done:
                self.flush()
        elif len(self.frames) >= FLUSH_FRAMES:
            self.flush()

    def _start(self, task: CuttingTask) -> None:
        """Copy what the frames of ``task`` are drawn with; the worker derives the rest."""
        self.flush()
        self.task = task
        self.threaded = self.recorder._threaded(task)
        grid, config = task.grid, task.config
        self.envs = np.arange(min(self.recorder.envs, task.num_envs))
        self.env_roots = [f"{self.root}/env_{env}" for env in self.envs]
        dt = np.asarray(task.sim.params["dt"], dtype=np.float64).reshape(-1)
        envs = [
            _EnvSetup(
                root=root,
                contour=task.contours[env],
                tip=task.trajectories[env].tip,
                pinch=task.pinch_points[env].copy(),
                disc=grid.disc_mask(task.pinch_points[env], config.grasp_radius) & ~task.sim.fixture
                if task.sim.grasped[env]
                else None,
                step_s=float(dt[env % dt.size]) * config.updates_per_step,
            )
            for env, root in zip(self.envs, self.env_roots, strict=True)
        ]
        self.grasped = any(env.disc is not None for env in envs)
        setup = _TaskSetup(grid, config.springs, grid_triangles(grid), envs)
        self.setup = setup
        self.recorder._submit(lambda: self._prepare(setup), self.threaded)

    def _prepare(self, task_setup: _TaskSetup) -> None:
        """Per-env constants (contour cells, intended region, cutting runs) and the static entities."""
        stream, grid = self.recorder.stream, task_setup.grid
        # Points every half spacing follow the deformed sheet closely enough; the contour's own points
        # (every 0.5 mm for the built-ins) would cost several times more to interpolate every frame.
        spacing = 0.5 * min(grid.spacing_mm)
        for setup in task_setup.envs:
            vertices, weights = material_cells(_polyline(setup.contour, spacing), grid)
            rows = np.repeat(np.arange(len(vertices)), vertices.shape[1])
            setup.contour_matrix = sparse.csr_matrix(
                (weights.ravel(), (rows, vertices.ravel())), shape=(len(vertices), grid.num_vertices)
            )
            setup.intended = intended_mask(setup.contour.intended_region(), grid)
            setup.cut_runs = _cutting_runs(setup.tip)
            where = "none" if setup.disc is None else f"({setup.pinch[0]:.1f}, {setup.pinch[1]:.1f}) mm"
            stream.log(
                f"{setup.root}/info",
                rr.TextDocument(
                    f"contour {setup.contour.name}, pinch point {where}; "
                    f"vertex colours: {self.recorder.colour_by}"
                ),
                static=True,
            )
            stream.log(f"{setup.root}/action", rr.SeriesLines(names=["x", "y", "z"]), static=True)
            stream.log(f"{setup.root}/error_vertices", rr.SeriesLines(names="error (vertices)"), static=True)
        if self.threaded:
            self.recorder._send_blueprint()  # off the stepping thread; close() sends it otherwise

    def flush(self) -> None:
        """Hand the buffered frames to the worker (or send them now, unless ``threaded``)."""
        frames, self.frames = self.frames, []
        if frames:
            setup = self.setup
            self.recorder._submit(lambda: self._send(frames, setup), self.threaded)

    def _send(self, frames: list[_Frame], task_setup: _TaskSetup) -> None:
        """Send a batch of frames of every recorded env."""
        steps = np.array([f.step for f in frames])
        updates = np.array([f.update for f in frames])
        positions = np.stack([f.positions for f in frames], axis=1)  # (n, F, V, 3)
        alive = np.stack([f.alive for f in frames], axis=1)
        displacements = (
            np.stack([f.displacements for f in frames], axis=1)
            if frames[0].displacements is not None
            else np.zeros((len(task_setup.envs), len(frames), 3))
        )
        acted = [f for f in frames if f.action is not None]
        action_steps = np.array([f.step for f in acted], dtype=np.int64)
        for k, setup in enumerate(task_setup.envs):
            actions = np.array([f.action[k] for f in acted]).reshape(-1, 3)
            self._send_env(
                task_setup,
                setup,
                steps,
                updates,
                positions[k],
                alive[k],
                displacements[k],
                action_steps,
                actions,
            )

    def _send_env(
        self,
        task_setup: _TaskSetup,
        setup: _EnvSetup,
        steps: np.ndarray,
        updates: np.ndarray,
        positions: np.ndarray,
        alive: np.ndarray,
        displacements: np.ndarray,
        action_steps: np.ndarray,
        actions: np.ndarray,
    ) -> None:
        """One env's frames: ``positions`` (F, V, 3), ``alive`` (F, V), ``displacements`` (F, 3)."""
        stream, grid = self.recorder.stream, task_setup.grid
        frames, num_vertices = len(steps), grid.num_vertices

        def send(entity: str, columns, at: np.ndarray = steps) -> None:
            times = [
                rr.TimeColumn("step", sequence=at),
                rr.TimeColumn("sim_time", duration=at * setup.step_s),
            ]
            stream.send_columns(f"{setup.root}/{entity}", indexes=times, columns=columns, strict=True)

        if setup.height_range is None:
            # Colours and the arrow's origin stay fixed at the episode's first frame (the settled sheet).
            z = positions[0, :, 2]
            setup.height_range = (float(z.min()), max(float(z.max()), float(z.min()) + 1.0))
            if setup.disc is not None:
                setup.disc_origin = positions[0, setup.disc].mean(axis=0)

        if self.recorder.colour_by == "strain":
            colours = _ramp(vertex_strain(positions, alive, grid, task_setup.springs), 0.0, STRAIN_FULL_SCALE)
        else:
            colours = _ramp(positions[..., 2], *setup.height_range)
        send(
            "sheet",
            rr.Mesh3D.columns(
                vertex_positions=positions.reshape(-1, 3), vertex_colors=colours.reshape(-1)
            ).partition(np.full(frames, num_vertices)),
        )
        # The topology and the error change only when the scissors remove vertices.
        changed = np.ones(frames, dtype=bool)
        changed[1:] = np.any(alive[1:] != alive[:-1], axis=1)
        if setup.last_alive is not None:
            changed[0] = bool(np.any(alive[0] != setup.last_alive))
        setup.last_alive = alive[-1].copy()
        if changed.any():
            triangles = task_setup.triangles
            kept = alive[changed][:, triangles].all(axis=2)  # (changed frames, triangles)
            faces = triangles[np.nonzero(kept)[1]]
            send(
                "sheet",
                rr.Mesh3D.columns(triangle_indices=faces).partition(kept.sum(axis=1)),
                at=steps[changed],
            )
            # Unchanged frames carry the last error forward.
            scored = np.concatenate(
                [[setup.last_error], _error_vertices(alive[changed], setup.intended, grid)]
            )
            errors = scored[np.cumsum(changed)]
        else:
            errors = np.full(frames, setup.last_error)
        setup.last_error = float(errors[-1])
        send("error_vertices", rr.Scalars.columns(scalars=errors))

        # All frames' contours in one product: (K, V) @ (V, F * 3).
        by_vertex = np.moveaxis(positions, 0, 1).reshape(num_vertices, frames * 3)
        contour = np.moveaxis((setup.contour_matrix @ by_vertex).reshape(-1, frames, 3), 1, 0)
        send("contour", rr.LineStrips3D.columns(strips=contour))

        trajectory = setup.tip
        current = np.clip(updates - 1, 0, len(trajectory) - 1)
        cutting = (trajectory[current, 3] > 0) & (updates <= len(trajectory))
        send(
            "tip",
            rr.Points3D.columns(
                positions=trajectory[current, :3],
                colors=np.where(cutting[:, None], _CUTTING_RGB, _TRAVEL_RGB),
            ),
        )
        strips, counts = _cut_paths(trajectory, setup.cut_runs, updates)
        send("cut_path", rr.LineStrips3D.columns(strips=strips).partition(counts))

        if setup.disc is not None:
            send(
                "grasp/disc",
                rr.Points3D.columns(positions=positions[:, setup.disc].reshape(-1, 3)).partition(
                    [int(setup.disc.sum())] * frames
                ),
            )
            send(
                "grasp/displacement",
                rr.Arrows3D.columns(
                    origins=np.broadcast_to(setup.disc_origin, (frames, 3)), vectors=displacements
                ),
            )
        if len(action_steps):
            send("action", rr.Scalars.columns(scalars=actions).partition([3] * len(actions)), at=action_steps)


def vertex_strain(
    positions: np.ndarray,
    alive: np.ndarray,
    grid: SheetGrid,
    springs: tuple[str, ...] = ("structural", "shear"),
) -> np.ndarray:
    """Per vertex, the mean relative stretch ``|length / rest - 1|`` of its live springs.

    Args:
        positions: (F, V, 3) vertex positions (mm) of F frames of one sheet.
        alive: (F, V) bool; a spring is live while both its ends are alive.
        grid: The sheet's rest layout (V = ny * nx vertices).
        springs: The spring families simulated (:attr:`~warpcut.config.SimConfig.springs`).

    Returns:
        (F, V) float32; 0 for a vertex without live springs.
    """
    frames = len(positions)
    ny, nx = grid.ny, grid.nx
    # Component-major, so that every spring direction is a pair of shifted slices of the grid: no gather.
    p = np.ascontiguousarray(np.moveaxis(np.asarray(positions, dtype=np.float32), -1, 0))
    p = p.reshape(3, frames, ny, nx)
    a = np.asarray(alive, dtype=bool).reshape(frames, ny, nx)
    total = np.zeros((frames, ny, nx), dtype=np.float32)
    count = np.zeros((frames, ny, nx), dtype=np.float32)
    for di, dj, rest in _spring_directions(grid, springs):
        start = (slice(0, ny - dj), slice(max(0, -di), nx - max(0, di)))
        end = (slice(dj, ny), slice(max(0, di), nx + min(0, di)))
        d = p[(slice(None), slice(None), *end)] - p[(slice(None), slice(None), *start)]
        d *= d
        strain = np.sqrt(d[0] + d[1] + d[2])
        strain *= np.float32(1.0 / rest)
        strain -= 1.0
        np.abs(strain, out=strain)
        live = a[(slice(None), *start)] & a[(slice(None), *end)]
        strain *= live
        for ends in (start, end):
            total[(slice(None), *ends)] += strain
            count[(slice(None), *ends)] += live
    return (total / np.maximum(count, 1.0)).reshape(frames, ny * nx)


def _spring_directions(grid: SheetGrid, springs: tuple[str, ...]) -> list[tuple[int, int, float]]:
    """The springs of ``springs``' families as ``(di, dj, rest length in mm)``: every vertex ``(row, col)``
    with ``(row + dj, col + di)`` on the grid has one (both parities of each colour)."""
    directions = sorted({(c.di, c.dj) for c in spring_colours(springs)})
    return [(di, dj, math.hypot(di * grid.spacing_mm[0], dj * grid.spacing_mm[1])) for di, dj in directions]


def _error_vertices(alive: np.ndarray, intended: np.ndarray, grid: SheetGrid) -> np.ndarray:
    """(F,) symmetric difference in vertices of F alive masks (F, V) against the ``intended`` mask (V,):
    :func:`~warpcut.scoring.symmetric_difference`'s ``error_vertices``. One labelling of all frames finds
    those in which the sheet is still one piece: nothing is separated there, so the error is the intended
    area; only the others are scored in full."""
    frames = len(alive)
    labels, _ = ndimage.label(alive.reshape(frames, grid.ny, grid.nx), structure=_FRAME_CROSS)
    # Each label lies within one frame (the structure does not join frames): count the labels per frame.
    label_frame = np.zeros(labels.max() + 1, dtype=np.intp)
    label_frame[labels.reshape(frames, -1)] = np.arange(frames)[:, None]
    pieces = np.bincount(label_frame[1:], minlength=frames)
    errors = np.full(frames, float(intended.sum()))
    for f in np.flatnonzero(pieces > 1):
        errors[f] = np.count_nonzero(achieved_mask(alive[f], intended, grid)[0] != intended)
    return errors


# 4-connectivity within a frame, none across frames (as scoring.achieved_mask labels one frame).
_FRAME_CROSS = np.zeros((3, 3, 3), dtype=bool)
_FRAME_CROSS[1] = ndimage.generate_binary_structure(2, 1)


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
    points = contour.resample(spacing_mm)
    return np.vstack([points, points[:1]]) if contour.closed else points


# Rerun's arrow types of a 3D point and of a 3D line strip (rerun.components.LineStrip3D), spelled out
# (tests/test_recording.py checks them against rerun's): the strips of all frames are built as one arrow
# array from flat numpy buffers, without a Python object per strip.
_POINT3D_TYPE = pa.list_(pa.field("item", pa.float32(), nullable=False), 3)
_LINE_STRIP3D_TYPE = pa.list_(pa.field("item", _POINT3D_TYPE, nullable=False))


def _cut_paths(tip: np.ndarray, runs: np.ndarray, updates: np.ndarray) -> tuple[pa.Array, np.ndarray]:
    """The path cut so far after each of F ``updates``: per frame, the part of every cutting run of the
    (T, 4) ``tip`` trajectory that the scissors have passed (at least two points), as a rerun line strip
    array of all frames' strips, and (F,) how many strips each frame has."""
    starts = runs[:, 0]
    lengths = np.minimum(runs[None, :, 1], np.asarray(updates)[:, None]) - starts[None, :]  # (F, R)
    lengths = np.where(lengths >= 2, lengths, 0)
    counts = np.count_nonzero(lengths, axis=1)
    kept = lengths.ravel() > 0
    lengths, starts = (
        lengths.ravel()[kept],
        np.broadcast_to(starts, (len(updates), len(starts))).ravel()[kept],
    )
    offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int32)
    points = tip[np.repeat(starts - offsets[:-1], lengths) + np.arange(offsets[-1]), :3]
    inner = pa.FixedSizeListArray.from_arrays(pa.array(points.astype(np.float32).ravel()), type=_POINT3D_TYPE)
    return pa.ListArray.from_arrays(pa.array(offsets), inner, type=_LINE_STRIP3D_TYPE), counts


def _cutting_runs(tip: np.ndarray) -> np.ndarray:
    """(R, 2) ``[start, end)`` update ranges in which the tip cuts."""
    cutting = np.concatenate([[0], (tip[:, 3] > 0).astype(np.int8), [0]])
    return np.flatnonzero(np.diff(cutting)).reshape(-1, 2)


def _ramp(values: np.ndarray, low: float, high: float) -> np.ndarray:
    """Packed RGBA (uint32) of ``values`` on a viridis ramp from ``low`` to ``high`` (clipped)."""
    top = len(_RAMP_RGBA) - 1
    t = (np.asarray(values, dtype=np.float32) - np.float32(low)) * np.float32(top / (high - low))
    np.clip(t, 0.0, top, out=t)
    return _RAMP_RGBA[t.astype(np.intp)]


@dataclass
class RecordingSummary:
    """What a ``.rrd`` file holds, read back from it."""

    application_id: str
    """The rerun application id."""
    frames: int
    """Distinct ``step`` values recorded."""
    first_step: int
    last_step: int
    duration_s: float
    """Simulated time from the first to the last frame (s)."""
    entity_paths: list[str]
    """Every entity with data, sorted."""


def read_summary(path: str | os.PathLike) -> RecordingSummary:
    """Read a recording back: its frames, entity paths and duration.

    Raises:
        FileNotFoundError: There is no file at ``path``.
        ValueError: The file is not a readable rerun recording.
    """
    from rerun.chunk import RrdReader

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such recording")
    try:
        reader = RrdReader(path)
        recordings = reader.recordings()
        if not recordings:
            raise ValueError("it holds no recording")
        steps, durations, entities = set(), [], set()
        for chunk in reader.stream(store=recordings[0]):
            if chunk.entity_path.startswith("/__"):
                continue
            entities.add(chunk.entity_path)
            batch = chunk.to_record_batch()
            if "step" in batch.schema.names:
                steps.update(batch.column("step").to_pylist())
            if "sim_time" in batch.schema.names:
                durations.extend(v / 1e9 for v in batch.column("sim_time").cast("int64").to_pylist())
    except (OSError, ValueError, RuntimeError) as exc:
        raise ValueError(f"{path}: not a readable rerun recording ({str(exc).splitlines()[0]})") from None
    return RecordingSummary(
        application_id=recordings[0].application_id,
        frames=len(steps),
        first_step=min(steps, default=0),
        last_step=max(steps, default=0),
        duration_s=(max(durations) - min(durations)) if durations else 0.0,
        entity_paths=sorted(entities),
    )
