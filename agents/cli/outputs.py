"""Where a command writes, and what it says it wrote: its run directory claimed (:func:`claim`), its output
paths checked before any work (:func:`check_outputs`), its recording, plots and progress lines."""

from __future__ import annotations

import contextlib
import os
import time
from pathlib import Path

import click

from agents.cli.errors import COMMAND_LINE


def claim(out: Path | None, prefix: str, resume: bool, overwrite: bool, command: str):
    """``(run directory, its claim)``: ``out`` (or a fresh ``logs/PREFIX-...``) and a context that holds it
    (:func:`warpcut.io.claim_run_dir` for ``command``: marked and locked; refused if it holds files warpcut
    did not write, or another run unless resuming one of ``command`` or overwriting), saying what
    ``--overwrite`` deleted and kept."""
    if resume and out is None:
        raise click.BadParameter("give the run directory to continue with --out", param_hint="--resume")
    if resume and not (out.is_dir() and any(out.iterdir())):
        raise click.BadParameter(
            f"{out} holds no run to continue; drop --resume to start one", param_hint="--resume"
        )
    out = run_dir(out, prefix)
    check_outputs({"--out": out})
    return out, _claimed(out, command, resume, overwrite)


@contextlib.contextmanager
def _claimed(out: Path, command: str, resume: bool, overwrite: bool):
    from warpcut.io import claim_run_dir, overwritten

    with claim_run_dir(out, command=command, resume=resume, overwrite=overwrite, argv=COMMAND_LINE or None):
        deleted, kept = overwritten(out)
        if deleted:
            shown = f"; kept what warpcut did not write: {', '.join(kept[:5])}" if kept else ""
            more = f", ... ({len(kept)} entries)" if len(kept) > 5 else ""
            click.echo(f"--overwrite: deleted {len(deleted)} files of the earlier run in {out}{shown}{more}")
        yield out


def check_outputs(
    outputs: dict[str, Path | None], inputs: list[str] = (), own: tuple[Path, str] | None = None
) -> None:
    """Refuse, before any work, an output path (``{option: path}``, files or directories) that cannot be
    written, or a file that is one of the input files (contour files): writing it would destroy the input.
    A file the user names (``--json``) is refused where it would replace a file warpcut did not write, or
    land in a run directory the command does not own (``own``: its run directory and the command, whose
    marker it may carry)."""
    files = [Path(i) for i in inputs if Path(i).is_file()]
    for option, path in outputs.items():
        if path is None:
            continue
        problem = _unwritable(path)
        if problem:
            raise click.BadParameter(
                f"cannot write {path} ({problem}); choose another path", param_hint=option
            )
        for given in files:
            if path.exists() and path.resolve() == given.resolve():
                raise click.BadParameter(
                    f"{path} is an input (a contour file); choose another file", param_hint=option
                )
        if option == "--json":
            from agents.cli.checks import check_named_file

            check_named_file(path, own, option)


def _unwritable(path: Path) -> str | None:
    """Why ``path`` (a file or directory to write, and the directories it needs) cannot be written, or
    None: a temporary file is made and removed in the deepest directory of it that exists."""
    import errno
    import tempfile

    existing = path if path.is_dir() else path.parent
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        return f"{existing} is not a directory"
    try:
        fd, probe = tempfile.mkstemp(dir=existing, prefix=".warpcut-probe-")
    except OSError as exc:
        from warpcut.limits import write_cause

        where = f"the working folder {existing.resolve()}" if existing == Path(".") else existing
        reason = write_cause(exc) or exc.strerror or str(exc)
        if exc.errno == errno.ENOENT:  # the folder is there: a file system that makes no files (/proc, /sys)
            reason = "files cannot be created there"
        return f"{where}: {reason}"
    os.close(fd)
    os.unlink(probe)
    return None


def run_dir(out: Path | None, prefix: str) -> Path:
    """``out`` or a fresh ``logs/PREFIX-YYYYmmdd-HHMMSS`` directory."""
    if out is not None:
        return out
    stamp = time.strftime("%Y%m%d-%H%M%S")
    path = Path("logs") / f"{prefix}-{stamp}"
    suffix = 1
    while path.exists():
        path = Path("logs") / f"{prefix}-{stamp}-{suffix}"
        suffix += 1
    return path


def recorder(out: Path, record_envs: int | None, colour_by: str):
    """A :class:`~warpcut.viz.recorder.Recorder` of ``out/recording.rrd``, or a null context when not
    recording."""
    if record_envs is None:
        return contextlib.nullcontext()
    from warpcut.viz.recorder import Recorder

    return Recorder(out / "recording.rrd", envs=record_envs, colour_by=colour_by)


def step_callbacks(recorder, cuts, meshes=None):
    """The pipelines' ``step_callbacks(method, first_contour)``: the recorder's (of the batches starting at
    the first contour: it records the first envs), the final-cut collector's and the mesh exporter's; None
    when none is on."""
    if recorder is None and cuts is None and meshes is None:
        return None

    def for_batch(method: str, first_contour: int):
        callbacks = [c.step_callback(method) for c in (cuts, meshes) if c is not None]
        if recorder is not None and first_contour == 0:
            callbacks.insert(0, recorder.step_callback(method))
        if len(callbacks) == 1:
            return callbacks[0]

        def on_step(task, action) -> None:
            for callback in callbacks:
                callback(task, action)

        return on_step

    return for_batch


def final_cuts(no_plots: bool):
    """A collector of every method's final cut for the regions plot, unless plots are off."""
    if no_plots:
        return None
    from warpcut.viz.plots import FinalCuts

    return FinalCuts()


def echo_recording(recorder) -> None:
    """Say where the recording went (if anything was recorded), and which methods had fewer envs than
    ``--record`` asked for."""
    if recorder is None or not recorder.written:
        return
    fewer = {m: k for m, k in recorder.recorded_envs.items() if k < recorder.envs}
    if fewer:
        ran = ", ".join(f"{m}: {k}" for m, k in fewer.items())
        click.echo(
            f"warning: --record {recorder.envs}: fewer envs ran, all of them recorded ({ran})", err=True
        )
    echo_written([recorder.path])


def echo_written(paths) -> None:
    for path in paths:
        click.echo(f"wrote {path}")


def log(line: str) -> None:
    """A pipeline's progress line, on stderr."""
    click.echo(line, err=True)


def plot_learning_curves(runs: dict[Path, str]) -> list[Path]:
    """Each training run's learning curve (``learning_curve.png/svg`` in it), titled as given."""
    from agents.plots import plot_learning_curve
    from warpcut.io import read_json

    written = []
    for run, title in runs.items():
        summary = read_json(run / "summary.json")
        written += plot_learning_curve(summary["history"], summary["validation"], run, title=title)
    return written


def infeasible_mark(feasible: bool | None) -> str:
    """What a printed result line ends with where its pinch point is not a feasible grasp (``feasible``
    False: the results' ``pinch_feasible``, allowed by ``allow_infeasible_pinch``); "" otherwise."""
    return "  [infeasible pinch]" if feasible is False else ""


def echo_infeasible(problems: dict[str, str | None]) -> None:
    """Say, for the results ``{what: why its pinch point is not a feasible grasp}`` (None: it is), that they
    are not ones the robot could reach (one line per reason)."""
    grouped: dict[str, list[str]] = {}
    for what, why in problems.items():
        if why is not None:
            grouped.setdefault(why, []).append(what)
    for why, whats in grouped.items():
        click.echo(f"infeasible pinch ({', '.join(whats)}): {why}; not a result the robot could reach")
