"""Files written so that a crash or Ctrl-C never leaves a half-written result behind, file names that
never leave their directory, and run directories that one process at a time owns."""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import fcntl
import hashlib
import json
import math
import os
import re
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

RUN_MARKER = ".warpcut-run.json"
"""The file by which warpcut marks a run directory as its own (:func:`claim_run_dir`): the command that
claimed it, the run's id, when, and every file the run wrote there (the only files ``--overwrite``
deletes)."""

_SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")

_TEMP_TAG = ".warpcut.tmp"
_TEMP_NAME = re.compile(r"\.(.+)\.[a-z0-9_]{8}" + re.escape(_TEMP_TAG) + r"(?:\.[a-z0-9]{1,4})?")
"""The temporary file of NAME that :func:`temp_file` makes: ``.NAME.XXXXXXXX.warpcut.tmp`` (and an
extension its writer needs, e.g. ``.mp4``), a form no one else uses: ``--overwrite`` deletes only these
beside the files a run wrote, never a user's ``.NAME.orig`` or ``.NAME.swp``."""


def plain_file_mode() -> int:
    """The mode a plain ``open(path, "w")`` would give a new file: mkstemp's temporary files are 0600."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


WRITE_ERRORS = {
    errno.ENOSPC: ("the disk is full", "free space"),
    errno.EDQUOT: ("the disk quota is exceeded", "free space within the quota"),
    errno.EFBIG: ("the file is larger than this process may write (ulimit -f)", "raise the limit"),
    errno.EROFS: ("the file system is read-only", "make it writable, or write elsewhere"),
    errno.EACCES: ("permission denied", "make the folder writable, or write elsewhere"),
    errno.EPERM: ("permission denied", "make the folder writable, or write elsewhere"),
    errno.EIO: ("an I/O error (a failing disk or a lost network mount?)", "check the disk"),
    errno.ENOENT: ("a folder on its path does not exist and cannot be made", "create it, or write elsewhere"),
    errno.ENOTDIR: ("a part of its path is a file, not a folder", "write elsewhere"),
}
"""The reason and the fix that :class:`WriteFailed` gives for an ``OSError`` on write, by its errno; any
other errno is named as the OS words it."""


class WriteFailed(ValueError):
    """A write failed in the OS (a full disk, a quota, a file-size limit, a read-only or unwritable folder,
    an I/O error); the file it would have replaced is intact. The ``OSError`` is its cause.

    Attributes:
        path: The file not written.
        reason: What went wrong, in words ("the disk is full").
        fix: What to do before writing again ("free space").
    """

    def __init__(self, path: Path, error: OSError):
        self.path = Path(path)
        self.reason, self.fix = WRITE_ERRORS.get(
            error.errno, (error.strerror or type(error).__name__, "fix that")
        )
        super().__init__(f"{path}: not written, {self.reason}; its previous version (if any) is intact")


def temp_file(path: Path, extension: str = "") -> tuple[int, str]:
    """A new temporary file beside ``path`` for writing it atomically: its open descriptor (the mode a
    plain ``open`` would give) and its name, which only warpcut's temporary files have (:data:`_TEMP_NAME`;
    ``extension``, e.g. ``".mp4"``, for a writer that needs one)."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=_TEMP_TAG + extension)
    os.fchmod(fd, plain_file_mode())
    return fd, tmp


def write_atomic(path: str | os.PathLike, data: bytes | str) -> Path:
    """Write ``data`` to a temporary file beside ``path``, fsync it, then rename it over ``path``: a write
    that fails (a full disk, a file-size limit, a read-only folder, a signal) leaves the file at ``path`` as
    it was and no temporary file. A file written inside a run directory that warpcut claimed is listed in
    its marker (:func:`note_written`).

    Raises:
        ValueError: ``path`` is a directory; :class:`WriteFailed` (a ``ValueError``; the ``OSError`` is its
            cause) when the OS refuses the write. The message names the file and why.
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path}: is a directory, not a file; choose another path")
    raw = data.encode() if isinstance(data, str) else data
    tmp = None
    try:
        note_written(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = temp_file(path)
        with os.fdopen(fd, "wb") as f:
            f.write(raw)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        if tmp is not None:
            with contextlib.suppress(OSError):
                Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise WriteFailed(path, exc) from exc
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


@dataclasses.dataclass
class _Claim:
    """A run directory this process holds: its marker's contents and the open directory it locks."""

    path: Path
    marker: dict
    fd: int
    deleted: list[str] = dataclasses.field(default_factory=list)
    kept: list[str] = dataclasses.field(default_factory=list)
    listed: set[str] = dataclasses.field(default_factory=set)
    """The marker's files, as a set (a run may write many thousands)."""

    def __post_init__(self) -> None:
        self.listed = set(self.marker["files"])


_HELD: dict[Path, _Claim] = {}
"""The run directories this process holds, by resolved path (a claim inside one of them passes)."""


def _marker_path(path: Path) -> Path:
    return path / RUN_MARKER


def read_run_marker(path: str | os.PathLike) -> dict | None:
    """The marker of the run directory ``path`` (:data:`RUN_MARKER`), or None where warpcut never marked it
    (no marker, or a file there that is not one)."""
    try:
        marker = check_nesting(json.loads(_marker_path(Path(path)).read_text()), RUN_MARKER)
    except (OSError, ValueError, RecursionError):
        return None
    if not (isinstance(marker, dict) and marker.get("format") == "warpcut-run"):
        return None
    files = marker.get("files")
    marker["files"] = [f for f in files if isinstance(f, str)] if isinstance(files, list) else []
    return marker


def _write_marker(claim: _Claim) -> None:
    claim.marker["files"] = sorted(claim.listed)
    write_atomic(_marker_path(claim.path), json.dumps(claim.marker, indent=2) + "\n")


def _holder(path: Path) -> _Claim | None:
    """The claim of this process that ``path`` lies in, if any."""
    path = Path(os.path.abspath(path))
    for parent in (path, *path.parents):
        key = parent.resolve() if parent.exists() else parent
        if key in _HELD:
            return _HELD[key]
    return None


def enclosing_run(path: str | os.PathLike) -> Path | None:
    """The run directory that ``path`` lies in (one this process holds, or the nearest marked folder at
    or above it), or None."""
    path = Path(os.path.abspath(path))
    claim = _holder(path)
    if claim is not None:
        return claim.path
    for parent in (path, *path.parents):
        if _marker_path(parent).is_file() and read_run_marker(parent) is not None:
            return parent
    return None


def written_by_warpcut(path: str | os.PathLike) -> bool:
    """Whether the file ``path`` is one a warpcut run wrote (listed in the marker of its run directory)."""
    run = enclosing_run(path)
    if run is None:
        return False
    claim = _holder(Path(path))
    files = claim.marker["files"] if claim is not None else (read_run_marker(run) or {}).get("files", [])
    return _in_run(Path(path), Path(run)) in files


def _in_run(path: Path, run: Path) -> str | None:
    """``path`` relative to the run directory ``run``, both resolved (``path``'s folders, not ``path``
    itself: a file that is a link is the link), or None where ``path`` leads out of ``run`` (through a link
    among its folders)."""
    path = Path(os.path.abspath(path))
    relative = os.path.relpath(path.parent.resolve() / path.name, run.resolve())
    return None if relative == ".." or relative.startswith(f"..{os.sep}") else relative


def _link_out(path: Path) -> tuple[Path, str] | None:
    """A link among the folders in the run directory ``path`` that leads out of it, and where to: what a
    run writes or deletes there would land outside (a folder of the run replaced by a link), or None."""
    real = os.path.realpath(path)
    for folder, dirs, _ in os.walk(path):
        for name in dirs:  # os.walk lists a link to a folder here and does not descend into it
            entry = os.path.join(folder, name)
            target = os.path.realpath(entry)
            if os.path.islink(entry) and os.path.commonpath([real, target]) != real:
                return Path(entry), target
    return None


def note_written(path: str | os.PathLike, *, written: bool = False) -> None:
    """List ``path`` in the marker of the run directory it lies in, as a file warpcut wrote there (before
    it is written: a run killed mid-write still names it). A path in no run directory this process holds
    is listed in the marker of the nearest enclosing run directory, claimed for the moment (e.g. ``warpcut
    export`` writing beside a finished run); outside any run directory, nothing is done. ``written``: the
    file exists already because this run wrote it through a library that names its own files (rsl-rl's
    TensorBoard events), so it is listed, not refused.

    Raises:
        ValueError: ``path`` exists in a run directory and the run did not write it (a file put there by
            hand): warpcut never replaces it. Or the enclosing run directory is in use by another process.
    """
    path = Path(os.path.abspath(path))
    if path.name == RUN_MARKER:
        return
    claim = _holder(path)
    if claim is None:
        run = enclosing_run(path.parent)
        if run is not None:
            with claim_run_dir(run, command=None, resume=True):
                note_written(path, written=written)
        return
    relative = _in_run(path, claim.path)
    if relative is None:
        raise ValueError(
            f"{path}: leads out of the run directory {claim.path} through a link ({path.parent} is "
            f"{path.parent.resolve()}); warpcut never writes through it: remove the link, or choose another "
            "output folder"
        )
    if relative in claim.listed:
        return
    if (path.exists() or path.is_symlink()) and not written:
        raise ValueError(
            f"{path}: exists, and warpcut did not write it (it is not in {claim.path / RUN_MARKER}), so it "
            "never replaces it: move it, or choose another output folder"
        )
    claim.listed.add(relative)
    claim.marker["files"].append(relative)
    _write_marker(claim)


def _lock(path: Path, option: str = "--out") -> int:
    """An open descriptor of the directory ``path`` holding its exclusive lock; a ``ValueError`` names the
    process that holds it already."""
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as exc:
        os.close(fd)
        if exc.errno not in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
            raise ValueError(f"{path}: cannot be locked ({exc.strerror}); choose another {option}") from None
        marker = read_run_marker(path) or {}
        holder = f"warpcut process {marker['pid']}" if marker.get("pid") else "another warpcut process"
        raise ValueError(
            f"{path}: in use by {holder}; wait for it to finish, or choose another {option}"
        ) from None
    return fd


def check_not_busy(path: str | os.PathLike, option: str = "--out") -> None:
    """Refuse at once, before any work, a run directory ``path`` that another process holds (as
    :func:`claim_run_dir` would, after the work that precedes it); nothing is written or kept locked."""
    path = Path(path)
    if path.is_dir() and _holder(path) is None:
        with contextlib.suppress(OSError):  # a folder it cannot open: the claim says why, later
            os.close(_lock(path, option))


def _delete_written(path: Path, files: list[str]) -> tuple[list[str], list[str]]:
    """Delete what a run wrote in ``path``: the files its marker lists (and their temporary files), then the
    folders that held them where they are left empty. Returns what was deleted and what was kept (the
    entries of ``path`` warpcut did not write)."""
    root, real = os.path.abspath(path), os.path.realpath(path)
    by_folder: dict[str, list[str]] = {}
    for name in files:
        file = os.path.normpath(os.path.join(root, name))
        folder = os.path.dirname(file)
        if file == root or os.path.commonpath([real, os.path.realpath(folder)]) != real:
            continue  # a path leading out of the run (an edited marker, a folder made a link): not followed
        by_folder.setdefault(folder, []).append(os.path.basename(file))
    deleted, folders = [], set()
    for folder, names in by_folder.items():
        try:
            present = os.listdir(folder)  # once per folder: a marker may list many thousands of files
        except OSError:
            continue
        listed = set(names)
        wanted = listed | {  # the temporary files of its writers, by the form only warpcut uses
            e for e in present if (temp := _TEMP_NAME.fullmatch(e)) is not None and temp.group(1) in listed
        }
        for name in sorted(wanted.intersection(present)):
            entry = os.path.join(folder, name)
            if os.path.islink(entry) or os.path.isfile(entry):
                os.unlink(entry)
                deleted.append(os.path.relpath(entry, root))
        parent = Path(folder)
        while str(parent) != root and os.path.commonpath([root, str(parent)]) == root:
            folders.add(parent)
            parent = parent.parent
    for folder in sorted(folders, key=lambda p: len(p.parts), reverse=True):
        with contextlib.suppress(OSError):
            folder.rmdir()  # only where it is empty: a file the user put there keeps its folder
    kept = sorted(p.name for p in Path(root).iterdir() if p.name != RUN_MARKER)
    return deleted, kept


def _check_run_dir(
    path: Path, command: str | None, resume: bool, overwrite: bool, option: str = "--out", reuse: bool = False
) -> tuple[dict | None, list]:
    """The marker and the entries of the folder ``path``, after the checks of :func:`claim_run_dir`."""
    marker = read_run_marker(path)
    contents = [p.name for p in path.iterdir() if p.name != RUN_MARKER]
    if marker is None and contents:
        outer = enclosing_run(path.parent)
        if outer is not None:
            command_of = (read_run_marker(outer) or {}).get("command") or "COMMAND"
            raise ValueError(
                f"{path}: is part of the run of 'warpcut {command_of}' in {outer}, not a run of its own; "
                f"continue that one (warpcut {command_of} ... --out {outer} --resume), or choose another "
                "--out"
            )
        damaged = _marker_path(path).exists()
        why = f"its {RUN_MARKER} is damaged" if damaged else f"no {RUN_MARKER}"
        raise ValueError(
            f"{path}: holds files warpcut did not write ({len(contents)} entries, {why}); "
            + ("warpcut never deletes them, so " if overwrite else "")
            + ("there is no run to resume; " if resume else "")
            + f"choose a new or empty folder for {option}"
        )
    command_of = marker.get("command") if marker else None
    what = f"a run of 'warpcut {command_of}'" if command_of else "a warpcut run"
    if reuse and marker is not None and marker.get("command") not in (command, None):
        raise ValueError(
            f"{path}: holds {what}; choose a new or empty folder for {option} (or one of warpcut {command}'s)"
        )
    if marker is not None and contents and not (resume or overwrite or reuse):
        raise ValueError(
            f"{path}: holds {what} ({marker.get('id', '?')}); pass --resume to continue it, --overwrite "
            "to delete what it wrote and start again, or choose another --out"
        )
    if resume and marker is not None and command and marker.get("command") not in (command, None):
        raise ValueError(
            f"{path}: holds {what}, not of 'warpcut {command}'; resume it with 'warpcut "
            f"{marker.get('command')}', or choose another --out"
        )
    return marker, contents


def check_run_dir(path: str | os.PathLike, *, command: str | None, resume: bool = False) -> None:
    """Refuse, as :func:`claim_run_dir` would, to read a run from ``path`` (e.g. its settings, to resume it)
    that warpcut did not mark, or that another command made; nothing is written."""
    path = Path(path)
    if path.is_dir():
        _check_run_dir(path, command, resume, overwrite=False)


@contextlib.contextmanager
def claim_run_dir(
    path: str | os.PathLike,
    *,
    command: str | None,
    resume: bool = False,
    overwrite: bool = False,
    argv: list[str] | None = None,
    option: str = "--out",
    reuse: bool = False,
) -> Iterator[Path]:
    """Own the run directory ``path`` while the block runs: create it, mark it as warpcut's
    (:data:`RUN_MARKER`: ``command``, a run id, when, and every file the run writes there) and hold an
    exclusive lock on it, so that a second process fails at once instead of mixing two runs' files.

    Only a new or empty folder starts a run. A folder warpcut did not mark is never written or deleted in.
    A marked one with a run in it is refused unless ``resume`` (continue it: only a run of the same
    ``command``; None: any) or ``overwrite`` (delete the files the run wrote, keep everything else, and start
    again; :func:`overwritten` says what went) is given; ``reuse`` writes into a folder of ``command``'s
    again without asking (an output folder, not a run: ``warpcut export``'s, ``simulate``'s). ``option``
    is the option the folder came from, for the messages. A claim inside a directory
    this process holds passes at once (a command claims its run directory, then the pipeline it runs claims
    it again). When the block ends with nothing written, the marker goes, and the folder too if the claim
    made it.

    Raises:
        ValueError: one line naming the folder, why, and the fix.
    """
    path = Path(path)
    if resume and overwrite:
        raise ValueError("--resume and --overwrite: give one (continue the run, or replace it)")
    if _holder(path) is not None:  # claimed already by this process (e.g. by the command around a pipeline)
        yield path
        return
    if path.exists() and not path.is_dir():
        raise ValueError(f"{path}: is a file, not a run directory; choose another {option}")
    made = [p for p in (path, *path.parents) if not p.exists()]  # removed again where nothing is written
    if made:
        try:
            path.mkdir(parents=True)
        except OSError as exc:
            reason, fix = WRITE_ERRORS.get(exc.errno, (exc.strerror, "fix that"))
            raise ValueError(
                f"{path}: cannot create the folder, {reason}; {fix}, or choose another {option}"
            ) from None
    try:
        fd = _lock(path, option)
    except BaseException:
        _remove_empty(made)
        raise
    claim, deleted, kept = None, [], []
    try:
        marker, contents = _check_run_dir(path, command, resume, overwrite, option, reuse)
        link = _link_out(path) if contents else None
        if link is not None:
            raise ValueError(
                f"{link[0]}: a link to {link[1]}, out of the run directory {path}; warpcut never writes or "
                f"deletes through it: remove the link, or choose another {option}"
            )
        if overwrite and marker is not None:
            deleted, kept = _delete_written(path, marker["files"])
        if (resume or reuse) and marker is not None and contents:
            marker.update(pid=os.getpid())
        else:
            marker = {
                "format": "warpcut-run",
                "command": command,
                "id": f"{time.strftime('%Y%m%d-%H%M%S')}-{uuid.uuid4().hex[:8]}",
                "argv": ["warpcut", *sys.argv[1:]] if argv is None else list(argv),
                "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                "pid": os.getpid(),
                "files": [],
            }
        claim = _Claim(path, marker, fd, deleted, kept)
        _write_marker(claim)
    except BaseException:
        os.close(fd)
        _remove_empty(made)
        raise
    key = path.resolve()
    _HELD[key] = claim
    try:
        yield path
    finally:
        del _HELD[key]
        try:
            if not claim.marker["files"] and not [p for p in path.iterdir() if p.name != RUN_MARKER]:
                _marker_path(path).unlink(missing_ok=True)  # nothing written: no run left behind
                _remove_empty(made)
            else:
                claim.marker.pop("pid", None)
                _write_marker(claim)
        except (OSError, ValueError):
            pass  # the marker stays as it was: it still lists every file written
        finally:
            os.close(fd)


def _remove_empty(folders: list[Path]) -> None:
    """Remove ``folders`` (deepest first), each only where it is empty: the folders a claim made."""
    for folder in folders:
        with contextlib.suppress(OSError):
            folder.rmdir()


def overwritten(path: str | os.PathLike) -> tuple[list[str], list[str]]:
    """What ``--overwrite`` did when this process claimed the run directory ``path``: the files it deleted
    (those the earlier run wrote) and the entries it kept (those warpcut did not write)."""
    claim = _holder(Path(path))
    return (claim.deleted, claim.kept) if claim is not None else ([], [])


MAX_NESTING = 32
"""How deep the data warpcut reads (a run's JSON files, a config, a contour) may nest: its own nest fewer
than 10 levels; deeper data is refused before anything walks it (Python's recursion stops near 1,000)."""


def check_nesting(data: Any, where: str, items: int | None = None) -> Any:
    """``data`` (parsed JSON or YAML) as is, after checking, without expanding it, that it nests at most
    :data:`MAX_NESTING` deep, holds no cycle (a YAML alias inside itself) and, where ``items`` is given,
    expands to at most that many values (each shared part counted as often as it is reached).

    Raises:
        ValueError: one line naming ``where``, what was found and the limit.
    """
    sizes: dict[int, int] = {}
    open_: set[int] = set()

    def size(obj: Any, depth: int) -> int:
        if isinstance(obj, dict):
            children = obj.values()
        elif isinstance(obj, list | tuple):
            children = obj
        else:
            return 1
        key = id(obj)
        if key in sizes:
            return sizes[key]
        if key in open_:
            raise ValueError(f"{where}: holds itself (a recursive alias); write the data out")
        if depth >= MAX_NESTING:
            raise ValueError(_too_deep(where))
        open_.add(key)
        total = 1
        for child in children:
            total += size(child, depth + 1)
            if items is not None and total > items:
                raise ValueError(
                    f"{where}: expands to more than {items:,} values (nested aliases?); write the data out "
                    "without them, or make it smaller"
                )
        open_.discard(key)
        sizes[key] = total
        return total

    size(data, 0)
    return data


def read_json(path: str | os.PathLike) -> Any:
    """The JSON in ``path``; a file that is not valid JSON, or nests deeper than any of warpcut's
    (:func:`check_nesting`), raises ``ValueError`` naming it (a missing file: ``FileNotFoundError``, as
    ``open`` raises it)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not a valid JSON file ({exc}); restore or remove it") from None
    except RecursionError:  # too deep for the parser itself
        raise ValueError(f"{_too_deep(path)}; not a file warpcut wrote: restore or remove it") from None
    try:
        return check_nesting(data, str(path))
    except ValueError as exc:
        raise ValueError(f"{exc}; not a file warpcut wrote: restore or remove it") from None


def _too_deep(where: str | os.PathLike) -> str:
    return f"{where}: nests deeper than {MAX_NESTING} levels (warpcut's data nest a few)"
