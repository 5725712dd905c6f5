"""What the commands share: the error handling, the common options and the output helpers."""

from __future__ import annotations

import contextlib
import math
import os
import re
import signal
import sys
import threading
import time
from pathlib import Path

import click

from agents.config import SEED_RANGE
from warpcut.sim.config import ARM_LENGTH_MM, RESOLUTION_RANGE, SimConfig
from warpcut.viz.process import RecordingError

COMMAND_LINE: list[str] = []
"""The command line of the command running (what a run directory's marker records)."""


class CleanErrors(click.Group):
    """Turn usage errors, the library's ValueErrors and files that cannot be read or written (an OSError
    naming a path; with ``WARPCUT_VERBOSE`` set, its traceback instead) into one line on stderr and exit
    status 2; a failed recording (:class:`RecordingError`) into one line and status 1
    (with ``WARPCUT_VERBOSE`` set, also the recorder process's traceback)."""

    def main(self, *args, **kwargs):
        kwargs["standalone_mode"] = False
        given = args[0] if args else kwargs.get("args")
        COMMAND_LINE[:] = ["warpcut", *(sys.argv[1:] if given is None else given)]
        handlers = _stop_on_signals()
        try:
            result = super().main(*args, **kwargs)
        except click.exceptions.Abort as exc:  # Ctrl-C, SIGTERM, SIGHUP: what was saved, how to continue
            click.echo(_interrupted_message(exc, args[0] if args else sys.argv[1:]), err=True)
            stop = _stop(exc)
            sys.exit(128 + stop.signum if stop is not None else 130)
        except click.exceptions.NoArgsIsHelpError as exc:  # no command given: the help, as --help shows it
            click.echo(exc.ctx.get_help())
            sys.exit(0)
        except click.ClickException as exc:
            hint = (
                f" (see 'warpcut {exc.ctx.command.name} --help')"
                if getattr(exc, "ctx", None) and exc.ctx.command is not self
                else ""
            )
            message = exc.format_message()
            if isinstance(exc, click.NoSuchOption) and (value := _negative_record(kwargs, args, exc)):
                # click reads "--record -1" (an option whose value is optional) as --record, then -1.
                message = f"--record: N must be a positive integer (got {value})"
            click.echo(f"error: {message}{hint}", err=True)
            sys.exit(2)
        except (ValueError, FileNotFoundError) as exc:
            click.echo(f"error: {exc}", err=True)
            sys.exit(2)
        except OSError as exc:  # a file that cannot be read or written (a path named), unless debugging
            if exc.filename is None or os.environ.get("WARPCUT_VERBOSE"):
                raise
            click.echo(f"error: {exc}", err=True)
            sys.exit(2)
        except RecordingError as exc:  # the file holds what was recorded until then
            click.echo(f"error: {exc}", err=True)
            for note in getattr(exc, "__notes__", ()) if os.environ.get("WARPCUT_VERBOSE") else ():
                click.echo(note, err=True)
            sys.exit(1)
        finally:
            for signum, handler in handlers.items():
                signal.signal(signum, handler)
        sys.exit(result if isinstance(result, int) else 0)


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised where the command is, so that it stops as after Ctrl-C: training saves a
    checkpoint and its summary, a pipeline names what to resume."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class RunInterrupted(KeyboardInterrupt):
    """A command's Ctrl-C (or :class:`Terminated`) once its training saved a checkpoint in ``run_dir``."""

    def __init__(self, run_dir: Path):
        super().__init__(str(run_dir))
        self.run_dir = run_dir


_RECEIVED: list[int] = []
"""The signals :func:`_raise_terminated` turned into :class:`Terminated` (a library that catches the
exception and raises a KeyboardInterrupt of its own, as Ray's waits do, loses its type, not the signal)."""


def _raise_terminated(signum: int, frame) -> None:
    _RECEIVED.append(signum)
    raise Terminated(signum)


def _stop(exc: BaseException) -> Terminated | None:
    """The SIGTERM or SIGHUP that stopped the command (its :class:`Terminated` in ``exc``'s causes, or the
    signal received), or None: a Ctrl-C."""
    stop = _cause(exc, Terminated)
    return stop if stop is not None or not _RECEIVED else Terminated(_RECEIVED[-1])


def _stop_on_signals() -> dict:
    """Turn SIGTERM and SIGHUP into :class:`Terminated` (main thread only); returns the old handlers."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {signum: signal.signal(signum, _raise_terminated) for signum in (signal.SIGTERM, signal.SIGHUP)}


def _cause(exc: BaseException, kind: type | str) -> BaseException | None:
    """The first exception of ``kind`` (a type, or the name of an attribute it has) in ``exc``'s chain of
    causes and contexts."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(kind, str) and hasattr(exc, kind) or isinstance(kind, type) and isinstance(exc, kind):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def _interrupted_message(exc: BaseException, argv: list[str]) -> str:
    """What an interrupted command says: the signal, the checkpoint a training saved and how to continue."""
    stop = _stop(exc)
    what = f"terminated ({stop})" if stop is not None else "interrupted"
    where = getattr(_cause(exc, "run_dir"), "run_dir", None)  # a pipeline's TrainingInterrupted
    command = next((a for a in argv if not a.startswith("-")), None)
    if where is not None:
        what += f": checkpoint saved in {where}"
    if command in ("evaluate", "run"):
        what += f"; continue with the same 'warpcut {command}' command plus --resume (same --out)"
    elif command == "train" and where is not None:
        what += f"; continue with 'warpcut train --resume {where}'"
    return what


def _negative_record(kwargs: dict, args: tuple, exc: click.NoSuchOption) -> str | None:
    """The negative number given to ``--record`` that click took for the unknown option ``exc`` names,
    if that is what happened."""
    given = list(kwargs.get("args") or (args[0] if args else sys.argv[1:]))
    for k, token in enumerate(given):
        if token == "--record" and k + 1 < len(given):
            value = given[k + 1]
        elif token.startswith("--record="):
            value = token.split("=", 1)[1]
        else:
            continue
        if re.fullmatch(r"-\d[\d.eE+-]*", value) and value.startswith(exc.option_name):
            return value
    return None


def _resolve_device(ctx: click.Context, param: click.Parameter, value: str | None) -> str:
    from warpcut.sim.simulator import resolve_device

    return resolve_device(value)


class FloatRange(click.FloatRange):
    """click's ``FloatRange`` that also refuses NaN, which its bounds let through (NaN compares false with
    every bound), and the infinities unless ``allow_inf`` (e.g. ``--arm-length inf``)."""

    def __init__(self, *args, allow_inf: bool = False, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.allow_inf = allow_inf

    def convert(self, value, param, ctx):
        number = super().convert(value, param, ctx)
        if math.isnan(number) or (math.isinf(number) and not self.allow_inf):
            self.fail(f"{number} is not a finite number.", param, ctx)
        return number


device_option = click.option(
    "--device",
    default=None,
    callback=_resolve_device,
    help="Warp device: cpu or cuda (default: cuda if available, else cpu).",
)
seed_option = click.option(
    "--seed",
    default=0,
    show_default=True,
    type=click.IntRange(*SEED_RANGE),
    help=f"Seed of everything random (noise, sampling, training); an integer in [0, {SEED_RANGE[1]}].",
)


DEFAULTS = SimConfig()
"""The library's defaults, which the options below show and pass on (one set for library and CLI)."""


arm_length_option = click.option(
    "--arm-length",
    default=ARM_LENGTH_MM,
    show_default=True,
    type=FloatRange(min=0.0, allow_inf=True),
    help="Reach of the cutting arm's footprint from the scissor tip toward +x (mm), for pinch feasibility; "
    "inf (the paper's cylinder): the whole way, so the grasp never holds the piece being cut; a short "
    "footprint (e.g. 15) lets it hold the piece (docs/results.md).",
)


generalist_option = click.option(
    "--generalist",
    "generalist_source",
    default=None,
    metavar="DIR",
    help="The generalist to play (a run directory of 'warpcut generalist'); default: the one warpcut ships.",
)


def _check_ray(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    from agents.cluster import parse_address

    try:
        parse_address(value)
    except ValueError as exc:
        raise click.BadParameter(str(exc).removeprefix("--ray: "), ctx, param) from None
    return value


def ray_option(units: str):
    """``--ray ADDRESS``: run the command's independent ``units`` on a Ray cluster (:mod:`agents.cluster`)."""
    return click.option(
        "--ray",
        default=None,
        metavar="ADDRESS",
        callback=_check_ray,
        help=f"Run {units} as tasks on a Ray cluster: local (a cluster of this machine's cores for the "
        "command; local:N, N CPUs), auto or HOST:PORT (one 'ray start' runs); the same results as "
        "without it (docs/cluster.md).",
    )


json_option = click.option(
    "--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write results here."
)


def out_option(default: str):
    """``--out DIR``, the run directory (``default`` says where it goes without it)."""
    return click.option(
        "--out",
        type=click.Path(file_okay=False, path_type=Path),
        default=None,
        help=f"Run directory (default: {default}).",
    )


overwrite_option = click.option(
    "--overwrite",
    is_flag=True,
    help="Delete what an earlier warpcut run wrote in --out (nothing else) and start again.",
)


def run_dir_options(command):
    """``--resume`` and ``--overwrite`` for a command that writes a run directory (``--out``)."""
    command = overwrite_option(command)
    return click.option(
        "--resume",
        is_flag=True,
        help="Continue the run in --out (interrupted, or to finish it): policies trained to the end are "
        "kept, interrupted ones continue from their checkpoints; the settings must be the run's.",
    )(command)


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


def count_option(name: str, default: int | None, help: str):
    """A positive integer option ``--NAME`` (shows its default when it has one)."""
    return click.option(
        f"--{name}", default=default, show_default=default is not None, type=click.IntRange(min=1), help=help
    )


contour_option = click.option(
    "--contour", "contour_name", required=True, help="Built-in name or a .json/.svg contour file."
)
resolution_option = click.option(
    "--resolution",
    default=DEFAULTS.resolution,
    show_default=True,
    type=click.IntRange(*RESOLUTION_RANGE),
    help="Vertices per side.",
)


def parse_point(value: str | None, name: str) -> tuple[float, float] | None:
    """``X,Y`` (mm) as a point; None stays None."""
    if value is None:
        return None
    try:
        x, y = (float(v) for v in value.split(","))
    except ValueError:
        raise click.BadParameter(f"expected X,Y in mm, e.g. 60,40 (got {value!r})", param_hint=name) from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise click.BadParameter(f"X and Y must be finite numbers in mm (got {value!r})", param_hint=name)
    return x, y


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
    from warpcut.io import read_json
    from warpcut.viz.plots import plot_learning_curve

    written = []
    for run, title in runs.items():
        summary = read_json(run / "summary.json")
        written += plot_learning_curve(summary["history"], summary["validation"], run, title=title)
    return written


class Command(click.Command):
    """click's command that refuses an option given twice: click would keep the last value without a word."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        try:
            return self._parse_args(ctx, args)
        except click.NoSuchOption as error:
            key = setting_of(self.name, error.option_name)
            if key is None:
                raise
            raise click.UsageError(
                f"{error.option_name}: '{self.name}' has no such option; it is a setting: --set {key}=VALUE",
                ctx=ctx,
            ) from None

    def invoke(self, ctx: click.Context):
        """Run the command, after refusing a run directory another process holds (``--out``,
        ``--resume``), with the library's advice in errors naming settings as the command gives them
        (:func:`setting_form`)."""
        from agents.cli.checks import setting_form
        from warpcut.io import check_not_busy
        from warpcut.planning.feasibility import setting_forms

        for name in ("out", "resume"):  # a run another process holds: said at once, not after the checks
            if isinstance(ctx.params.get(name), Path):
                check_not_busy(ctx.params[name], f"--{name}")
        with setting_forms(lambda key, value: setting_form(self, COMMAND_JOBS.get(self.name), key, value)):
            return super().invoke(ctx)

    def _parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        if args:
            _, _, order = self.make_parser(ctx).parse_args(args=list(args))
            seen: set[str] = set()
            for param in order:
                if not isinstance(param, click.Option) or param.multiple or param.count:
                    continue
                if param.name in seen:
                    raise click.UsageError(f"{param.opts[0]}: given twice; give it once", ctx=ctx)
                seen.add(param.name)
        return super().parse_args(ctx, args)


COMMAND_JOBS = {
    "run": "RunJob",
    "evaluate": "EvaluateJob",
    "train": "TrainJob",
    "optimize": "OptimizeJob",
    "robustness": "RobustnessJob",
    "simulate": "SimulateJob",
    "generalist": "GeneralistJob",
    "teachers": "TeachersJob",
}
"""Each command's job (:mod:`agents.jobs`): the settings ``--set`` reaches."""


def setting_of(command: str | None, option: str) -> str | None:
    """The ``--set`` key of ``command``'s job that an option it lacks (``--trials``, ``--num-envs``) names:
    the key itself, or the one key ending in it (``iterations``: ``train.iterations``); None if none."""
    if command not in COMMAND_JOBS:
        return None
    import agents.jobs
    from agents.config_io import flatten, to_plain

    name = option.lstrip("-").replace("-", "_")
    keys = flatten(to_plain(getattr(agents.jobs, COMMAND_JOBS[command])()))
    found = [key for key in keys if key == name or key.endswith(f".{name}")]
    return found[0] if len(found) == 1 or name in found else None


def config_options(command):
    """``--config FILE|PRESET``, ``--set KEY=VALUE`` (repeatable) and ``--print-config``: the settings a
    command's flags do not reach (:func:`resolve`)."""
    from agents.config_io import presets

    command = click.option(
        "--print-config", is_flag=True, help="Print the full resolved config (YAML) and exit."
    )(command)
    command = click.option(
        "--set",
        "overrides",
        multiple=True,
        metavar="KEY=VALUE",
        help="Set one setting by its dotted key (repeatable), e.g. --set sim.noise_std=0 --set "
        "train.es.sigma=0.01; --print-config shows every key.",
    )(command)
    return click.option(
        "--config",
        "config_file",
        metavar="FILE|PRESET",
        help="Settings from a TOML, YAML or JSON file (a run directory's config.json runs it again), or a "
        f"preset: {', '.join(presets())}. Flags and --set override it.",
    )(command)


def resolve(job_class, config_file: str | None, overrides: tuple[str, ...], flags: dict[str, str], base=None):
    """The job a command runs: the defaults (or ``base``), then the ``--config`` file, then ``--set``, then
    the flags given on the command line (``flags``: parameter name -> key), each checked by its key.

    Defaults that follow from other settings follow them unless given (:func:`agents.jobs.
    with_dependent_defaults`): ``--algo ppo`` trains PPO's discrete moves.

    Raises:
        click.UsageError: A key given twice (``--set`` twice, or a flag and ``--set``).
        ValueError: An unknown key or a value of the wrong type (naming it and where it came from).
    """
    from agents.config_io import apply, flatten, parse_override, read_file, to_plain
    from agents.jobs import with_dependent_defaults

    ctx = click.get_current_context()
    job = base if base is not None else job_class()
    explicit: set[str] = set()
    if config_file:
        data = read_file(config_file)
        job = apply(job, data, str(config_file))
        explicit |= set(flatten(data))
    sets: dict = {}
    for text in overrides:
        key, value = parse_override(text)
        if key in sets:
            raise click.UsageError(f"--set {key}: given twice; give it once")
        sets[key] = value
    given = {}
    for name, key in flags.items():
        if ctx.get_parameter_source(name) != click.core.ParameterSource.COMMANDLINE:
            continue
        flag = next(p.opts[0] for p in ctx.command.params if p.name == name)
        if key in sets:
            raise click.UsageError(f"{flag} and --set {key}: both set {key}; give one")
        given[key] = (flag, ctx.params[name])
    job = apply(job, sets, "--set")
    for key, (flag, value) in given.items():
        job = apply(job, {key: value}, flag)
    explicit |= set(sets) | set(given)
    if base is not None:  # a resumed run's own settings count as given
        explicit |= set(flatten(to_plain(base)))
    return with_dependent_defaults(job, explicit)  # a job checks its seed's range itself (SEED_RANGE)


NOT_SETTINGS = ("out", "json_path", "overwrite", "no_progress", "device")
"""The options that say where and how a command runs, not what: ``--print-config`` would ignore them."""


def print_config(job) -> None:
    """``--print-config``: the resolved job as YAML on stdout; an option that only says where or how the
    command would run (:data:`NOT_SETTINGS`) is refused with it, as a setting the invocation ignores."""
    from agents.config_io import to_yaml

    ctx = click.get_current_context()
    ignored = [
        p.opts[0]
        for p in ctx.command.params
        if p.name in NOT_SETTINGS
        and ctx.get_parameter_source(p.name) == click.core.ParameterSource.COMMANDLINE
    ]
    if ignored:
        raise click.UsageError(
            f"{', '.join(ignored)}: --print-config prints the settings and exits, running and writing "
            f"nothing; drop {'them' if len(ignored) > 1 else 'it'}"
        )
    click.echo(to_yaml(job), nl=False)


def point_callback(ctx: click.Context, param: click.Parameter, value: str | None) -> list[float] | None:
    """A ``X,Y`` option (mm) as ``[x, y]``."""
    point = parse_point(value, param.opts[0])
    return None if point is None else [float(v) for v in point]


def record_flag(what: str):
    """``--record [N]``: a rerun recording (``what``) of the first N envs (default 1) of each method."""
    return click.option(
        "--record",
        "record_envs",
        type=click.IntRange(min=1),
        is_flag=False,
        flag_value=1,
        default=None,
        metavar="[N]",
        help=f"Write recording.rrd ({what}) of the first N envs (default 1) of each method; view it with "
        "'warpcut replay' (colours: --set colour_by=strain|height).",
    )


def resumed_job(job_class, out: Path | None, resume: bool, command: str):
    """With ``--resume``, the job the run in ``out`` was started with (its ``config.json``): the base of the
    settings, so that a resumed run keeps its own and only what is given again changes (and is then
    checked against the run's); None when not resuming, or when the run saved no settings yet."""
    from agents.jobs import CONFIG_FILE
    from warpcut.io import check_run_dir

    if not resume or out is None or not out.is_dir():
        return None
    check_run_dir(out, command=command, resume=True)  # a run of this command, before its settings are read
    return saved_job(job_class, out / CONFIG_FILE) if (out / CONFIG_FILE).is_file() else None


def saved_job(job_class, path: Path):
    """The job a run directory's ``config.json`` (``path``) holds, to resume it."""
    from agents.config_io import apply
    from warpcut.io import read_json

    if not path.is_file():
        from warpcut.io import read_run_marker

        marker = read_run_marker(path.parent)
        if marker is not None:  # killed before it saved its settings: nothing to continue
            line = " ".join(marker.get("argv") or []) or "its command"
            raise click.BadParameter(
                f"{path.parent}: the run stopped before it saved its settings ({path.name}); start it "
                f"again, without --resume: {line}",
                param_hint="--resume",
            )
        raise click.BadParameter(
            f"{path.parent}: no {path.name}: not a run this command wrote; give its run directory",
            param_hint="--resume",
        )
    data = read_json(path)
    if not isinstance(data, dict):
        raise click.BadParameter(
            f"{path}: not a run's settings; restore it, or start a new run", param_hint="--resume"
        )
    return apply(job_class(), data, str(path))


def refuse_unused_keys(
    job, keys: list[str], overrides: tuple[str, ...], flags: dict[str, str], why: str
) -> None:
    """A UsageError naming the settings under ``keys`` (dotted keys or sections, e.g. ``grad``) that this
    invocation gives but would ignore (``why``: when they apply), instead of ignoring them without a word:
    those that ``--set`` or a flag (``flags``: parameter name -> key) gives, and those away from the job's
    defaults (a ``--config`` file's; a run directory's ``config.json`` holds each unused setting at its
    default, so it runs again as it is)."""
    from agents.config_io import flatten, parse_override, to_plain

    def under(key: str) -> bool:
        return any(key == k or key.startswith(f"{k}.") for k in keys)

    ctx = click.get_current_context()
    now, default = flatten(to_plain(job)), flatten(to_plain(type(job)()))
    given = [key for key, _ in map(parse_override, overrides)]
    given += [
        key
        for name, key in flags.items()
        if ctx.get_parameter_source(name) == click.core.ParameterSource.COMMANDLINE
    ]
    given += [key for key, value in now.items() if value != default.get(key)]
    unused = [key for key in dict.fromkeys(given) if under(key)]
    if unused:
        raise click.UsageError(f"{', '.join(unused)}: {why}; drop {'them' if len(unused) > 1 else 'it'}")


def refuse_unused_settings(job, overrides: tuple[str, ...], flags: dict[str, str]) -> None:
    """The general rule that a setting the job would not use is refused, not ignored: each key that
    ``job.unused_keys()`` names (``{key: when it applies}``, from the job's own settings, e.g. simulate's
    ``pinch`` where ``policy`` has neither fixed nor analytic) is checked against the keys given (a flag,
    ``--set``, or a value away from the default: :func:`refuse_unused_keys`)."""
    for key, why in job.unused_keys().items():
        refuse_unused_keys(job, [key], overrides, flags, why)


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


def check_learner(job) -> None:
    """``ValueError`` naming the setting, before any work, where ``job``'s learner (``job.train``) cannot
    train in its env (``job.env``): an action type it does not play, a population that does not fit the
    batch, an actor's feedback path on a tracking error the policy does not observe, or domain
    randomisation (or a relative reward) for APG, which differentiates one fixed sheet."""
    import dataclasses

    from agents.algorithms import algorithm

    job.train.check(job.env.action_type == "discrete")
    device = job.train.torch_device
    if device.startswith(("cuda", "mps")):
        import torch

        backend = torch.cuda if device.startswith("cuda") else torch.backends.mps
        index = int(device.partition(":")[2] or 0)
        if not backend.is_available() or (backend is torch.cuda and index >= torch.cuda.device_count()):
            raise ValueError(f"train.torch_device: {device} is not available here; use cpu (the default)")
    if job.train.feedback and not job.env.contour_features:
        own = {f.name for f in dataclasses.fields(job.train.learner)}
        drop = f"train.{job.train.algo}.feedback=false" if "feedback" in own else "--algo ppo"
        raise ValueError(
            "feedback: the policy observes no tracking error (env.contour_features=false); observe the "
            f"contour, or train without the feedback path ({drop})"
        )
    fixed_sheet = algorithm(job.train.algo).fixed_sheet
    if fixed_sheet is not None and (job.env.randomize or job.env.relative_reward):
        raise ValueError(fixed_sheet)
    from agents.cli.checks import check_network_memory

    check_network_memory(job.train)
