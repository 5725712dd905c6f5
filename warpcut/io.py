"""Files written so that a crash or Ctrl-C never leaves a half-written result behind, file names that
never leave their directory, and run directories that one process at a time owns."""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import json
import math
import os
import re
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

LOCK_FILE = ".warpcut.lock"
"""The lock file in a run directory that the process writing it holds (:func:`claim_run_dir`)."""

_RUN_FILES = ("results.json", "summary.json", "options.json", "scenario.json", "config.json", "plan.json")
"""Files by which :func:`claim_run_dir` recognises a run directory warpcut wrote before run directories
had a lock file."""

_SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")

_HELD: set[Path] = set()
"""The run directories this process has claimed (a claim inside a claim of the same directory passes)."""


def plain_file_mode() -> int:
    """The mode a plain ``open(path, "w")`` would give a new file: mkstemp's temporary files are 0600."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


class DiskFull(ValueError):
    """A write failed for lack of space (``ENOSPC``, ``EDQUOT``); the file it would replace is intact."""


def write_atomic(path: str | os.PathLike, data: bytes | str) -> Path:
    """Write ``data`` to a temporary file beside ``path``, fsync it, then rename it over ``path``: a write
    that fails (a full disk, a signal) leaves the file at ``path`` as it was and no temporary file.

    Raises:
        ValueError: ``path`` is a directory; :class:`DiskFull` (a ``ValueError``; the ``OSError`` is its
            cause) when the disk is full. The message names the file.
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path}: is a directory, not a file; choose another path")
    path.parent.mkdir(parents=True, exist_ok=True)
    raw = data.encode() if isinstance(data, str) else data
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, plain_file_mode())
        with os.fdopen(fd, "wb") as f:
            f.write(raw)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT):
            raise DiskFull(
                f"{path}: not written, the disk is full; its previous version (if any) is intact"
            ) from exc
        raise
    return path


def write_json(path: str | os.PathLike, obj: Any) -> Path:
    """Atomically write ``obj`` as indented, standard JSON: a non-finite float (a missing value, e.g. the
    score of a diverged trial) is written as ``null``, never as ``NaN``/``Infinity``."""
    return write_atomic(path, json.dumps(finite_json(obj), indent=2, sort_keys=False, allow_nan=False) + "\n")


def finite_json(obj: Any) -> Any:
    """``obj`` as :func:`write_json` writes it: every non-finite float (NumPy's included) replaced by None,
    NumPy values as Python ones, containers copied."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite_json(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite_json(v) for v in obj]
    if hasattr(obj, "dtype") and hasattr(obj, "tolist"):  # NumPy scalars and arrays
        return finite_json(obj.tolist())
    return obj


def safe_name(name: str) -> str:
    """A file name for ``name`` (e.g. a contour's) that stays inside its directory: ``name`` itself when it
    is a plain name (letters, digits, ``.``, ``_``, ``-``; at most 64 characters; not starting with a dot or
    dash), else a slug of it plus a short hash, so that different names never share a file."""
    if _SAFE_NAME.fullmatch(name) and name not in (".", ".."):
        return name
    slug = re.sub(r"[^A-Za-z0-9._-]+", "-", name).strip(".-_")[:48] or "contour"
    return f"{slug}-{hashlib.sha1(name.encode()).hexdigest()[:8]}"


@contextlib.contextmanager
def claim_run_dir(
    path: str | os.PathLike, *, resume: bool = False, overwrite: bool = False
) -> Iterator[Path]:
    """Own the run directory ``path`` while the block runs: create it, and hold an exclusive lock on its
    :data:`LOCK_FILE` so that a second process fails at once instead of mixing two runs' files.

    An existing directory with files in it is refused unless ``resume`` (continue the run in it) or
    ``overwrite`` (delete its contents first; only in a directory warpcut wrote) is given; the error says
    which option does what. Claiming a directory this process holds already passes at once (a command
    claims its run directory, then the pipeline it runs claims it again).

    Raises:
        ValueError: ``path`` is a file, is not empty (and neither option given), or another process holds
            its lock; both options given.
    """
    path = Path(path)
    if resume and overwrite:
        raise ValueError("--resume and --overwrite: give one (continue the run, or replace it)")
    key = path.resolve()
    if key in _HELD:  # claimed already by this process (e.g. by the command around a pipeline)
        yield path
        return

    if path.exists() and not path.is_dir():
        raise ValueError(f"{path}: is a file, not a run directory; choose another --out")
    path.mkdir(parents=True, exist_ok=True)
    claimed_before = (path / LOCK_FILE).exists() or any((path / f).exists() for f in _RUN_FILES)
    with open(path / LOCK_FILE, "a+") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno not in (errno.EAGAIN, errno.EACCES):
                raise
            lock.seek(0)
            holder = lock.read().strip() or "another process"
            raise ValueError(
                f"{path}: in use by {holder}; wait for it to finish, or choose another --out"
            ) from None
        contents = [p for p in path.iterdir() if p.name != LOCK_FILE]
        if contents and not (resume or overwrite):
            raise ValueError(
                f"{path}: already holds a run ({len(contents)} entries); pass --resume to continue it, "
                "--overwrite to replace it, or choose another --out"
            )
        if overwrite and contents and not claimed_before:
            raise ValueError(
                f"{path}: --overwrite deletes a run directory's contents, and this does not look like one "
                f"(none of {', '.join(_RUN_FILES)}); empty or remove it yourself, or choose another --out"
            )
        if overwrite:
            for entry in contents:
                shutil.rmtree(entry) if entry.is_dir() and not entry.is_symlink() else entry.unlink()
        lock.seek(0)
        lock.truncate()
        lock.write(f"warpcut process {os.getpid()}\n")
        lock.flush()
        _HELD.add(key)
        try:
            yield path
        finally:
            _HELD.discard(key)
            lock.seek(0)
            lock.truncate()


def read_json(path: str | os.PathLike) -> Any:
    """The JSON in ``path``; a file that is not valid JSON raises ``ValueError`` naming it (a missing
    file: ``FileNotFoundError``, as ``open`` raises it)."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not a valid JSON file ({exc}); restore or remove it") from None
