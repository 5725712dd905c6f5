"""``warpcut replay``: open a recording in the rerun viewer, or say what it holds."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import click

VIEWER = [sys.executable, "-m", "rerun_cli"]
"""The rerun viewer (rerun-sdk's ``rerun`` command), as ``replay`` runs it."""

VIEWER_START_S = 3.0
"""How long ``replay`` watches the viewer it started: one that ends within this time with an error could
not open a window, and ``replay`` then prints what it prints without a display."""


@click.command("replay")
@click.argument("path", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--web", is_flag=True, help="Serve the web viewer on http://127.0.0.1:9090 instead (Ctrl-C stops it)."
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
        click.echo(f"serving {path} at http://127.0.0.1:9090 (gRPC on port 9876); Ctrl-C stops it")
        sys.exit(subprocess.run([*viewer, "--web-viewer", "--bind", "127.0.0.1", str(path)]).returncode)
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
    click.echo(
        f"  run 'warpcut replay {path} --web' and open http://localhost:9090 "
        "(over ssh, forward ports 9090 and 9876: ssh -L 9090:localhost:9090 -L 9876:localhost:9876 HOST)"
    )
    if has_display:  # the viewer could not be opened
        sys.exit(1)
