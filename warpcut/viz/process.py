"""The recorder process behind ``Recorder(background="process")``, from the stepping process's side:
starting it, the pipes to and from it and their messages, and the recording's errors and final file
(:func:`place_file`, which the writer uses too). What runs in the process is :func:`warpcut.viz.server.serve`.

This imports only the standard library, so that :func:`start_recorder_process` can start the process
before its caller has imported anything slow (the CLI calls it first thing when ``--record`` is given):
the process's own start-up (Python, numpy, scipy, shapely and rerun) then overlaps the caller's. The
server's own imports (the writer, the frame wire format) are made in the process, which imports them
while it starts (:mod:`warpcut.viz.server`, :func:`~warpcut.viz.rerun_writer.import_rerun`).
"""

from __future__ import annotations

import os
import pickle
import select
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

from warpcut.cores import cpu_cores

PROCESS_NICE = 10
"""How much the recorder process lowers its scheduling priority (``nice``): where no core is free, the
stepping loop keeps its core and the recording catches up while the stepping process waits (at the latest
in :meth:`~warpcut.viz.recorder.Recorder.close`, or when the pipe is full)."""

CLOSE_TIMEOUT_S = 120.0
"""How long :meth:`~warpcut.viz.recorder.Recorder.close` (and a step callback whose pipe is full) waits for
the recorder process before it gives up, stops the process and raises :class:`RecordingError`."""


class RecordingError(RuntimeError):
    """The recorder process failed, died or stopped answering; the message names the recording."""


def start_recorder_process() -> bool:
    """Start a recorder process now, where recorders use one by default (``Recorder(background=None)``),
    for the next :class:`~warpcut.viz.recorder.Recorder` of this Python process to take: its start-up
    (Python, numpy, scipy, shapely and rerun) then overlaps the caller's own (the CLI calls it first thing
    when ``--record`` is given). Whether one is started (or an idle one is already waiting).

    Raises:
        RecordingError: The process could not be started.
    """
    if default_background() != "process":
        return False
    with RecorderProcess._lock:
        if any(
            child.owner == os.getpid() and child.process.poll() is None for child in RecorderProcess._idle
        ):
            return True
    try:
        RecorderProcess().release()
    except OSError as exc:
        raise RecordingError(f"could not start the recorder process ({exc})") from exc
    return True


def place_file(tmp: str | os.PathLike, path: str | os.PathLike, keep: bool) -> None:
    """Move a recording's finished temporary file ``tmp`` to ``path`` (``keep``), or delete it (nothing was
    recorded: a file already at ``path`` stays as it was).

    A file cut short (a full disk, a killed process: no rerun footer,
    :func:`~warpcut.viz.readback.is_complete`) raises :class:`RecordingError` and never replaces a file
    already at ``path``: it is kept beside it as ``NAME.partial.rrd``; where there is none, it takes
    ``path`` (rerun reads what it holds).
    """
    from warpcut.viz.readback import is_complete

    if not keep:
        os.unlink(tmp)
        return
    if is_complete(tmp):
        os.replace(tmp, path)
        return
    if Path(path).exists():
        partial = Path(path).with_suffix(".partial.rrd")
        os.replace(tmp, partial)
        where = f"what was written is in {partial}; {path} still holds the earlier recording"
    else:
        os.replace(tmp, path)
        where = "the file holds what was written, truncated there (rerun reads it up to the cut)"
    raise RecordingError(f"{path}: the recording was cut short, {_cut_short_cause(path)}; {where}")


def _cut_short_cause(path: str | os.PathLike) -> str:
    """Why a recording's file (now at ``path``, or beside it) was cut short: rerun's writer sees the OS
    error, not this process, so it is told from what is left: a file as large as the file-size limit
    (``ulimit -f``), a full disk."""
    import shutil

    from warpcut.limits import file_size_cause, file_size_limit

    limit = file_size_limit()
    sizes = [p.stat().st_size for p in (Path(path), Path(path).with_suffix(".partial.rrd")) if p.is_file()]
    if limit is not None and any(size >= limit for size in sizes):
        return f"the file reached the largest file this process may write: {file_size_cause()}"
    try:
        free = shutil.disk_usage(Path(path).parent).free
    except OSError:
        free = None
    if free is not None and free < (1 << 20):
        return f"the disk holding it is full ({free} bytes free): free space and record again"
    return "its writer stopped early (a refused write, a killed process: WARPCUT_VERBOSE=1 shows rerun's log)"


def _child_environment() -> dict[str, str]:
    """The recorder process's environment: rerun's own log (a write it could not make, in several lines of
    ERROR and WARN) silenced unless ``WARPCUT_VERBOSE`` or ``RUST_LOG`` is set, since the
    :class:`RecordingError` names the cause in one line."""
    env = dict(os.environ)
    if not env.get("WARPCUT_VERBOSE"):
        env.setdefault("RUST_LOG", "off")
    return env


def default_background() -> str | bool:
    """``Recorder(background=None)``: a recorder process on a POSIX machine with more than one core (a
    core the stepping loop may leave free), else the step callback itself."""
    return "process" if os.name == "posix" and cpu_cores() > 1 else False


# The pipe to the recorder process carries messages of a kind byte and a payload length, then the payload:
# b"P", a pickled tuple (``open``, ``start``, ``close``; and every reply), or b"F", one frame in raw bytes
# (:func:`warpcut.viz.transport.encode_frames`).
MESSAGE_HEAD = struct.Struct("<cI")


def pickled_message(message: tuple) -> bytes:
    """``message`` as a b"P" message."""
    data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    return MESSAGE_HEAD.pack(b"P", len(data)) + data


class MessageReader:
    """The messages arriving on a pipe's reading end ``fd``."""

    def __init__(self, fd: int):
        self.fd = fd
        self.buffer = bytearray()
        self.start = 0  # where the next message begins in the buffer
        self.eof = False

    def next(self, block: bool = True, timeout: float | None = None):
        """The next message as ``(kind, payload)``; None at the end of the pipe, or when none arrived in
        time (``block=False``: none is waiting now; ``timeout``: seconds)."""
        while True:
            if len(self.buffer) - self.start >= MESSAGE_HEAD.size:
                kind, size = MESSAGE_HEAD.unpack_from(self.buffer, self.start)
                begin = self.start + MESSAGE_HEAD.size
                if len(self.buffer) >= begin + size:
                    with memoryview(self.buffer) as view:
                        payload = bytes(view[begin : begin + size])
                    self.start = begin + size
                    return kind, payload
            if self.eof:
                return None
            if not block or timeout is not None:
                ready, _, _ = select.select([self.fd], [], [], 0.0 if not block else timeout)
                if not ready:
                    return None
            data = os.read(self.fd, 1 << 20)
            if not data:
                self.eof = True
            del self.buffer[: self.start]
            self.start = 0
            self.buffer += data


class RecorderProcess:
    """A recorder process (:func:`serve`) and the two pipes to it; one recording at a time."""

    _idle: list[RecorderProcess] = []
    _lock = threading.Lock()

    def __init__(self):
        cmd_read, self.cmd = os.pipe()
        reply_read, reply_write = os.pipe()
        try:
            import fcntl

            # Room for ~125 frames of a 25 x 25 sheet (Linux; 64 KiB elsewhere): the stepping loop seldom
            # has to wait for a busy recorder process.
            fcntl.fcntl(self.cmd, fcntl.F_SETPIPE_SZ, 1 << 20)
        except (ImportError, AttributeError, OSError):
            pass
        os.set_blocking(self.cmd, False)
        source = str(Path(__file__).resolve().parents[2])  # the directory holding the warpcut package
        kwargs = {"process_group": 0} if sys.version_info >= (3, 11) else {"start_new_session": True}
        try:
            self.process = subprocess.Popen(
                [
                    sys.executable,
                    "-c",
                    _CHILD_MAIN.format(nice=PROCESS_NICE, source=source, cmd=cmd_read, reply=reply_write),
                ],
                pass_fds=(cmd_read, reply_write),
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                close_fds=True,
                env=_child_environment(),
                **kwargs,
            )
        except BaseException:
            for fd in (self.cmd, reply_read):
                os.close(fd)
            raise
        finally:
            os.close(cmd_read)
            os.close(reply_write)
        self.replies = MessageReader(reply_read)
        self.owner = os.getpid()
        self._unsent = b""

    @classmethod
    def acquire(cls) -> RecorderProcess:
        """An idle recorder process of this Python process, or a new one."""
        with cls._lock:
            while cls._idle:
                child = cls._idle.pop()
                if child.owner == os.getpid() and child.process.poll() is None:
                    return child
                child.detach()
        return cls()

    def release(self) -> None:
        """Keep the process for the next recorder (one at most), or let it end."""
        with self._lock:
            if not self._idle and self.owner == os.getpid() and self.process.poll() is None:
                self._idle.append(self)
                return
        self.detach()

    def detach(self) -> None:
        """Close this end of the pipes: the process finishes the recording it holds (if any) and ends (a
        thread waits for it, so that it does not linger as a zombie)."""
        self._close_pipes()
        threading.Thread(target=self.process.wait, name="warpcut-recorder-reaper", daemon=True).start()

    def _close_pipes(self) -> None:
        for fd in (self.cmd, self.replies.fd):
            try:
                os.close(fd)
            except OSError:
                pass
        self.cmd = self.replies.fd = -1

    def send(self, parts: list, wait_s: float = CLOSE_TIMEOUT_S) -> None:
        """Write one message (its ``parts``, bytes-like) into the pipe, waiting while the pipe is full.
        A message cut short by an exception (Ctrl-C) is completed before the next one.

        Raises:
            BrokenPipeError: The process has ended.
            TimeoutError: The pipe stayed full for ``wait_s``.
        """
        views = [memoryview(p).cast("B") for p in ([self._unsent] if self._unsent else []) + parts]
        unsent, self._unsent = len(self._unsent), b""  # the end of an earlier message comes first
        deadline = None
        try:
            while views:
                try:
                    written = os.writev(self.cmd, views)
                except BlockingIOError:
                    written = 0
                unsent -= written
                while views and written >= len(views[0]):
                    written -= len(views[0])
                    views.pop(0)
                if written:
                    views[0] = views[0][written:]
                if views:
                    deadline = deadline or time.monotonic() + wait_s
                    select.select([], [self.cmd], [], 0.5)
                    if self.process.poll() is not None:
                        raise BrokenPipeError(f"the recorder process (pid {self.process.pid}) has ended")
                    if time.monotonic() > deadline:
                        raise TimeoutError(f"the recorder process took no data for {wait_s:.0f} s")
        except BaseException:
            if unsent < 0:  # this message began: the rest of it goes first next time
                self._unsent = b"".join(views)
            elif unsent > 0:  # an earlier message is still not complete; this one was not sent
                self._unsent = b"".join(views)[:unsent]
            raise

    def __del__(self):  # no thread here: it may run at interpreter exit
        try:
            if self.cmd >= 0:
                self._close_pipes()
        except Exception:  # noqa: BLE001 - at interpreter exit
            pass


# The recorder process: ignores Ctrl-C (the terminal sends it to the stepping process's group; this one
# runs in its own group, but the signal may come by other ways), imports the writer, lowers its priority
# and serves recordings. It imports at the caller's priority: niced, its start-up would get only a sliver
# of a core that the caller (importing and building its own task) or another process also wants, and
# would still be running when the first episode ends. A failure to start is reported through the reply
# pipe like any other.
_CHILD_MAIN = """\
import os, signal, sys
signal.signal(signal.SIGINT, signal.SIG_IGN)
sys.path[0] = {source!r}
try:
    from warpcut.viz.rerun_writer import import_rerun
    from warpcut.viz.server import serve

    import_rerun()
except BaseException as exc:
    import pickle, struct, traceback
    data = pickle.dumps(("failed", type(exc).__name__, str(exc), traceback.format_exc()))
    os.write({reply}, struct.pack("<cI", b"P", len(data)) + data)
    sys.exit(1)
try:
    os.nice({nice})
except OSError:
    pass
serve({cmd}, {reply})
"""
