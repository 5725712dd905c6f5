"""Rerun recordings of cutting episodes, and what a recording holds when read back.

A :class:`Recorder` writes one ``.rrd`` file. Every method recorded into it gets its own entity tree,
``/{method}/env_{k}/...`` for the first ``envs`` envs of its task, so methods cut on the same contour
can be compared side by side in one viewer (the recording carries a blueprint that lays them out so):

* ``sheet``: the sheet as a triangle mesh (two triangles per grid cell, faces touching a cut vertex
  dropped), vertex colours by height;
* ``contour``: the intended contour carried along with the material (bilinear lookup on the sheet);
* ``tip`` and ``cut_path``: the scissor tip (red while cutting) and the path it has cut so far;
* ``grasp/disc`` and ``grasp/displacement``: the grasped vertices and the grasp's displacement;
* ``action``: the tensioning action (mm) as three scalar series;
* ``error_vertices``: the running symmetric difference between the intended and the separated region.

Frames are on the ``step`` timeline (0 after the reset, then one per env step) and on ``sim_time``
(simulated seconds). Recording must not slow the stepping loop down, so the step callback only copies
the recorded envs' state; the frames are turned into rerun columns (``send_columns``) and scored in
batches, every 64 frames and when the recorder closes. ``every=k`` keeps only every k-th step (plus the
first and the last) for long runs or big sheets.

The file is written beside its target under a temporary name and renamed when the recorder closes,
also when an exception or Ctrl-C ends the run early, so a readable recording of what happened so far
always remains. Use it as a context manager::

    with Recorder("logs/run/recording.rrd", envs=2) as recorder:
        task.run(policy, on_step=recorder.on_step("fixed"))
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from warpcut.config import SheetGrid
from warpcut.contours import Contour
from warpcut.io import plain_file_mode
from warpcut.scoring import symmetric_difference
from warpcut.task import CuttingTask, interpolate, material_cells

StepCallback = Callable[[CuttingTask, "np.ndarray | None"], None]
"""``on_step(task, action)`` as :meth:`CuttingTask.run` calls it."""

FLUSH_FRAMES = 64
"""Frames buffered per method before they are sent to the file."""

# Vertex colours by height, low (dark blue) to high (yellow): viridis, from five stops to 256 entries.
_VIRIDIS_STOPS = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]])
_HEIGHT_COLOURS = np.stack(
    [np.interp(np.linspace(0, 4, 256), np.arange(5), _VIRIDIS_STOPS[:, c]) for c in range(3)], axis=1
).astype(np.uint8)
_CUTTING_RGB, _TRAVEL_RGB = (230, 40, 40), (150, 150, 150)


class Recorder:
    """Records cutting episodes into one ``.rrd`` file.

    Args:
        path: The ``.rrd`` file to write (its folder is created).
        envs: How many envs (the first ones) of each task to record.
        application_id: Rerun application id; the viewer groups recordings by it.
        every: Record every ``every``-th env step only (the reset and the last step always).

    Raises:
        ValueError: ``envs`` or ``every`` is not a positive integer.
    """

    def __init__(
        self, path: str | os.PathLike, envs: int = 1, application_id: str = "warpcut", every: int = 1
    ):
        for name, value in (("envs", envs), ("every", every)):
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}: must be a positive integer (got {value!r})")
        self.path = Path(path)
        self.envs, self.every = envs, every
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=self.path.parent, prefix=f".{self.path.name}.", suffix=".tmp")
        os.fchmod(fd, plain_file_mode())
        os.close(fd)
        self._tmp = Path(tmp)
        self.stream = rr.RecordingStream(application_id)
        self.stream.save(self._tmp)
        self.stream.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._episodes: dict[str, _Episode] = {}
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
        """Send the buffered frames and the blueprint, finish the file and move it into place."""
        if self.closed:
            return self.path
        self.closed = True
        try:
            for episode in self._episodes.values():
                episode.flush()
            self.stream.send_blueprint(self._blueprint())
            self.stream.flush()
        finally:
            self.stream.disconnect()
            os.replace(self._tmp, self.path)
        return self.path

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def _blueprint(self) -> rrb.Blueprint:
        """A 3D view per recorded env side by side, above the errors and the actions over time."""
        roots = [root for e in self._episodes.values() for root in e.env_roots]
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
    alive: np.ndarray
    displacements: np.ndarray
    action: np.ndarray | None


class _Episode:
    """The step callback of one method: buffers frames and sends them as rerun columns."""

    def __init__(self, recorder: Recorder, method: str):
        self.recorder = recorder
        self.root = "/" + rr.escape_entity_path_part(method)
        self.task: CuttingTask | None = None
        self.env_roots: list[str] = []
        self.frames: list[_Frame] = []

    def __call__(self, task: CuttingTask, action: np.ndarray | None) -> None:
        if task is not self.task:
            self._start(task)
        step = task.step_index
        if step % self.recorder.every and not task.done:
            return
        envs = self.envs
        self.frames.append(
            _Frame(
                step,
                task.update_index,
                task.sim.positions()[envs],
                task.sim.alive_mask()[envs],
                task.sim.displacements()[envs],
                None if action is None else np.asarray(action, dtype=np.float64).reshape(-1, 3)[envs],
            )
        )
        if len(self.frames) >= FLUSH_FRAMES:
            self.flush()

    def _start(self, task: CuttingTask) -> None:
        """Per-task constants (topology, contour cells, grasp discs), and the static entities."""
        self.flush()
        self.task = task
        grid, stream = task.grid, self.recorder.stream
        self.envs = np.arange(min(self.recorder.envs, task.num_envs))
        self.env_roots = [f"{self.root}/env_{env}" for env in self.envs]
        self.triangles = grid_triangles(grid)
        # Points every half spacing follow the deformed sheet closely enough; the contour's own points
        # (every 0.5 mm for the built-ins) would cost several times more to interpolate every frame.
        spacing = 0.5 * min(grid.spacing_mm)
        self.contour_cells = [
            material_cells(_polyline(task.contours[env], spacing), grid) for env in self.envs
        ]
        self.regions = [task.contours[env].intended_region() for env in self.envs]
        self.cut_runs = [_cutting_runs(task.trajectories[env].tip) for env in self.envs]
        dt = np.asarray(task.sim.params["dt"], dtype=np.float64).reshape(-1)
        self.step_s = [float(dt[env % dt.size]) * task.config.updates_per_step for env in self.envs]
        self.discs = [
            grid.disc_mask(task.pinch_points[env], task.config.grasp_radius) & ~task.sim.fixture
            if task.sim.grasped[env]
            else None
            for env in self.envs
        ]
        self.height_range: list[tuple[float, float] | None] = [None] * len(self.envs)
        self.disc_origin: list[np.ndarray | None] = [None] * len(self.envs)
        self.last_alive: list[np.ndarray | None] = [None] * len(self.envs)
        self.last_error = [0.0] * len(self.envs)
        for env, root in zip(self.envs, self.env_roots, strict=True):
            pinch = task.pinch_points[env]
            where = f"({pinch[0]:.1f}, {pinch[1]:.1f}) mm" if task.sim.grasped[env] else "none"
            stream.log(
                f"{root}/info",
                rr.TextDocument(f"contour {task.contours[env].name}, pinch point {where}"),
                static=True,
            )
            stream.log(f"{root}/action", rr.SeriesLines(names=["x", "y", "z"]), static=True)
            stream.log(f"{root}/error_vertices", rr.SeriesLines(names="error (vertices)"), static=True)

    def flush(self) -> None:
        """Send the buffered frames to the file."""
        frames, self.frames = self.frames, []
        if not frames:
            return
        positions = np.stack([f.positions for f in frames], axis=1)  # (n, F, V, 3)
        alive = np.stack([f.alive for f in frames], axis=1)
        displacements = np.stack([f.displacements for f in frames], axis=1)
        acted = [f for f in frames if f.action is not None]
        for k in range(len(self.envs)):
            self._send_env(
                k,
                np.array([f.step for f in frames]),
                np.array([f.update for f in frames]),
                positions[k],
                alive[k],
                displacements[k],
                np.array([f.step for f in acted]),
                np.array([f.action[k] for f in acted]).reshape(-1, 3),
            )

    def _send_env(
        self,
        k: int,
        steps: np.ndarray,
        updates: np.ndarray,
        positions: np.ndarray,
        alive: np.ndarray,
        displacements: np.ndarray,
        action_steps: np.ndarray,
        actions: np.ndarray,
    ) -> None:
        """One env's frames: ``positions`` (F, V, 3), ``alive`` (F, V), ``displacements`` (F, 3)."""
        task, stream, root = self.task, self.recorder.stream, self.env_roots[k]
        env, grid = int(self.envs[k]), task.grid
        frames, num_vertices = len(steps), grid.num_vertices

        def send(entity: str, columns, at: np.ndarray = steps) -> None:
            times = [
                rr.TimeColumn("step", sequence=at),
                rr.TimeColumn("sim_time", duration=at * self.step_s[k]),
            ]
            stream.send_columns(f"{root}/{entity}", indexes=times, columns=columns, strict=True)

        if self.height_range[k] is None:
            # Colours and the arrow's origin stay fixed at the episode's first frame (the settled sheet).
            z = positions[0, :, 2]
            self.height_range[k] = (float(z.min()), max(float(z.max()), float(z.min()) + 1.0))
            if self.discs[k] is not None:
                self.disc_origin[k] = positions[0, self.discs[k]].mean(axis=0)

        colours = _height_colours(positions[..., 2], *self.height_range[k])
        send(
            "sheet",
            rr.Mesh3D.columns(
                vertex_positions=positions.reshape(-1, 3), vertex_colors=colours.reshape(-1, 3)
            ).partition([num_vertices] * frames),
        )
        # The topology and the error change only when the scissors remove vertices.
        previous = self.last_alive[k]
        changed = np.ones(frames, dtype=bool)
        changed[1:] = np.any(alive[1:] != alive[:-1], axis=1)
        if previous is not None:
            changed[0] = bool(np.any(alive[0] != previous))
        self.last_alive[k] = alive[-1].copy()
        errors = np.full(frames, np.nan)
        if changed.any():
            kept = alive[changed][:, self.triangles].all(axis=2)  # (changed frames, triangles)
            faces = np.broadcast_to(self.triangles, (*kept.shape, 3))[kept]
            send(
                "sheet",
                rr.Mesh3D.columns(triangle_indices=faces).partition(kept.sum(axis=1)),
                at=steps[changed],
            )
            errors[changed] = symmetric_difference(alive[changed], self.regions[k], grid).error_vertices
        for f in range(frames):
            errors[f] = self.last_error[k] if np.isnan(errors[f]) else errors[f]
            self.last_error[k] = errors[f]
        send("error_vertices", rr.Scalars.columns(scalars=errors))

        vertices, weights = self.contour_cells[k]
        contour = interpolate(
            positions,
            np.broadcast_to(vertices, (frames, *vertices.shape)),
            np.broadcast_to(weights, (frames, *weights.shape)),
        )
        send("contour", rr.LineStrips3D.columns(strips=contour))

        trajectory = task.trajectories[env].tip
        current = np.clip(updates - 1, 0, len(trajectory) - 1)
        cutting = (trajectory[current, 3] > 0) & (updates <= len(trajectory))
        send(
            "tip",
            rr.Points3D.columns(
                positions=trajectory[current, :3],
                colors=np.where(cutting[:, None], _CUTTING_RGB, _TRAVEL_RGB),
            ),
        )
        strips, counts = [], []
        for u in updates:
            frame_strips = [trajectory[s : min(e, u), :3] for s, e in self.cut_runs[k] if min(e, u) - s >= 2]
            strips.extend(frame_strips)
            counts.append(len(frame_strips))
        send(
            "cut_path",
            rr.LineStrips3D.columns(strips=strips or np.zeros((0, 2, 3))).partition(counts),
        )

        disc = self.discs[k]
        if disc is not None:
            send(
                "grasp/disc",
                rr.Points3D.columns(positions=positions[:, disc].reshape(-1, 3)).partition(
                    [int(disc.sum())] * frames
                ),
            )
            send(
                "grasp/displacement",
                rr.Arrows3D.columns(
                    origins=np.broadcast_to(self.disc_origin[k], (frames, 3)), vectors=displacements
                ),
            )
        if len(action_steps):
            send("action", rr.Scalars.columns(scalars=actions).partition([3] * len(actions)), at=action_steps)


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


def _cutting_runs(tip: np.ndarray) -> np.ndarray:
    """(R, 2) ``[start, end)`` update ranges in which the tip cuts."""
    cutting = np.concatenate([[0], (tip[:, 3] > 0).astype(np.int8), [0]])
    return np.flatnonzero(np.diff(cutting)).reshape(-1, 2)


def _height_colours(z: np.ndarray, low: float, high: float) -> np.ndarray:
    """uint8 RGB of heights ``z`` (mm) on a viridis ramp from ``low`` to ``high``."""
    t = np.clip((z - low) / (high - low), 0.0, 1.0)
    return _HEIGHT_COLOURS[(t * (len(_HEIGHT_COLOURS) - 1)).astype(np.intp)]


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
