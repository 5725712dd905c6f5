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
"""

import ctypes
import os
import sys

import warp as wp


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


if not os.environ.get("WARPCUT_VERBOSE"):
    wp.config.log_level = wp.LOG_WARNING
    if not _cuda_driver_loadable():
        _init_quietly()

__all__ = ["wp"]
