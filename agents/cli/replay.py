"""``warpcut replay``: open a recording in the rerun viewer, or say what it holds."""

from __future__ import annotations

import math
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from urllib.parse import quote

import click

from agents.cli import settings

VIEWER = [sys.executable, "-m", "rerun_cli"]
"""The rerun viewer (rerun-sdk's ``rerun`` command), as ``replay`` runs it."""

VIEWER_START_S = 3.0
"""How long ``replay`` watches the viewer it started: one that ends within this time with an error could
not open a window, and ``replay`` then prints what it prints without a display."""

WEB_PORT, GRPC_PORT = 9090, 9876
"""The ports of rerun's web viewer (HTTP) and of the gRPC server that holds the recording (rerun's
defaults)."""

VIEWER_STOP_S = 3.0
"""How long ``replay --web`` waits for the viewer to end after each signal it sends (SIGINT, then SIGTERM,
then SIGKILL) when it stops."""


def web_url(web_port: int = WEB_PORT, grpc_port: int = GRPC_PORT) -> str:
    """The web viewer's address that opens the recording: the page alone shows rerun's Welcome screen, the
    recording loads from the gRPC server named in its ``url`` parameter."""
    source = quote(f"rerun+http://localhost:{grpc_port}/proxy", safe="")
    return f"http://127.0.0.1:{web_port}/?url={source}"


@click.command("replay", cls=settings.Command)
@click.argument("path", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--web",
    is_flag=True,
    help="Serve the web viewer on 127.0.0.1 instead and print the address that opens the recording "
    "(Ctrl-C stops it).",
)
def command(path: Path, web: bool) -> None:
    """Open a recording (.rrd from --record) in the rerun viewer.

    Without a display (no DISPLAY or WAYLAND_DISPLAY) it prints how to view the file and what it holds;
    so it does, exiting with status 1, where the viewer ends at once (a display that cannot be reached).
    """
    from warpcut.viz import read_summary

    summary = read_summary(path)
    viewer = VIEWER
    if web:
        sys.exit(serve_web(path, viewer))
    has_display = sys.platform in ("darwin", "win32") or any(
        os.environ.get(v) for v in ("DISPLAY", "WAYLAND_DISPLAY")
    )
    if has_display:
        with tempfile.TemporaryFile() as log:  # not a pipe: the viewer outlives this command
            process = subprocess.Popen(
                [*viewer, str(path)], stdout=subprocess.DEVNULL, stderr=log, start_new_session=True
            )
            try:  # a viewer that cannot open a window (a display that is set but unreachable) ends at once
                code = process.wait(timeout=VIEWER_START_S)
            except subprocess.TimeoutExpired:
                click.echo(f"opened {path} in the rerun viewer")
                return
            log.seek(0)
            said = re.sub(r"\x1b\[[0-9;]*m", "", log.read().decode(errors="replace")).splitlines()
        errors = [line.strip() for line in said if line.startswith("Error")]
        if code == 0 and not errors:  # e.g. handed the file to a viewer that was open already
            click.echo(f"opened {path} in the rerun viewer")
            return
        # (rerun's viewer ends with status 0 also when it cannot reach the display)
        reason = errors[-1].rsplit(": ", 1)[-1] if errors else f"exit code {code}"
        click.echo(
            f"error: the rerun viewer ended at once ({reason}); is the display reachable? "
            "What the recording holds:",
            err=True,
        )
    size_mb = path.stat().st_size / 1e6
    click.echo(f"recording {path} ({size_mb:.1f} MB, application {summary.application_id})")
    click.echo(
        f"  {summary.frames} frames (steps {summary.first_step} to {summary.last_step}), "
        f"{summary.duration_s:.2f} s simulated"
    )
    shown = 40
    click.echo(f"  {len(summary.entity_paths)} entities:")
    for entity in summary.entity_paths[:shown]:
        click.echo(f"    {entity}")
    if len(summary.entity_paths) > shown:
        click.echo(f"    ... and {len(summary.entity_paths) - shown} more")
    click.echo(
        "no display here (DISPLAY and WAYLAND_DISPLAY are unset); to view it, either"
        if not has_display
        else "to view it, either"
    )
    click.echo(f"  run 'rerun {path}' (pip install rerun-sdk) on a machine with a display, or")
    click.echo(f"  run 'warpcut replay {path} --web' and open {web_url()}")
    click.echo(f"  ({_SSH_HINT})")
    if has_display:  # the viewer could not be opened
        sys.exit(1)


_SSH_HINT = (
    f"over ssh, forward both ports first: ssh -L {WEB_PORT}:localhost:{WEB_PORT} "
    f"-L {GRPC_PORT}:localhost:{GRPC_PORT} HOST"
)


def serve_web(path: Path, viewer: list[str]) -> int:
    """Serve ``path`` with rerun's web viewer until it ends or this command is stopped; returns its exit
    status.

    The viewer runs in its own process group (rerun's ``rerun`` command is a Python wrapper that starts
    the server binary), and Ctrl-C, SIGTERM and SIGHUP (which :class:`~agents.cli.errors.CleanErrors`
    raises as ``KeyboardInterrupt``) stop the whole group before the interrupt goes on: no server is left
    holding the ports.
    """
    size = path.stat().st_size
    # The server keeps what it loaded for viewers that connect later (the browser always does): room for
    # all of it, not rerun's default 1 GiB, beyond which it drops the start of the recording.
    limit = f"{max(1, math.ceil(4 * size / 2**30))}GiB"
    command = [*viewer, "--web-viewer", "--bind", "127.0.0.1", "--server-memory-limit", limit, str(path)]
    click.echo(f"serving {path}: open {web_url()}")
    click.echo(f"({_SSH_HINT}); Ctrl-C stops it")
    process, deferred = _start_deferring_signals(command)
    try:
        for signum in deferred:  # arrived while the viewer started: handled now that it can be stopped
            os.kill(os.getpid(), signum)
        return process.wait()
    finally:
        stop_viewer(process)


STOP_SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)
)
"""The signals that stop ``replay --web`` (Ctrl-C; SIGTERM and SIGHUP through ``CleanErrors``)."""


def _start_deferring_signals(command: list[str]) -> tuple[subprocess.Popen, list[int]]:
    """Start the viewer in its own process group with :data:`STOP_SIGNALS` held back meanwhile: one that
    arrived while ``Popen`` ran would raise in it after the viewer had started, before its process could
    be stopped, and leave the viewer's server running (seen on a slow machine). Returns the process and the
    signals held back, for the caller to send again. Held back only in the main thread, where Python runs
    signal handlers; the viewer starts with the default handlers either way (exec resets them)."""
    import threading

    deferred: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        return subprocess.Popen(command, start_new_session=hasattr(os, "killpg")), deferred
    previous = {
        signum: signal.signal(signum, lambda signum, _: deferred.append(signum)) for signum in STOP_SIGNALS
    }
    try:
        process = subprocess.Popen(command, start_new_session=hasattr(os, "killpg"))
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    return process, deferred


def stop_viewer(process: subprocess.Popen, grace_s: float | None = None) -> None:
    """End the process group that ``process`` leads (SIGINT, then SIGTERM, then SIGKILL, each given
    ``grace_s``, default :data:`VIEWER_STOP_S`), and reap ``process``."""
    grace_s = VIEWER_STOP_S if grace_s is None else grace_s
    if not hasattr(os, "killpg"):  # Windows: no process groups to signal
        if process.poll() is None:
            process.terminate()
        process.wait()
        return
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(process.pid, signum)
        except ProcessLookupError:  # the group is gone
            break
        deadline = time.monotonic() + grace_s
        while time.monotonic() < deadline and _group_alive(process):
            time.sleep(0.05)
        if not _group_alive(process):
            break
    process.wait()


def _group_alive(process: subprocess.Popen) -> bool:
    """Whether a process of ``process``'s group still runs (``process`` itself is reaped once it ended)."""
    process.poll()
    try:
        os.killpg(process.pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # a member that changed its user: still there
        return True
    return process.returncode is None or _has_live_member(process.pid)


def _has_live_member(group: int) -> bool:
    """Whether a process of ``group`` other than a zombie runs (Linux's /proc; elsewhere: assume so)."""
    proc = Path("/proc")
    if not proc.is_dir():
        return True
    for entry in proc.iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if int(fields[2]) == group and fields[0] != "Z":  # state, ppid, pgrp
            return True
    return False
