"""What runs in the recorder process (:mod:`warpcut.viz.process` starts it): :func:`serve` reads the
messages that the stepping process's :class:`~warpcut.viz.transport.ProcessSink` writes into the pipe,
has a :class:`~warpcut.viz.rerun_writer.RerunWriter` score and encode the frames, and answers through
the reply pipe.

The recorder process imports this module while it starts, with the writer and the frame wire format;
the stepping process never does.
"""

from __future__ import annotations

import os
import pickle
import time
import traceback
from pathlib import Path

from warpcut.viz.process import MessageReader, pickled_message, place_file
from warpcut.viz.rerun_writer import RerunWriter
from warpcut.viz.transport import FLUSH_FRAMES, decode_frame


def serve(cmd_fd: int, reply_fd: int) -> None:
    """The recorder process: serve recordings one after the other until the pipe from the stepping
    process ends (it closed us, or it died: the recording it held open is finished then)."""
    messages = MessageReader(cmd_fd)

    def reply(*message) -> None:
        try:
            os.write(reply_fd, pickled_message(message))
        except OSError:  # the stepping process is gone; the file is finished anyway
            pass

    while (message := messages.next()) is not None:
        command, *args = pickle.loads(message[1])
        if command != "open":
            reply("failed", "RuntimeError", f"protocol: expected 'open', got {command!r}", "")
            return
        if not _serve_recording(messages, reply, *args):
            return


def _serve_recording(
    messages: MessageReader, reply, tmp: str, path: str, application_id: str, colour_by: str
) -> bool:
    """Write one recording from the messages; whether the stepping process closed it (else the pipe
    ended). The frames are scored and sent a group at a time once no further message is waiting, so
    that a process that has fallen behind (no core free) catches up in fewer, larger batches. The first
    failure is reported at once; the frames after it are read and dropped."""
    failure: list = []
    pending: dict[int, list] = {}
    ready: set[int] = set()  # keys whose pending frames end with a whole group
    shapes: dict[int, tuple[int, int]] = {}
    writer: RerunWriter | None = None

    def report(exc: Exception) -> None:
        """Report ``exc`` to the stepping process, unless something failed already."""
        if not failure:
            failure[:] = [type(exc).__name__, str(exc), traceback.format_exc()]
            reply("failed", *failure)

    def send(key: int) -> None:
        ready.discard(key)
        frames = pending.pop(key, None)
        if frames and not failure:
            try:
                writer.frames(key, frames)
            except Exception as exc:  # noqa: BLE001 - reported to the stepping process
                report(exc)

    try:
        writer = RerunWriter(Path(tmp), Path(path), application_id, colour_by, background=True)
    except Exception as exc:  # noqa: BLE001 - reported to the stepping process
        report(exc)
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
                key, frame, group_end = decode_frame(payload, shapes)
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
            for key in list(pending):
                send(key)
            key, method, setup = args
            shapes[key] = (len(setup.envs), setup.grid.num_vertices)
            if not failure:
                writer.start(key, method, setup)
        except Exception as exc:  # noqa: BLE001 - reported to the stepping process
            report(exc)
    for key in list(pending):
        send(key)
    if not closed:  # the stepping process died: keep what it recorded, if anything
        keep = bool(shapes)
    try:
        if writer is not None:
            writer.finish(complete=not failure, keep=keep)
        else:
            place_file(tmp, path, keep)
    except Exception as exc:  # noqa: BLE001 - reported to the stepping process
        report(exc)
    reply("closed", time.process_time())
    return closed
