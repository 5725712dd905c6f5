"""How a command ends: the library's errors, usage errors and unreadable or unwritable files as one line
on stderr, and Ctrl-C, SIGTERM and SIGHUP as an interruption that says what was saved and how to continue."""

from __future__ import annotations

import os
import re
import signal
import sys
import threading
from pathlib import Path

import click

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
        handlers, unraisable = _stop_on_signals(), sys.unraisablehook
        sys.unraisablehook = _redeliver
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
            sys.unraisablehook = unraisable
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


def _redeliver(unraisable) -> None:
    """``sys.unraisablehook`` while a command runs: a Ctrl-C, SIGTERM or SIGHUP whose exception was raised
    inside a finalizer (a ``__del__``, which Python runs wherever memory is freed and whose exceptions it
    prints and drops) is sent again, from a thread of its own once this hook has returned (a handler run
    inside the hook would be dropped too), so that it stops the command at its next step instead of being
    lost; anything else goes to Python's hook."""
    exc = unraisable.exc_value
    if isinstance(exc, KeyboardInterrupt) and threading.current_thread() is threading.main_thread():
        signum = exc.signum if isinstance(exc, Terminated) else signal.SIGINT
        again = threading.Timer(0.01, os.kill, (os.getpid(), signum))
        again.daemon = True
        again.start()
        return
    sys.__unraisablehook__(unraisable)


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
