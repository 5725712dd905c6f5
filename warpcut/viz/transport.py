"""How the frames that a step callback copied reach the :class:`~warpcut.viz.rerun_writer.RerunWriter`:
the three sinks of ``Recorder(background=...)`` and the wire format of a frame on the pipe to the recorder
process.

* :class:`ProcessSink` (``"process"``): through a pipe to a recorder process (:mod:`warpcut.viz.process`),
  :data:`PROCESS_BATCH_FRAMES` frames at a time (one ``writev``), which scores them, builds the columns,
  runs rerun's encoding and writes the file on another core, without holding the stepping process's GIL.
  The stepping process does not import rerun.
* :class:`ThreadSink` (``"thread"``): on a worker thread of the stepping process, every
  :data:`WORKER_BATCH_FRAMES` frames (it runs only while the stepping thread releases the GIL).
* :class:`InlineSink` (``False``): in the step callback itself, every :data:`FLUSH_FRAMES` frames.

Every sink takes an episode's start (:meth:`start`), its frames in batches (:meth:`frames`) and the end of
the recording (:meth:`close`), and says how the step callback should batch (:meth:`batching`).
"""

from __future__ import annotations

import math
import pickle
import queue
import struct
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from warpcut.cores import cpu_cores
from warpcut.viz.frames import Frame, TaskSetup
from warpcut.viz.process import (
    CLOSE_TIMEOUT_S,
    MESSAGE_HEAD,
    RecorderProcess,
    RecordingError,
    pickled_message,
    place_file,
)

if TYPE_CHECKING:
    from warpcut.task import CuttingTask
    from warpcut.viz.rerun_writer import RerunWriter

FLUSH_FRAMES = 128
"""Frames buffered per method before they are scored and sent to the file in the step callback
(``background=False``). Each batch has a fixed cost on top of its cost per frame, so few large batches are
cheapest; 128 frames stay a modest buffer per recorded env."""

WORKER_BATCH_FRAMES = 32
"""Frames handed to the worker thread at a time (``background="thread"``; and the rest when the episode
ends): smaller batches than :data:`FLUSH_FRAMES`, so that little work is left for ``Recorder.close`` to
wait for."""

PROCESS_BATCH_FRAMES = 32
"""Frames the step callback writes into the pipe to the recorder process at a time (``background=
"process"``; and the rest when the episode ends), and that the process then scores and sends as one
batch (or several such groups at once when it has fallen behind): one wake-up of the process per group,
not per frame (on a busy machine each wake-up may take the stepping thread's core for a moment), and
batches small enough that little is left for ``Recorder.close`` to wait for. Where the simulator's
threads use every core the groups hold :data:`FLUSH_FRAMES` frames instead: the process then only runs
on time taken from the stepping threads, and one large batch costs it least."""

PROCESS_LEAD_FRAMES = (10, 4)
"""The step callback also hands its frames to the recorder process when the episode is this many frames
from its end (each of them): the process scores them while the last steps run, in batches small enough
to be done before the next arrives, and only the last few frames (one small batch) are left when the
episode ends."""


class InlineSink:
    """``background=False``: the step callback writes its frames itself, every :data:`FLUSH_FRAMES`."""

    def __init__(self, writer: RerunWriter):
        self.writer = writer

    def batching(self, task: CuttingTask | None) -> tuple[int, tuple[int, ...]]:
        """Frames per batch, and how many frames before an episode's end the rest is handed over."""
        return FLUSH_FRAMES, ()

    def start(self, key: int, method: str, setup: TaskSetup) -> None:
        self.writer.start(key, method, setup)

    def frames(self, key: int, frames: list[Frame], final: bool) -> None:
        self.writer.frames(key, frames)

    def close(self, keep: bool) -> None:
        self.writer.finish(keep=keep)


class ThreadSink:
    """``background="thread"``: a worker thread writes the frames, in submission order."""

    def __init__(self, writer: RerunWriter):
        self.writer = writer
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._worker: threading.Thread | None = None
        self._failure: BaseException | None = None

    def batching(self, task: CuttingTask | None) -> tuple[int, tuple[int, ...]]:
        return WORKER_BATCH_FRAMES, ()

    def start(self, key: int, method: str, setup: TaskSetup) -> None:
        self._submit(lambda: self.writer.start(key, method, setup))

    def frames(self, key: int, frames: list[Frame], final: bool) -> None:
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


class ProcessSink:
    """``background="process"``: the frames go through a pipe to a recorder process
    (:func:`warpcut.viz.server.serve`), which scores them, writes the file and moves it into place."""

    def __init__(self, path: Path, tmp: Path, application_id: str, colour_by: str):
        self.path, self.tmp = path, tmp
        self._failure: RecordingError | None = None
        self.process_cpu_s: float | None = None
        """The recorder process's CPU time (s, all its threads) since it started, once it has closed."""
        try:
            self.child = RecorderProcess.acquire()
        except OSError as exc:
            raise RecordingError(f"{path}: could not start the recorder process ({exc})") from exc
        self._send([pickled_message(("open", str(tmp), str(path), application_id, colour_by))])

    def batching(self, task: CuttingTask | None) -> tuple[int, tuple[int, ...]]:
        """Groups of :data:`PROCESS_BATCH_FRAMES` and the rest :data:`PROCESS_LEAD_FRAMES` before the end;
        but where the simulator's threads use every core, groups of :data:`FLUSH_FRAMES` (as the step
        callback batches them): there the recorder process only runs on time taken from the stepping
        threads, and fewer, larger batches cost it less."""
        if task is not None and cpu_cores() <= task.sim.threads:
            return FLUSH_FRAMES, ()
        return PROCESS_BATCH_FRAMES, PROCESS_LEAD_FRAMES

    def start(self, key: int, method: str, setup: TaskSetup) -> None:
        self._send([pickled_message(("start", key, method, setup))])

    def frames(self, key: int, frames: list[Frame], final: bool) -> None:
        self._send(encode_frames(key, frames))
        self._check_replies()

    def close(self, keep: bool) -> None:
        """Tell the process to finish the file (``keep``: and move it into place, else delete it) and wait
        until it has (or has failed or died)."""
        child, closed = self.child, False
        try:
            self._send([pickled_message(("close", keep))], check=False)
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
        except RecordingError as failure:
            if self.tmp.exists():
                try:
                    place_file(self.tmp, self.path, keep)
                except RecordingError as placed:  # cut short: say where it went, after why
                    failure.args = (f"{failure}; {str(placed).removeprefix(f'{self.path}: ')}",)
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
            if name == RecordingError.__name__ and text.startswith(f"{self.path}: "):  # its own words
                self._fail(text.removeprefix(f"{self.path}: "), trace)
            else:
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


# A frame travels to the recorder process as a b"F" message (:data:`~warpcut.viz.process.MESSAGE_HEAD`):
# _FRAME_HEAD, then the recorded envs' state (float32: positions and alive), and if flagged their
# displacements and actions (float64) and the cut path traced since the previous frame (its first update
# and length as int64, then float32). The last frame of each group that a step callback hands over is
# flagged _GROUP_END: the process scores a group (or, when it has fallen behind, several) at once.
_FRAME_HEAD = struct.Struct("<Iqqb")
_HAS_DISPLACEMENTS, _HAS_ACTION, _GROUP_END, _HAS_PATH = 1, 2, 4, 8


def encode_frames(key: int, frames: list[Frame]) -> list:
    """One group of frames of episode ``key`` as b"F" messages: the bytes-like parts of one ``writev``."""
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
        parts.append(MESSAGE_HEAD.pack(b"F", size) + _FRAME_HEAD.pack(key, frame.step, frame.update, flags))
        parts.extend(arrays)
    return parts


def decode_frame(payload: bytes, shapes: dict[int, tuple[int, int]]) -> tuple[int, Frame, bool]:
    """A b"F" message's episode key, frame and whether it ends a group; ``shapes``: per episode key, its
    recorded envs and vertices per env."""
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
    return key, Frame(step, update, *arrays, path_start, path), bool(flags & _GROUP_END)
