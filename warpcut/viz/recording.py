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
* ``fiducials``: the fiducial points a camera tracks on the gauze (what the paper's policy observes), green
  where visible, grey where hidden (cut away or under the cutting arm's shaft; :mod:`warpcut.fiducials`):
  the fiducials of the env that the task belongs to, or where a task has none (baselines, ``simulate``),
  :data:`~warpcut.fiducials.NUM_FIDUCIALS` drawn for the recording as an env draws them (seeded by the env
  index);
* ``action``: the tensioning action (mm) as three scalar series;
* ``path``: the points the scissors went through in material coordinates (the traced cut path,
  :meth:`~warpcut.sim.simulator.Simulator.trace_path`), drawn on the rest plane z = 0 above the sagging
  sheet, where ``material_contour`` (static) draws the intended contour the same way;
* ``path_error_vertices``: the path score (:mod:`warpcut.scoring`) of the cut so far, as if the cut were
  closed at that step (the last frame's is the episode's path score);
* ``separated_error_vertices``: the running symmetric difference between the intended and the separated
  region (the separated score).

Frames are on the ``step`` timeline (0 after the reset, then one per env step) and on ``sim_time``
(simulated seconds). Recording must not slow the stepping loop down, so the step callback only copies
the recorded envs' state, and only theirs (:meth:`~warpcut.sim.simulator.Simulator.read_state`, a few
microseconds); the frames are scored and turned into rerun columns (``send_columns``) in batches, all
frames of a batch at once (one labelling for the errors, shifted grid slices for the strain, one sparse
product for the contour), where ``background`` says:

* ``"process"`` (the default on a POSIX machine with more than one core): in a recorder process. The step
  callback writes the copied state into a pipe, :data:`PROCESS_BATCH_FRAMES` frames at a time (one
  ``writev``, ~0.1 ms for 32 frames of a 25 x 25 sheet; :data:`FLUSH_FRAMES` where the simulator's threads
  use every core); the process scores the frames, builds the columns, runs rerun's encoding and writes
  the file, on another core and without holding the stepping process's GIL, at a lower priority
  (:data:`PROCESS_NICE`, once it has imported what it needs). The stepping process does not import rerun.
  The process (:mod:`warpcut.viz.process`) is started when the first :class:`Recorder` is created,
  or earlier by :func:`start_recorder_process` (its start-up, ~0.7 s on an idle core, overlaps the
  caller's work), and is kept for the next one, so later recordings in the same Python process do not pay
  for it again.
* ``"thread"``: on a worker thread of the stepping process, every :data:`WORKER_BATCH_FRAMES` frames (it
  runs only while the stepping thread releases the GIL);
* ``False``: in the step callback itself, every :data:`FLUSH_FRAMES` frames.

Without a step callback (``on_step=None``) :meth:`CuttingTask.run` does none of this. ``every=k`` keeps
only every k-th step (plus the first and the last) for long runs or big sheets. ``docs/performance.md``
has the measured overhead (``scripts/recording_overhead.py``).

The file is written beside its target under a temporary name and renamed when the recorder closes,
also when an exception or Ctrl-C ends the run early, so a readable recording of what happened so far
always remains; a recorder that recorded no episode writes nothing (and leaves a file already at its
path as it was). :meth:`Recorder.close` returns once the file is complete. The recorder process ignores
Ctrl-C (it runs in its own process group) and finishes the file when the recorder closes, or on its own
when the stepping process dies. Use a recorder as a context manager::

    with Recorder("logs/run/recording.rrd", envs=2) as recorder:
        task.run(policy, on_step=recorder.on_step("fixed"))
"""

from __future__ import annotations

import math
import os
import pickle
import queue
import struct
import subprocess
import tempfile
import threading
import time
import traceback
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage

from warpcut.contours import Contour
from warpcut.fiducials import NUM_FIDUCIALS, SHAFT_RADIUS_MM, sample_fiducials, visible
from warpcut.io import plain_file_mode
from warpcut.scoring import achieved_mask, intended_mask
from warpcut.sim.config import SheetGrid, SimConfig
from warpcut.sim.material import interpolate, material_cells
from warpcut.sim.springs import spring_colours
from warpcut.viz.process import (  # noqa: F401 - PROCESS_NICE, CLOSE_TIMEOUT_S: documented here too
    _HEAD,
    CLOSE_TIMEOUT_S,
    PROCESS_NICE,
    RecordingError,
    _Child,
    _default_background,
    _Messages,
    _pickled,
    start_recorder_process,
)

if TYPE_CHECKING:
    from warpcut.task import CuttingTask

StepCallback = Callable[["CuttingTask", "np.ndarray | None"], None]
"""``on_step(task, action)`` as :meth:`CuttingTask.run` calls it."""

FLUSH_FRAMES = 128
"""Frames buffered per method before they are scored and sent to the file in the step callback
(``background=False``). Each batch costs ~3 ms on top of ~0.1 ms per frame (25 x 25 sheet), so few large
batches are cheapest; 128 frames of a 25 x 25 sheet hold ~1 MB per recorded env."""

WORKER_BATCH_FRAMES = 32
"""Frames handed to the worker thread at a time (``background="thread"``; and the rest when the episode
ends): smaller batches than :data:`FLUSH_FRAMES`, so that little work is left for :meth:`Recorder.close`
to wait for."""

PROCESS_BATCH_FRAMES = 32
"""Frames the step callback writes into the pipe to the recorder process at a time (``background=
"process"``; and the rest when the episode ends), and that the process then scores and sends as one
batch (or several such groups at once when it has fallen behind): one wake-up of the process per group,
not per frame (on a busy machine each wake-up may take the stepping thread's core for a moment), and
batches small enough that little is left for :meth:`Recorder.close` to wait for. Where the simulator's
threads use every core the groups hold :data:`FLUSH_FRAMES` frames instead: the process then only runs
on time taken from the stepping threads, and one large batch costs it least."""

PROCESS_LEAD_FRAMES = (10, 4)
"""The step callback also hands its frames to the recorder process when the episode is this many frames
from its end (each of them): the process scores them while the last steps run, in batches small enough
to be done before the next arrives, and only the last few frames (one small batch) are left when the
episode ends."""

BACKGROUND_MODES = ("process", "thread")
"""``Recorder(background=...)`` besides ``False`` (in the step callback) and ``None`` (the default)."""

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
_VISIBLE_RGB, _HIDDEN_RGB = (40, 200, 60), (110, 110, 110)
_CUTTING_RGBA, _TRAVEL_RGBA, _VISIBLE_RGBA, _HIDDEN_RGBA = (
    (r << 24) | (g << 16) | (b << 8) | 0xFF
    for r, g, b in (_CUTTING_RGB, _TRAVEL_RGB, _VISIBLE_RGB, _HIDDEN_RGB)
)


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
        background: Where the copied frames are scored, turned into rerun columns and written:
            ``"process"``: in a recorder process, so that the stepping loop only pays for copying the
            recorded envs' state into a pipe (the process is started here, or an idle one left by an
            earlier recorder of this Python process is reused); ``"thread"`` (or ``True``): on a worker
            thread of this process; ``False``: in the step callback itself, every :data:`FLUSH_FRAMES`
            frames. ``None`` (default): ``"process"`` on a POSIX machine with more than one core (a core
            the stepping loop may leave free), else ``False``.

    Raises:
        ValueError: ``envs`` or ``every`` is not a positive integer, ``colour_by`` is not one of
            :data:`COLOUR_FIELDS`, or ``background`` is none of the above.
        RecordingError: The recorder process could not be started.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        envs: int = 1,
        application_id: str = "warpcut",
        every: int = 1,
        colour_by: str = "strain",
        background: str | bool | None = None,
    ):
        for name, value in (("envs", envs), ("every", every)):
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"{name}: must be a positive integer (got {value!r})")
        if colour_by not in COLOUR_FIELDS:
            raise ValueError(f"colour_by: choose one of {COLOUR_FIELDS} (got {colour_by!r})")
        if background is None:
            background = _default_background()
        elif background is True:
            background = "thread"
        if background is not False and background not in BACKGROUND_MODES:
            raise ValueError(
                f"background: choose one of {BACKGROUND_MODES}, False or None (got {background!r})"
            )
        self.path = Path(path)
        self.envs, self.every, self.colour_by, self.background = envs, every, colour_by, background
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=self.path.parent, prefix=f".{self.path.name}.", suffix=".tmp")
        os.fchmod(fd, plain_file_mode())
        os.close(fd)
        self._tmp = Path(tmp)
        try:
            if background == "process":
                self._sink = _ProcessSink(self.path, self._tmp, application_id, colour_by)
            else:
                writer = _Writer(self._tmp, self.path, application_id, colour_by, bool(background))
                self._sink = _ThreadSink(writer) if background else _InlineSink(writer)
        except BaseException:
            self._tmp.unlink(missing_ok=True)
            raise
        self._episodes: dict[str, _Episode] = {}
        self.closed = False
        self.written = False
        """Whether :meth:`close` put the file in place (an episode was recorded)."""

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
        episode = _Episode(self, method, len(self._episodes))
        self._episodes[method] = episode
        return episode

    def close(self) -> Path | None:
        """Send the buffered frames and the blueprint, finish the file and move it into place; return
        its path once that is done (in the recorder process too). A recorder closed before any episode
        started (e.g. a run interrupted before its recorded evaluation) writes nothing, leaves a file
        already at :attr:`path` as it was, and returns None (:attr:`written` says which).

        Raises:
            RecordingError: The recorder process failed (the message names the recording and carries the
                process's error), died or did not finish within :data:`CLOSE_TIMEOUT_S`; the file (what it
                wrote so far) was moved into place.
            Exception: Whatever failed on the worker thread, after the file was moved into place.
        """
        if self.closed:
            return self.path if self.written else None
        self.closed = True
        keep = any(episode.started for episode in self._episodes.values())
        try:
            for episode in self._episodes.values():
                episode.flush(final=True)
        finally:
            self.written = keep  # also when the sink fails: it moves what it wrote into place
            self._sink.close(keep)
        return self.path if keep else None

    @property
    def recorded_envs(self) -> dict[str, int]:
        """How many envs were recorded of each method whose episode started: ``envs``, or fewer where its
        task had fewer."""
        return {method: len(e.envs) for method, e in self._episodes.items() if e.started}

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


@dataclass
class _Frame:
    """What one step callback copies out of the task: the recorded envs' state after a step."""

    step: int
    update: int
    state: np.ndarray
    """(n, V, 4) float32: positions (mm) and alive (1.0, or 0.0 where cut), as
    :meth:`~warpcut.sim.simulator.Simulator.read_state` copies them."""
    displacements: np.ndarray | None
    """(n, 3) float64, None when no recorded env is grasped."""
    action: np.ndarray | None
    """(n, 3) float64, or None at the reset and for policies that return no moves."""
    path_start: int = 0
    """The first update of ``path``."""
    path: np.ndarray | None = None
    """(n, U, 3) float32: the traced cut path (material x, y, status) of updates ``path_start ..
    path_start + U - 1``, those since the previous frame; None where the task does not trace it."""


@dataclass
class _EnvSetup:
    """One recorded env of one task: what its frames are drawn with, copied from the task when the
    episode starts (so that the writer never reads a task that the caller goes on changing)."""

    env: int
    contour: Contour
    tip: np.ndarray
    """(T, 4) the scissor trajectory."""
    pinch: np.ndarray
    disc: np.ndarray | None
    """(V,) bool grasped vertices, None without a grasp."""
    step_s: float
    """Simulated seconds per env step."""
    fiducials: np.ndarray | None
    """(K, 2) material points of the env's fiducials; None: the writer draws them."""
    shaft_radius_mm: float
    """The cutting arm's shaft radius, which hides the fiducials under it (mm)."""
    arc: np.ndarray | None = None
    """(T,) arc length along the contour of the point each update meant to cut (the path's order); None
    where the task does not trace the cut path."""
    # Filled in by the writer (_Writer.start), then updated frame batch by frame batch:
    root: str = ""
    """The env's entity path, ``/{method}/env_{env}``."""
    contour_matrix: object = None
    """(K, V) scipy.sparse bilinear weights of the contour's K points on the sheet's vertices."""
    intended: np.ndarray | None = None
    cut_runs: np.ndarray | None = None
    height_range: tuple[float, float] | None = None
    disc_origin: np.ndarray | None = None
    last_alive: np.ndarray | None = None
    last_error: float = 0.0
    path: np.ndarray | None = None
    """(T, 3) the traced cut path so far, filled frame batch by frame batch."""
    fiducial_cells: tuple[np.ndarray, np.ndarray] | None = None
    """(1, K, 4) vertices and weights of the fiducials' cells (:func:`~warpcut.sim.material.material_cells`)."""


@dataclass
class _TaskSetup:
    """What every recorded env of one task shares."""

    grid: SheetGrid
    config: SimConfig
    envs: list[_EnvSetup]
    triangles: np.ndarray | None = None
    """:func:`grid_triangles`, built by the writer once per task."""


class _Episode:
    """The step callback of one method. In the stepping loop it only copies the recorded envs' state
    (only theirs: :meth:`~warpcut.sim.simulator.Simulator.read_state`) and hands it to the recorder's sink
    (the recorder process, the worker thread or the writer itself) in batches of the sink's size."""

    def __init__(self, recorder: Recorder, method: str, key: int):
        self.recorder, self.method, self.key = recorder, method, key
        self.sink = recorder._sink
        self.task: CuttingTask | None = None
        self.started = False
        """Whether the sink took this episode's start (then the recording holds it, and is kept)."""
        self.envs = np.zeros(0, dtype=np.intp)
        self.read_state: Callable[..., np.ndarray] | None = None
        self.frames: list[_Frame] = []
        self.path_start = 0
        self.read_path: Callable[[int, int], np.ndarray] | None = None
        self.grasped = False
        self.batch_frames, self.leads = self.sink.batching(None)

    def __call__(self, task: CuttingTask, action: np.ndarray | None) -> None:
        if task is not self.task:
            self._start(task)
        step = task.step_index
        if step % self.recorder.every and not task.done:
            return
        envs = self.envs
        path = None
        update = min(task.update_index, task.horizon_updates)
        if self.read_path is not None and update > self.path_start:
            path = self.read_path(self.path_start, update)
        self.frames.append(
            _Frame(
                step,
                task.update_index,
                self.read_state(),
                task.sim.displacement.numpy()[envs].astype(np.float64) if self.grasped else None,
                None if action is None else np.asarray(action, dtype=np.float64).reshape(-1, 3)[envs],
                self.path_start,
                path,
            )
        )
        self.path_start = update
        if len(self.frames) >= self.batch_frames or task.done:
            self.flush(final=task.done)
        elif (task.num_steps - step) // self.recorder.every in self.leads:
            # Near the end: hand over what has gathered, so that only the last few frames are left for
            # close() to wait for.
            self.flush()

    def _start(self, task: CuttingTask) -> None:
        """Copy what the frames of ``task`` are drawn with; the writer derives the rest."""
        self.flush(final=True)
        self.batch_frames, self.leads = self.sink.batching(task)
        grid, config = task.grid, task.config
        self.envs = np.arange(min(self.recorder.envs, task.num_envs))
        self.read_state = task.sim.state_reader(self.envs)
        self.path_start = 0
        traced = task.sim.path is not None
        self.read_path = task.sim.path_reader(len(self.envs)) if traced else None
        arcs = task.target_arcs() if traced else None
        dt = np.asarray(task.sim.params["dt"], dtype=np.float64).reshape(-1)
        fiducials = task.fiducials if task.fiducials is not None and len(task.fiducials.material) else None
        envs = [
            _EnvSetup(
                env=int(env),
                contour=task.contours[env],
                tip=task.trajectories[env].tip,
                pinch=task.pinch_points[env].copy(),
                disc=grid.disc_mask(task.pinch_points[env], config.grasp_radius) & ~task.sim.fixture
                if task.sim.grasped[env]
                else None,
                step_s=float(dt[env % dt.size]) * config.updates_per_step,
                fiducials=None if fiducials is None else fiducials.material[env].copy(),
                shaft_radius_mm=SHAFT_RADIUS_MM if fiducials is None else fiducials.shaft_radius_mm,
                arc=None if arcs is None else arcs[env].copy(),
            )
            for env in self.envs
        ]
        self.grasped = any(env.disc is not None for env in envs)
        self.sink.start(self.key, self.method, _TaskSetup(grid, config, envs))
        self.started = True
        self.task = task  # last: a start cut short (Ctrl-C) is made again by the next step

    def flush(self, final: bool = False) -> None:
        """Hand the buffered frames to the sink; ``final``: the episode (or the recording) ends here."""
        frames, self.frames = self.frames, []
        if frames:
            self.sink.frames(self.key, frames, final)


class _InlineSink:
    """``background=False``: the step callback writes its frames itself, every :data:`FLUSH_FRAMES`."""

    def __init__(self, writer: _Writer):
        self.writer = writer

    def batching(self, task: CuttingTask | None) -> tuple[int, tuple[int, ...]]:
        """Frames per batch, and how many frames before an episode's end the rest is handed over."""
        return FLUSH_FRAMES, ()

    def start(self, key: int, method: str, setup: _TaskSetup) -> None:
        self.writer.start(key, method, setup)

    def frames(self, key: int, frames: list[_Frame], final: bool) -> None:
        self.writer.frames(key, frames)

    def close(self, keep: bool) -> None:
        self.writer.finish(keep=keep)


class _ThreadSink:
    """``background="thread"``: a worker thread writes the frames, in submission order."""

    def __init__(self, writer: _Writer):
        self.writer = writer
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._worker: threading.Thread | None = None
        self._failure: BaseException | None = None

    def batching(self, task: CuttingTask | None) -> tuple[int, tuple[int, ...]]:
        return WORKER_BATCH_FRAMES, ()

    def start(self, key: int, method: str, setup: _TaskSetup) -> None:
        self._submit(lambda: self.writer.start(key, method, setup))

    def frames(self, key: int, frames: list[_Frame], final: bool) -> None:
        self._submit(lambda: self.writer.frames(key, frames))

    def close(self, keep: bool) -> None:
        try:
            self._join()
        finally:
            self.writer.finish(complete=self._failure is None, keep=keep)
        if self._failure is not None:
            raise self._failure

    def _submit(self, job: Callable[[], None]) -> None:
        if self._failure is not None:
            raise self._failure
        if self._worker is None:
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


# A frame travels to the recorder process as a b"F" message (:mod:`warpcut.viz.process`): _FRAME_HEAD,
# then the recorded envs' state (float32: positions and alive), and if flagged their displacements and
# actions (float64). The last frame of each group that a step callback hands over is flagged _GROUP_END:
# the process scores a group (or, when it has fallen behind, several) at once.
_FRAME_HEAD = struct.Struct("<Iqqb")
_HAS_DISPLACEMENTS, _HAS_ACTION, _GROUP_END, _HAS_PATH = 1, 2, 4, 8


class _ProcessSink:
    """``background="process"``: the frames go through a pipe to a recorder process (:func:`_serve`),
    which scores them, writes the file and moves it into place."""

    def __init__(self, path: Path, tmp: Path, application_id: str, colour_by: str):
        self.path, self.tmp = path, tmp
        self._failure: RecordingError | None = None
        self.process_cpu_s: float | None = None
        """The recorder process's CPU time (s, all its threads) since it started, once it has closed."""
        try:
            self.child = _Child.acquire()
        except OSError as exc:
            raise RecordingError(f"{path}: could not start the recorder process ({exc})") from exc
        self._send([_pickled(("open", str(tmp), str(path), application_id, colour_by))])

    def batching(self, task: CuttingTask | None) -> tuple[int, tuple[int, ...]]:
        """Groups of :data:`PROCESS_BATCH_FRAMES` and the rest :data:`PROCESS_LEAD_FRAMES` before the end;
        but where the simulator's threads use every core, groups of :data:`FLUSH_FRAMES` (as the step
        callback batches them): there the recorder process only runs on time taken from the stepping
        threads, and fewer, larger batches cost it less."""
        if task is not None and (os.cpu_count() or 1) <= task.sim.threads:
            return FLUSH_FRAMES, ()
        return PROCESS_BATCH_FRAMES, PROCESS_LEAD_FRAMES

    def start(self, key: int, method: str, setup: _TaskSetup) -> None:
        self._send([_pickled(("start", key, method, setup))])

    def frames(self, key: int, frames: list[_Frame], final: bool) -> None:
        parts = []
        for k, frame in enumerate(frames):
            flags = _GROUP_END if k == len(frames) - 1 else 0
            arrays = [frame.state]
            if frame.displacements is not None:
                flags |= _HAS_DISPLACEMENTS
                arrays.append(np.ascontiguousarray(frame.displacements, dtype=np.float64))
            if frame.action is not None:
                flags |= _HAS_ACTION
                arrays.append(np.ascontiguousarray(frame.action, dtype=np.float64))
            if frame.path is not None and frame.path.shape[1]:
                flags |= _HAS_PATH
                arrays.append(np.array([frame.path_start, frame.path.shape[1]], dtype=np.int64))
                arrays.append(np.ascontiguousarray(frame.path, dtype=np.float32))
            size = _FRAME_HEAD.size + sum(a.nbytes for a in arrays)
            parts.append(_HEAD.pack(b"F", size) + _FRAME_HEAD.pack(key, frame.step, frame.update, flags))
            parts.extend(arrays)
        self._send(parts)
        self._check_replies()

    def close(self, keep: bool) -> None:
        """Tell the process to finish the file (``keep``: and move it into place, else delete it) and wait
        until it has (or has failed or died)."""
        child, closed = self.child, False
        try:
            self._send([_pickled(("close", keep))], check=False)
            deadline = time.monotonic() + CLOSE_TIMEOUT_S
            while not closed:
                message = child.replies.next(timeout=0.5)
                if message is not None:
                    closed = self._reply(message)
                elif child.replies.eof or child.process.poll() is not None:
                    while (message := child.replies.next(block=False)) is not None and not closed:
                        closed = self._reply(message)
                    if not closed:
                        raise self._died()
                elif time.monotonic() > deadline:
                    child.process.kill()
                    raise self._fail(
                        f"the recorder process did not finish the file within {CLOSE_TIMEOUT_S:.0f} s "
                        "and was stopped; the file holds what it wrote so far"
                    )
        except RecordingError:
            if self.tmp.exists():
                if keep:
                    os.replace(self.tmp, self.path)
                else:
                    self.tmp.unlink()
            raise
        finally:
            if closed and self._failure is None:
                child.release()
            else:  # a failed or interrupted process finishes the file on its own once the pipe closes
                child.detach()
        if self._failure is not None:
            raise self._failure

    def _send(self, parts: list, check: bool = True) -> None:
        if check and self._failure is not None:
            raise self._failure
        try:
            self.child.send(parts)
        except BrokenPipeError:
            self._check_replies()  # it may have said why
            raise self._died() from None
        except TimeoutError as exc:
            self.child.process.kill()
            raise self._fail(f"{exc}; it was stopped") from None

    def _check_replies(self) -> None:
        """Raise the process's failure as soon as it reports one."""
        while (message := self.child.replies.next(block=False)) is not None:
            self._reply(message)
        if self._failure is not None:
            raise self._failure

    def _reply(self, message: tuple[bytes, bytes]) -> bool:
        """Take in one reply; whether it says that the file is finished."""
        kind, *details = pickle.loads(message[1])
        if kind == "failed" and self._failure is None:
            name, text, trace = details
            self._fail(f"the recorder process failed: {name}: {text}", trace)
        elif kind == "closed":
            (self.process_cpu_s,) = details
        return kind == "closed"

    def _died(self) -> RecordingError:
        if self._failure is not None:
            return self._failure
        try:
            code = self.child.process.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            code = None
        return self._fail(
            f"the recorder process (pid {self.child.process.pid}) ended unexpectedly (exit code {code})"
        )

    def _fail(self, text: str, trace: str | None = None) -> RecordingError:
        if self._failure is None:
            self._failure = RecordingError(f"{self.path}: {text}")
            if trace and hasattr(self._failure, "add_note"):
                self._failure.add_note(f"in the recorder process:\n{trace.rstrip()}")
        return self._failure


def _import_writer() -> None:
    """Import what :class:`_Writer` imports on first use (rerun, its blueprints, pyarrow, scipy.sparse):
    the recorder process does so while it starts, before it lowers its priority."""
    import pyarrow  # noqa: F401
    import rerun  # noqa: F401
    import rerun.blueprint  # noqa: F401
    from scipy import sparse  # noqa: F401

    _descriptors()


def _serve(cmd_fd: int, reply_fd: int) -> None:
    """The recorder process: serve recordings one after the other until the pipe from the stepping
    process ends (it closed us, or it died: the recording it held open is finished then)."""
    messages = _Messages(cmd_fd)

    def reply(*message) -> None:
        try:
            os.write(reply_fd, _pickled(message))
        except OSError:  # the stepping process is gone; the file is finished anyway
            pass

    while (message := messages.next()) is not None:
        command, *args = pickle.loads(message[1])
        if command != "open":
            reply("failed", "RuntimeError", f"protocol: expected 'open', got {command!r}", "")
            return
        if not _serve_recording(messages, reply, *args):
            return


def _serve_recording(messages: _Messages, reply, tmp: str, path: str, application_id: str, colour_by: str):
    """Write one recording from the messages; whether the stepping process closed it (else the pipe
    ended). The frames are scored and sent a group at a time once no further message is waiting, so
    that a process that has fallen behind (no core free) catches up in fewer, larger batches. The first
    failure is reported at once; the frames after it are read and dropped."""
    failure: list = []
    pending: dict[int, list[_Frame]] = {}
    ready: set[int] = set()  # keys whose pending frames end with a whole group
    shapes: dict[int, tuple[int, int]] = {}
    writer: _Writer | None = None

    def attempt(method: str, *args) -> None:
        """``writer.method(*args)``, unless something failed already."""
        if not failure:
            try:
                getattr(writer, method)(*args)
            except Exception as exc:  # noqa: BLE001 - reported to the stepping process
                failure[:] = [type(exc).__name__, str(exc), traceback.format_exc()]
                reply("failed", *failure)

    def send(key: int) -> None:
        ready.discard(key)
        frames = pending.pop(key, None)
        if frames:
            attempt("frames", key, frames)

    def send_all() -> None:
        for key in list(pending):
            send(key)

    try:
        writer = _Writer(Path(tmp), Path(path), application_id, colour_by, background=True)
    except Exception as exc:  # noqa: BLE001 - reported to the stepping process
        failure[:] = [type(exc).__name__, str(exc), traceback.format_exc()]
        reply("failed", *failure)
    closed = False
    while True:
        message = messages.next(block=False)
        if message is None and not messages.eof:
            for key in list(ready):  # nothing else is waiting: send the whole groups
                send(key)
            message = messages.next()
        if message is None:
            break
        kind, payload = message
        try:
            if kind == b"F":
                key, frame, group_end = _read_frame(payload, shapes)
                frames = pending.setdefault(key, [])
                frames.append(frame)
                if group_end:
                    ready.add(key)
                    if len(frames) >= FLUSH_FRAMES:
                        send(key)
                continue
            command, *args = pickle.loads(payload)
            if command == "close":
                closed = True
                (keep,) = args
                break
            if command != "start":
                raise RuntimeError(f"protocol: unexpected message {command!r}")
            send_all()
            key, method, setup = args
            shapes[key] = (len(setup.envs), setup.grid.num_vertices)
            attempt("start", key, method, setup)
        except Exception as exc:  # noqa: BLE001 - reported to the stepping process
            if not failure:
                failure[:] = [type(exc).__name__, str(exc), traceback.format_exc()]
                reply("failed", *failure)
    send_all()
    if not closed:  # the stepping process died: keep what it recorded, if anything
        keep = bool(shapes)
    try:
        if writer is not None:
            writer.finish(complete=not failure, keep=keep)
        elif keep:
            os.replace(tmp, path)
        else:
            os.unlink(tmp)
    except Exception as exc:  # noqa: BLE001 - reported to the stepping process
        if not failure:
            failure[:] = [type(exc).__name__, str(exc), traceback.format_exc()]
            reply("failed", *failure)
    reply("closed", time.process_time())
    return closed


def _read_frame(payload: bytes, shapes: dict[int, tuple[int, int]]) -> tuple[int, _Frame, bool]:
    """A b"F" message's episode key, frame and whether it ends a group."""
    key, step, update, flags = _FRAME_HEAD.unpack_from(payload)
    n, v = shapes[key]
    offset = _FRAME_HEAD.size
    arrays = []
    for dtype, shape, present in (
        (np.float32, (n, v, 4), True),
        (np.float64, (n, 3), flags & _HAS_DISPLACEMENTS),
        (np.float64, (n, 3), flags & _HAS_ACTION),
    ):
        if present:
            count = math.prod(shape)
            arrays.append(np.frombuffer(payload, dtype, count, offset).reshape(shape))
            offset += count * np.dtype(dtype).itemsize
        else:
            arrays.append(None)
    path_start, path = 0, None
    if flags & _HAS_PATH:
        path_start, count = (int(v) for v in np.frombuffer(payload, np.int64, 2, offset))
        offset += 16
        path = np.frombuffer(payload, np.float32, n * count * 3, offset).reshape(n, count, 3)
    return key, _Frame(step, update, *arrays, path_start, path), bool(flags & _GROUP_END)


class _Writer:
    """Turns what the step callbacks copied into rerun data in one ``.rrd`` file (in the recorder
    process, on the worker thread or in the step callback), and finishes the file."""

    def __init__(self, tmp: Path, path: Path, application_id: str, colour_by: str, background: bool):
        import rerun as rr

        self.tmp, self.path, self.colour_by = tmp, path, colour_by
        self.background = background
        """Off the stepping thread: send the blueprint when an episode starts (else :meth:`finish` does)."""
        self.stream = rr.RecordingStream(application_id)
        self.stream.save(tmp)
        self.stream.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self.episodes: dict[int, _TaskSetup] = {}
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
            if keep:
                os.replace(self.tmp, self.path)
            else:
                self.tmp.unlink()

    def start(self, key: int, method: str, task_setup: _TaskSetup) -> None:
        """Per-env constants (contour cells, intended region, cutting runs) and the static entities of a
        new episode (``key``: its callback) of ``method``."""
        import rerun as rr
        from scipy import sparse

        stream, grid = self.stream, task_setup.grid
        root = "/" + rr.escape_entity_path_part(method)
        task_setup.triangles = grid_triangles(grid)
        # Points every half spacing follow the deformed sheet closely enough; the contour's own points
        # (every 0.5 mm for the built-ins) would cost several times more to interpolate every frame.
        spacing = 0.5 * min(grid.spacing_mm)
        for setup in task_setup.envs:
            setup.root = f"{root}/env_{setup.env}"
            vertices, weights = material_cells(_polyline(setup.contour, spacing), grid)
            rows = np.repeat(np.arange(len(vertices)), vertices.shape[1])
            setup.contour_matrix = sparse.csr_matrix(
                (weights.ravel(), (rows, vertices.ravel())), shape=(len(vertices), grid.num_vertices)
            )
            setup.intended = intended_mask(setup.contour.intended_region(), grid)
            setup.cut_runs = _cutting_runs(setup.tip)
            if setup.fiducials is None:
                pinch = setup.pinch[None] if setup.disc is not None else np.full((1, 2), np.nan)
                rng = np.random.default_rng(setup.env)
                setup.fiducials = sample_fiducials(
                    rng, NUM_FIDUCIALS, [setup.contour], pinch, task_setup.config
                )[0]
            setup.fiducial_cells = material_cells(setup.fiducials[None], grid)
            where = "none" if setup.disc is None else f"({setup.pinch[0]:.1f}, {setup.pinch[1]:.1f}) mm"
            stream.log(
                f"{setup.root}/info",
                rr.TextDocument(
                    f"contour {setup.contour.name}, pinch point {where}; vertex colours: {self.colour_by}"
                ),
                static=True,
            )
            stream.log(f"{setup.root}/action", rr.SeriesLines(names=["x", "y", "z"]), static=True)
            stream.log(
                f"{setup.root}/separated_error_vertices",
                rr.SeriesLines(names="separated error (vertices)"),
                static=True,
            )
            if setup.arc is not None:
                setup.path = np.zeros((len(setup.arc), 3), dtype=np.float32)
                ring = _polyline(setup.contour, spacing)
                stream.log(
                    f"{setup.root}/material_contour",
                    rr.LineStrips3D([np.column_stack([ring, np.zeros(len(ring))])], colors=[[0, 0, 0]]),
                    static=True,
                )
                stream.log(
                    f"{setup.root}/path_error_vertices",
                    rr.SeriesLines(names="path error (vertices)"),
                    static=True,
                )
        self.episodes[key] = task_setup
        if self.background:
            self._send_blueprint()  # off the stepping thread; finish() sends it otherwise

    def _send_blueprint(self) -> None:
        """Send the layout of the envs recorded so far, unless it was sent already."""
        roots = [env.root for _, setup in sorted(self.episodes.items()) for env in setup.envs]
        if roots != self._blueprint_roots:
            self._blueprint_roots = roots
            self.stream.send_blueprint(_blueprint(roots))

    def frames(self, key: int, frames: list[_Frame]) -> None:
        """Send a batch of frames of every recorded env of episode ``key``."""
        task_setup = self.episodes[key]
        steps = np.array([f.step for f in frames])
        updates = np.array([f.update for f in frames])
        state = np.stack([f.state for f in frames], axis=1)  # (n, F, V, 4)
        positions, alive = np.ascontiguousarray(state[..., :3]), state[..., 3] != 0.0
        displacements = (
            np.stack([f.displacements for f in frames], axis=1)
            if frames[0].displacements is not None
            else np.zeros((len(task_setup.envs), len(frames), 3))
        )
        acted = [f for f in frames if f.action is not None]
        action_steps = np.array([f.step for f in acted], dtype=np.int64)
        for k, setup in enumerate(task_setup.envs):
            if setup.path is not None:
                for f in frames:
                    if f.path is not None:
                        setup.path[f.path_start : f.path_start + f.path.shape[1]] = f.path[k]
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
        import rerun as rr

        stream, grid = self.stream, task_setup.grid
        frames, num_vertices = len(steps), grid.num_vertices

        def timeline(at: np.ndarray) -> list:
            return [rr.TimeColumn("step", sequence=at), rr.TimeColumn("sim_time", duration=at * setup.step_s)]

        every_frame = timeline(steps)

        def send(entity: str, columns, at: np.ndarray | None = None) -> None:
            times = every_frame if at is None else timeline(at)
            stream.send_columns(f"{setup.root}/{entity}", indexes=times, columns=columns, strict=True)

        if setup.height_range is None:
            # Colours and the arrow's origin stay fixed at the episode's first frame (the settled sheet).
            z = positions[0, :, 2]
            setup.height_range = (float(z.min()), max(float(z.max()), float(z.min()) + 1.0))
            if setup.disc is not None:
                setup.disc_origin = positions[0, setup.disc].mean(axis=0)

        # The columns are built straight from numpy buffers as arrow arrays (_column and its helpers), which
        # costs a fraction of what rerun's archetype constructors (rr.Mesh3D.columns, ...) spend on a batch;
        # tests/test_recording.py checks that they are the archetypes' columns.
        if self.colour_by == "strain":
            colours = _ramp(
                vertex_strain(positions, alive, grid, task_setup.config.springs), 0.0, STRAIN_FULL_SCALE
            )
        else:
            colours = _ramp(positions[..., 2], *setup.height_range)
        rows = np.full(frames, num_vertices)
        send(
            "sheet",
            [
                _column("Mesh3D:vertex_positions", _vec3(positions), rows),
                _column("Mesh3D:vertex_colors", _uint32(colours), rows),
            ],
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
                [_column("Mesh3D:triangle_indices", _triangles(faces), kept.sum(axis=1))],
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
        send("separated_error_vertices", [_column("Scalars:scalars", _float64(errors))])
        if setup.path is not None:
            self._send_path(setup, grid, updates, send)

        # All frames' contours in one product: (K, V) @ (V, F * 3).
        by_vertex = np.moveaxis(positions, 0, 1).reshape(num_vertices, frames * 3)
        contour = np.moveaxis((setup.contour_matrix @ by_vertex).reshape(-1, frames, 3), 1, 0)
        send("contour", [_column("LineStrips3D:strips", _strips(contour))])

        trajectory = setup.tip
        current = np.clip(updates - 1, 0, len(trajectory) - 1)
        cutting = (trajectory[current, 3] > 0) & (updates <= len(trajectory))
        send(
            "tip",
            [
                _column("Points3D:positions", _vec3(trajectory[current, :3])),
                _column("Points3D:colors", _uint32(np.where(cutting, _CUTTING_RGBA, _TRAVEL_RGBA))),
            ],
        )
        strips, counts = _cut_paths(trajectory, setup.cut_runs, updates)
        send("cut_path", [_column("LineStrips3D:strips", strips, counts)])

        if len(setup.fiducials):
            cells, weights = setup.fiducial_cells
            world = interpolate(positions, cells, np.broadcast_to(weights, (frames, *weights.shape[1:])))
            seen = visible(world, alive, cells, trajectory[current], setup.shaft_radius_mm)
            per_frame = np.full(frames, len(setup.fiducials))
            send(
                "fiducials",
                [
                    _column("Points3D:positions", _vec3(world), per_frame),
                    _column(
                        "Points3D:colors", _uint32(np.where(seen, _VISIBLE_RGBA, _HIDDEN_RGBA)), per_frame
                    ),
                ],
            )

        if setup.disc is not None:
            send(
                "grasp/disc",
                [
                    _column(
                        "Points3D:positions",
                        _vec3(positions[:, setup.disc]),
                        np.full(frames, setup.disc.sum()),
                    )
                ],
            )
            send(
                "grasp/displacement",
                [
                    _column("Arrows3D:origins", _vec3(np.broadcast_to(setup.disc_origin, (frames, 3)))),
                    _column("Arrows3D:vectors", _vec3(displacements)),
                ],
            )
        if len(action_steps):
            send(
                "action",
                [_column("Scalars:scalars", _float64(actions), np.full(len(actions), 3))],
                at=action_steps,
            )

    def _send_path(self, setup: _EnvSetup, grid: SheetGrid, updates: np.ndarray, send) -> None:
        """The cut path so far in material coordinates, drawn on the rest plane (z = 0, above the sagging
        sheet), and its path score, frame by frame (one vectorised scoring of all frames)."""
        from warpcut.scoring import order_cut_path, path_errors

        ends = np.minimum(updates, len(setup.arc))
        ordered = [order_cut_path(setup.path[:end], setup.arc[:end])[0] for end in ends]
        errors = path_errors(ordered, [setup.contour] * len(ends), grid)[1]
        strips = []
        for end in ends:
            mapped = setup.path[:end][setup.path[:end, 2] > 0.5, :2]  # in cutting order
            strips.append(np.column_stack([mapped, np.zeros(len(mapped))]))
        send("path_error_vertices", [_column("Scalars:scalars", _float64(errors))])
        send("path", [_column("LineStrips3D:strips", _strips_ragged(strips), np.ones(len(strips)))])


def _blueprint(roots: list[str]):
    """A 3D view per recorded env side by side, above the errors and the actions over time."""
    import rerun.blueprint as rrb

    if not roots:
        return rrb.Blueprint(rrb.Spatial3DView(origin="/"))
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
            ),
            row_shares=[3, 1],
        ),
        collapse_panels=True,
    )


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
        springs: The spring families simulated (:attr:`~warpcut.sim.config.SimConfig.springs`).

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


@cache
def _arrow_types():
    """Rerun's arrow types of a 3D point or vector, of a 3D line strip (rerun.components.LineStrip3D) and
    of a triangle's vertex indices, spelled out (tests/test_recording.py checks them against rerun's):
    columns are built as arrow arrays from flat numpy buffers, without a Python object per element."""
    import pyarrow as pa

    point = pa.list_(pa.field("item", pa.float32(), nullable=False), 3)
    strip = pa.list_(pa.field("item", point, nullable=False))
    triangle = pa.list_(pa.field("item", pa.uint32(), nullable=False), 3)
    return point, strip, triangle


@cache
def _descriptors() -> dict:
    """Rerun's descriptors of the components recorded, by name (``Archetype:component``)."""
    import rerun as rr

    return {
        d.component: d
        for d in (
            rr.Mesh3D.descriptor_vertex_positions(),
            rr.Mesh3D.descriptor_vertex_colors(),
            rr.Mesh3D.descriptor_triangle_indices(),
            rr.Scalars.descriptor_scalars(),
            rr.LineStrips3D.descriptor_strips(),
            rr.Points3D.descriptor_positions(),
            rr.Points3D.descriptor_colors(),
            rr.Arrows3D.descriptor_origins(),
            rr.Arrows3D.descriptor_vectors(),
        )
    }


class _Arrow:
    """A ready-made arrow array as rerun's ``ComponentBatchLike``."""

    __slots__ = ("array",)

    def __init__(self, array):
        self.array = array

    def as_arrow_array(self):
        return self.array


def _column(component: str, array, rows: np.ndarray | None = None):
    """The ``rr.ComponentColumn`` of ``component`` (e.g. ``"Mesh3D:vertex_positions"``) holding the arrow
    ``array``, ``rows[i]`` elements in the i-th row (default: one)."""
    import rerun as rr

    return rr.ComponentColumn(_descriptors()[component], _Arrow(array), lengths=rows)


def _vec3(values: np.ndarray):
    """(..., 3) values as an arrow array of 3D points (or vectors)."""
    import pyarrow as pa

    flat = pa.array(np.ascontiguousarray(values, dtype=np.float32).reshape(-1))
    return pa.FixedSizeListArray.from_arrays(flat, type=_arrow_types()[0])


def _strips(points: np.ndarray):
    """(F, K, 3) points as an arrow array of F line strips of K points."""
    import pyarrow as pa

    frames, k = points.shape[:2]
    offsets = pa.array(np.arange(frames + 1, dtype=np.int32) * k)
    return pa.ListArray.from_arrays(offsets, _vec3(points), type=_arrow_types()[1])


def _strips_ragged(strips: list[np.ndarray]):
    """F line strips of (K_f, 3) points each as an arrow array of F strips."""
    import pyarrow as pa

    lengths = [len(strip) for strip in strips]
    offsets = pa.array(np.concatenate([[0], np.cumsum(lengths)]).astype(np.int32))
    points = np.concatenate(strips) if strips else np.zeros((0, 3))
    return pa.ListArray.from_arrays(offsets, _vec3(points), type=_arrow_types()[1])


def _triangles(faces: np.ndarray):
    """(T, 3) vertex indices as an arrow array of triangles."""
    import pyarrow as pa

    flat = pa.array(np.ascontiguousarray(faces, dtype=np.uint32).reshape(-1))
    return pa.FixedSizeListArray.from_arrays(flat, type=_arrow_types()[2])


def _uint32(values: np.ndarray):
    import pyarrow as pa

    return pa.array(np.ascontiguousarray(values, dtype=np.uint32).reshape(-1))


def _float64(values: np.ndarray):
    import pyarrow as pa

    return pa.array(np.ascontiguousarray(values, dtype=np.float64).reshape(-1))


def _cut_paths(tip: np.ndarray, runs: np.ndarray, updates: np.ndarray):
    """The path cut so far after each of F ``updates``: per frame, the part of every cutting run of the
    (T, 4) ``tip`` trajectory that the scissors have passed (at least two points), as a rerun line strip
    array (pyarrow) of all frames' strips, and (F,) how many strips each frame has."""
    import pyarrow as pa

    point_type, strip_type, _ = _arrow_types()
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
    inner = pa.FixedSizeListArray.from_arrays(pa.array(points.astype(np.float32).ravel()), type=point_type)
    return pa.ListArray.from_arrays(pa.array(offsets), inner, type=strip_type), counts


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
        with warnings.catch_warnings():
            # A file without rerun's footer (cut short) is read by scanning it: said by the error, if any.
            warnings.simplefilter("ignore")
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
