"""Rerun recordings of cutting episodes: :class:`Recorder`, and the step callback it makes per episode.

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
the recorded envs' state, and only theirs (:meth:`~warpcut.sim.simulator.Simulator.read_state`); the
frames are scored and turned into rerun columns in batches (:mod:`warpcut.viz.rerun_writer`), where
``background`` says (:mod:`warpcut.viz.transport`): in a recorder process (the default on a POSIX machine
with more than one core; :mod:`warpcut.viz.process`), on a worker thread, or in the step callback itself.
The recorder process is started when the first :class:`Recorder` is created, or earlier by
:func:`~warpcut.viz.process.start_recorder_process`, and is kept for the next one.

Without a step callback (``on_step=None``) :meth:`CuttingTask.run` does none of this. ``every=k`` keeps
only every k-th step (plus the first and the last) for long runs or big sheets. ``docs/performance.md``
has the measured overhead (``scripts/recording_overhead.py``).

The file is written beside its target under a temporary name and renamed when the recorder closes,
also when an exception or Ctrl-C ends the run early, so a readable recording of what happened so far
always remains; a recorder that recorded no episode writes nothing (and leaves a file already at its
path as it was). :meth:`Recorder.close` returns once the file is complete. The recorder process ignores
Ctrl-C (it runs in its own process group) and finishes the file when the recorder closes, or on its own
when the stepping process dies. Use a recorder as a context manager::

    with Recorder("recording.rrd", envs=2) as recorder:
        task.run(policy, on_step=recorder.step_callback("fixed"))
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from warpcut.fiducials import SHAFT_RADIUS_MM
from warpcut.io import note_written, temp_file
from warpcut.viz.colours import COLOUR_FIELDS
from warpcut.viz.frames import EnvSetup, Frame, TaskSetup
from warpcut.viz.process import default_background
from warpcut.viz.rerun_writer import RerunWriter
from warpcut.viz.transport import InlineSink, ProcessSink, ThreadSink

if TYPE_CHECKING:
    from warpcut.task import CuttingTask, StepCallback

BACKGROUND_MODES = ("process", "thread")
"""``Recorder(background=...)`` besides ``False`` (in the step callback) and ``None`` (the default)."""


class Recorder:
    """Records cutting episodes into one ``.rrd`` file.

    Args:
        path: The ``.rrd`` file to write (its folder is created).
        envs: How many envs (the first ones) of each task to record.
        application_id: Rerun application id; the viewer groups recordings by it.
        every: Record every ``every``-th env step only (the reset and the last step always).
        colour_by: What the sheet's vertex colours show: ``"strain"`` (the default: the mean relative
            stretch ``|length / rest - 1|`` of the vertex's live springs, see
            :func:`~warpcut.viz.colours.vertex_strain`, from 0 to
            :data:`~warpcut.viz.colours.STRAIN_FULL_SCALE`; it shows where the grasp and the clips pull
            the gauze, which the mesh's shape does not) or ``"height"`` (z over the settled sheet's range,
            which the 3D view shows anyway).
        background: Where the copied frames are scored, turned into rerun columns and written:
            ``"process"``: in a recorder process, so that the stepping loop only pays for copying the
            recorded envs' state into a pipe (the process is started here, or an idle one left by an
            earlier recorder of this Python process is reused); ``"thread"`` (or ``True``): on a worker
            thread of this process; ``False``: in the step callback itself, every
            :data:`~warpcut.viz.transport.FLUSH_FRAMES` frames. ``None`` (default): ``"process"`` on a
            POSIX machine with more than one core (a core the stepping loop may leave free), else
            ``False``.

    Raises:
        ValueError: ``envs`` or ``every`` is not a positive integer, ``colour_by`` is not one of
            :data:`~warpcut.viz.colours.COLOUR_FIELDS`, or ``background`` is none of the above.
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
            background = default_background()
        elif background is True:
            background = "thread"
        if background is not False and background not in BACKGROUND_MODES:
            raise ValueError(
                f"background: choose one of {BACKGROUND_MODES}, False or None (got {background!r})"
            )
        self.path = Path(path)
        self.envs, self.every, self.colour_by, self.background = envs, every, colour_by, background
        for written in (self.path, self.path.with_suffix(".partial.rrd")):  # a run directory's files
            note_written(written)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = temp_file(self.path)
        os.close(fd)
        self._tmp = Path(tmp)
        try:
            if background == "process":
                self._sink = ProcessSink(self.path, self._tmp, application_id, colour_by)
            else:
                writer = RerunWriter(self._tmp, self.path, application_id, colour_by, bool(background))
                self._sink = ThreadSink(writer) if background else InlineSink(writer)
        except BaseException:
            self._tmp.unlink(missing_ok=True)
            raise
        self._episodes: dict[str, _Episode] = {}
        self.closed = False
        self.written = False
        """Whether :meth:`close` put the file in place (an episode was recorded)."""

    def step_callback(self, method: str) -> StepCallback:
        """A new step callback recording one episode of ``method`` under ``/{method}``, for
        ``task.run(policy, on_step=recorder.step_callback(method))``. Use a new method name per episode: a
        second run through the same callback would write over the first one's steps.

        Raises:
            ValueError: ``method`` was already recorded, or the recorder is closed.
        """
        if self.closed:
            raise ValueError(f"step_callback: the recorder of {self.path} is closed")
        if method in self._episodes:
            raise ValueError(f"step_callback: method {method!r} is already recorded in {self.path}")
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
                process's error), died or did not finish within
                :data:`~warpcut.viz.process.CLOSE_TIMEOUT_S`; the file (what it wrote so far) was moved
                into place.
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
        self.frames: list[Frame] = []
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
            Frame(
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
            EnvSetup(
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
        self.sink.start(self.key, self.method, TaskSetup(grid, config, envs))
        self.started = True
        self.task = task  # last: a start cut short (Ctrl-C) is made again by the next step

    def flush(self, final: bool = False) -> None:
        """Hand the buffered frames to the sink; ``final``: the episode (or the recording) ends here."""
        frames, self.frames = self.frames, []
        if frames:
            self.sink.frames(self.key, frames, final)
