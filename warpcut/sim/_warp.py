"""Warp, imported with warpcut's settings: Warp prints a banner and a line per module load; keep the
CLI's output to our own unless ``WARPCUT_VERBOSE`` is set. Every warpcut module that uses Warp imports
it from here (``from warpcut.sim._warp import wp``), so that ``import warpcut`` itself stays light: the
recorder process and the CLI's start-up do not pay for Warp.

On a machine without NVIDIA's driver, Warp's native code prints "Warp CUDA warning: Could not find or
load the NVIDIA CUDA driver" on every start, which says nothing to someone who runs on the CPU anyway
(``--device cuda`` still fails with a clear error there): unless ``WARPCUT_VERBOSE`` is set, Warp is
initialised here, at import, with its standard error silenced when the driver cannot be loaded (so set
``wp.config`` options that ``wp.init()`` reads, such as the kernel cache, by their environment variables,
e.g. ``WARP_CACHE_PATH``, or before importing warpcut's simulator).

Warpcut initialises Warp through :func:`init` (at import, or when a device is resolved): a kernel cache
that cannot be created or written (``WARP_CACHE_PATH`` pointing at a read-only folder, or below a file)
raises :class:`KernelCacheError`, one line naming the cache and the fix, instead of a bare errno.

warpcut launches its kernels through :func:`launch`, which loads each module once through
:func:`load_module`: a module Warp cannot load (a corrupt kernel cache) raises :class:`KernelCacheError`,
one line naming the cache directory to delete, instead of Warp's traceback.
"""

import ctypes
import errno
import os
import shlex
import sys

import numpy as np
import warp as wp

from warpcut.limits import write_cause as _write_cause


def _cuda_driver_loadable() -> bool:
    for name in ("libcuda.so", "libcuda.so.1") if sys.platform.startswith("linux") else ():
        try:
            ctypes.CDLL(name)
            return True
        except OSError:
            pass
    return not sys.platform.startswith("linux")  # elsewhere: leave Warp's messages alone


def _init_quietly() -> None:
    """``wp.init()`` with file descriptor 2 pointed at /dev/null (the message comes from C); a plain
    ``wp.init()`` where there is no standard error to silence."""
    if sys.stderr is not None:
        sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # fd 2 is closed: nothing would be printed anyway
        wp.init()
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
        wp.init()
    finally:
        os.dup2(saved, 2)
        os.close(saved)


class KernelCacheError(ValueError):
    """Warp could not use its kernel cache: a cache folder that cannot be created or written (:func:`init`,
    :func:`load_module`), or one of warpcut's kernel modules that could not be loaded, most often because
    the cache holds truncated or garbled files; the message names the cache and the fix. A ``ValueError``
    so that the CLI reports it in one line."""


CACHE_ENV = "WARP_CACHE_PATH"
"""The environment variable that moves Warp's kernel cache (read by ``wp.init()``)."""

_UNWRITABLE = (errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOTDIR, errno.EEXIST)
"""What ``os.makedirs`` or a write in the cache fails with when the folder cannot be made or written."""


def _cache_text() -> str:
    """The kernel cache as the user knows it: ``WARP_CACHE_PATH=...`` where set, else Warp's folder."""
    given = os.environ.get(CACHE_ENV)
    if given:
        return f"{CACHE_ENV}={given}"
    return f"Warp's kernel cache {wp.config.kernel_cache_dir or '(its default folder)'}"


def _unwritable_cache(error: OSError) -> KernelCacheError:
    where = f" ({error.filename})" if error.filename else ""
    reason = error.strerror or type(error).__name__
    return KernelCacheError(
        f"Warp kernels: cannot create or write the kernel cache, {_cache_text()}{where}: {reason}; make it a "
        f"writable folder, or point {CACHE_ENV} at one (e.g. {CACHE_ENV}=/tmp/warp-cache)"
    )


def init() -> None:
    """``wp.init()`` (quietly where the CUDA driver cannot be loaded, unless ``WARPCUT_VERBOSE``).

    Raises:
        KernelCacheError: The kernel cache folder cannot be created or written; the message names it
            (``WARP_CACHE_PATH``) and the fix.
    """
    global _initialised
    if _initialised:
        return
    quiet = not os.environ.get("WARPCUT_VERBOSE") and not _cuda_driver_loadable()
    try:
        _init_quietly() if quiet else wp.init()
    except OSError as error:
        if _write_cause(error) is not None:
            raise _cache_write_failed(error) from None
        if error.errno in (*_UNWRITABLE, errno.ENOENT) or isinstance(error, PermissionError):
            raise _unwritable_cache(error) from None  # ENOENT: a folder under /proc or /sys
        raise
    _initialised = True


_initialised = False


_loaded: set[tuple[str, str]] = set()


def load_module(module: wp.Module, device: str) -> None:
    """Load ``module`` on ``device`` (compile it, or read it from Warp's kernel cache) unless done before.

    Raises:
        KernelCacheError: Warp failed (e.g. a corrupt cached binary or ``.meta`` file, or a cache it cannot
            write); the message says where the cache is (``wp.config.kernel_cache_dir``) and what to do.
    """
    key = (module.name, str(device))
    if key in _loaded:
        return
    try:
        wp.load_module(module, device=wp.get_device(device))
    except OSError as error:
        if _write_cause(error) is not None:  # not a corrupt cache: one it could not write
            raise _cache_write_failed(error) from error
        if error.errno in _UNWRITABLE or isinstance(error, PermissionError):
            raise _unwritable_cache(error) from error
        raise _corrupt_cache(module, device, error) from error
    except Exception as error:  # Warp raises bare Exceptions, JSONDecodeError...
        raise _corrupt_cache(module, device, error) from error
    _loaded.add(key)


def _cache_write_failed(error: OSError) -> KernelCacheError:
    """Writing the kernel cache failed for a limit of the OS (a file-size limit, a full disk)."""
    return KernelCacheError(
        f"Warp kernels: could not write the kernel cache, {_cache_text()} "
        f"({error.strerror or type(error).__name__}): {_write_cause(error)}"
    )


def _corrupt_cache(module: wp.Module, device: str, error: Exception) -> KernelCacheError:
    cache = wp.config.kernel_cache_dir
    detail = " ".join(f"{type(error).__name__}: {error}".split())
    return KernelCacheError(
        f"Warp kernels: could not load module {module.name!r} on {device} ({detail}); its kernel cache "
        f"{cache!r} may be corrupt: delete that directory (rm -rf {shlex.quote(str(cache))}) and run "
        "again, Warp recompiles the kernels"
    )


def launch(kernel: wp.Kernel, dim, inputs=(), outputs=(), device: str | None = None, **options) -> None:
    """``wp.launch``, after :func:`load_module` of the kernel's module (a set lookup once loaded)."""
    load_module(kernel.module, device)
    wp.launch(kernel, dim=dim, inputs=inputs, outputs=outputs, device=device, **options)


_NUMBERS = (bool, int, float, np.number)


class LaunchRecord:
    """One call site's :func:`launch`, recorded once (``wp.launch(..., record_cmd=True)``) and replayed.

    ``wp.launch`` packs every argument into its C form in Python at every call (the ``simd`` update's 23
    arguments and the tip tracing's 8 cost more than a 64-env update's own work on this 2-core CPU;
    docs/performance.md, section 6). A record replays the packed launch while its arrays and structs are the
    same objects (taken by identity: their contents may change, a struct must not be changed in place) and
    re-packs only the numbers whose values changed (a noise seed, an update index). Any other argument that
    changed records the launch again. The same kernel, arguments and launch bounds as :func:`launch`, so the
    same results bit for bit.

    Not for launches that a ``wp.Tape`` must see (a replay is not recorded on the tape), and one thread at a
    time: give each thread (each slice of a batch) its own.
    """

    __slots__ = ("_args", "_cmd", "_dim")

    def __init__(self) -> None:
        self._cmd = None
        self._args: list = []
        self._dim = None

    def __call__(self, kernel: wp.Kernel, dim, inputs=(), outputs=(), device: str | None = None) -> None:
        args = [*inputs, *outputs]
        cmd, old = self._cmd, self._args
        if cmd is None or cmd.kernel is not kernel or dim != self._dim or not _replayable(args, old):
            if any(isinstance(a, np.ndarray) for a in args):  # copied to Warp at each launch: not replayable
                launch(kernel, dim, inputs, outputs, device)
                self._cmd = None
                return
            load_module(kernel.module, device)
            cmd = wp.launch(kernel, dim=dim, inputs=inputs, outputs=outputs, device=device, record_cmd=True)
            self._cmd, self._args, self._dim = cmd, args, dim
            if cmd is None:  # an empty launch (a zero dimension): Warp has nothing to record or run
                return
        else:
            for index, (a, b) in enumerate(zip(args, old, strict=True)):
                if a is not b and not (type(a) is type(b) and a == b):  # a number that changed (or NaN)
                    cmd.set_param_at_index(index, a)
                    old[index] = a
        cmd.launch()


def _replayable(args: list, recorded: list) -> bool:
    """Whether a launch with ``args`` can replay one recorded with ``recorded``: the same objects throughout
    but for numbers, which may have changed."""
    return len(args) == len(recorded) and all(
        a is b or (isinstance(a, _NUMBERS) and isinstance(b, _NUMBERS))
        for a, b in zip(args, recorded, strict=True)
    )


class LaunchRecords(dict):
    """A :class:`LaunchRecord` per key (a call site, and the slice of the batch it launches for), made at the
    first use of the key."""

    def __missing__(self, key) -> LaunchRecord:
        record = self[key] = LaunchRecord()
        return record


if not os.environ.get("WARPCUT_VERBOSE"):
    wp.config.log_level = wp.LOG_WARNING
    if not _cuda_driver_loadable():
        init()

__all__ = [
    "CACHE_ENV",
    "KernelCacheError",
    "LaunchRecord",
    "LaunchRecords",
    "init",
    "launch",
    "load_module",
    "wp",
]
