"""How much memory a batch needs, checked before it is allocated.

A batch of ``B`` envs holds, per env, the simulator's state (positions, previous positions, alive and pin
masks, anchors, and the SIMD backend's packed copy: ~110 bytes a vertex), per update of the episode the
scissor trajectory, its targets and the traced cut path (~50 bytes), and, while it is scored, read-backs
and shapely geometry. Measured peak resident memory of whole runs (``CuttingTask`` built, run and scored,
CPU, fls-circle and e-shape, 13 x 13 to 50 x 50 vertices, 1024 to 4096 envs) is about
``130 * vertices + 200 * updates + 8 kB`` per env: 121 kB for the default 25 x 25 sheet and a 160-update
cut, so 10^6 trials would need ~120 GB. :func:`check_batch_memory` refuses a batch whose estimate exceeds
the memory available (``MemAvailable`` of ``/proc/meminfo``, or the cgroup's limit if lower; on a CUDA
device, also the device's free memory for the device arrays) with a ``ValueError`` that names the
parameter to lower, the estimate and the limit. ``WARPCUT_MEMORY_LIMIT_GB`` replaces the host limit (e.g.
to allow swapping, or to keep a shared machine free).
"""

from __future__ import annotations

import contextlib
import contextvars
import math
import os
from collections.abc import Iterator

MEMORY_LIMIT_ENV = "WARPCUT_MEMORY_LIMIT_GB"
"""Environment variable: the host memory (GB, 10^9 bytes) a batch may use, replacing the measured one."""
BYTES_PER_VERTEX = 130
"""Host bytes per vertex of every env (simulator state, packed SIMD copy, settled sheet, read-backs)."""
BYTES_PER_UPDATE = 200
"""Host bytes per update of the episode of every env (trajectory, targets, cut path, scoring)."""
BYTES_PER_ENV = 8192
"""Host bytes per env besides (Python objects, per-env geometry of the score)."""
DEVICE_BYTES_PER_VERTEX = 80
"""Device bytes per vertex of every env on a CUDA device (the ``colours`` backend's arrays)."""
DEVICE_BYTES_PER_UPDATE = 12
"""Device bytes per update of every env on a CUDA device (the traced cut path)."""

USABLE_FRACTION = 0.9
"""Share of the measured available memory a batch may take (the rest stays for the process and others)."""

_GB = 1e9


def batch_bytes(num_envs: int, num_vertices: int, horizon_updates: int = 0) -> int:
    """Estimated peak host memory (bytes) of a batch, built, run and scored (module docstring).

    Args:
        num_envs: Batch size B.
        num_vertices: Vertices per sheet.
        horizon_updates: Updates per episode (0: the simulator alone, no task).
    """
    per_env = BYTES_PER_VERTEX * num_vertices + BYTES_PER_UPDATE * horizon_updates + BYTES_PER_ENV
    return int(num_envs) * per_env


def memory_limit() -> tuple[float, str]:
    """``(bytes, where from)``: the host memory a new batch may take.

    ``WARPCUT_MEMORY_LIMIT_GB`` if set; else :data:`USABLE_FRACTION` of the smaller of ``MemAvailable``
    (``/proc/meminfo``) and the room left under the cgroup's memory limit, or of the free physical pages
    (``os.sysconf``) where there is no ``/proc/meminfo``; ``inf`` where none can be read.
    """
    override = os.environ.get(MEMORY_LIMIT_ENV)
    if override is not None and override.strip():
        try:
            value = float(override)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{MEMORY_LIMIT_ENV}: must be a positive number of GB (got {override!r})")
        return value * _GB, f"{MEMORY_LIMIT_ENV}={override}"
    limits = []
    available = _meminfo_available()
    if available is not None:
        limits.append((available, "available memory in /proc/meminfo"))
    else:
        try:
            limits.append((os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"), "free memory"))
        except (ValueError, OSError, AttributeError):
            pass
    room = _cgroup_room()
    if room is not None:
        limits.append((room, "memory left under this container's limit"))
    if not limits:
        return math.inf, "unknown available memory"
    room, source = min(limits)
    return USABLE_FRACTION * room, f"{USABLE_FRACTION:.0%} of the {source}"


def _meminfo_available() -> float | None:
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def _cgroup_room() -> float | None:
    """Bytes left under a cgroup v2 memory limit, or None where there is none."""
    try:
        with open("/sys/fs/cgroup/memory.max") as f:
            limit = f.read().strip()
        if limit == "max":
            return None
        with open("/sys/fs/cgroup/memory.current") as f:
            current = f.read().strip()
        return max(0.0, float(limit) - float(current))
    except (OSError, ValueError):
        return None


_NAMED: contextvars.ContextVar[tuple[str, str | None, int] | None] = contextvars.ContextVar(
    "batch", default=None
)
"""What the batches made inside :func:`batch_named` are, to the user, how to make them smaller, and how many
envs make one unit of the name."""


@contextlib.contextmanager
def batch_named(
    name: str, fix: str | None = None, *, default: bool = False, envs_per_unit: int = 1
) -> Iterator[None]:
    """Inside the block, a batch too big for memory is named ``name`` (what it is to the user, e.g. "the
    planner's batch (pinch candidates x segment orders)", or the setting that sizes it, e.g.
    "train.num_envs") instead of ``num_envs``, a count the user never gave: for the batches a pipeline makes
    itself. ``fix`` is what the user can change (``{fits}`` in it: the envs that fit); None: "use at most
    N". ``envs_per_unit``: envs per unit of ``name`` (:func:`check_batch_memory`). With ``default`` the name
    holds only where no caller named the batch already (a library's own name, which a command that knows its
    own settings replaces)."""
    if default and _NAMED.get() is not None:
        yield
        return
    token = _NAMED.set((name, fix, envs_per_unit))
    try:
        yield
    finally:
        _NAMED.reset(token)


def check_batch_memory(
    num_envs: int,
    num_vertices: int,
    horizon_updates: int = 0,
    device: str | None = None,
    name: str = "num_envs",
    envs_per_unit: int = 1,
    fix: str | None = None,
) -> None:
    """Refuse a batch that would not fit in memory, before anything is allocated.

    Args:
        num_envs: Batch size B.
        num_vertices: Vertices per sheet.
        horizon_updates: Updates per episode (an estimate is fine; 0: the simulator alone).
        device: Warp device; on a CUDA device its free memory also bounds the device arrays.
        name: The parameter the user sets, named in the error (``num_envs``, ``trials``...).
        envs_per_unit: Envs per unit of ``name`` (e.g. contours per trial): the error's largest value of
            ``name`` that fits is ``B / envs_per_unit`` scaled down.
        fix: What the user can change, where the batch size is not theirs to give (e.g. a search's
            candidates): said after how many envs would fit, instead of "use at most N".

    Raises:
        ValueError: The estimate exceeds the limit (:func:`memory_limit`); the message names ``name``,
            the estimate, the limit and the largest value that fits.
    """
    if name == "num_envs" and fix is None and _NAMED.get() is not None:
        name, fix, envs_per_unit = _NAMED.get()
    needed = batch_bytes(num_envs, num_vertices, horizon_updates)
    limit, source = memory_limit()
    shape = (num_envs, envs_per_unit, num_vertices, horizon_updates)
    if needed > limit:
        _refuse(
            name, shape, needed, limit, source, f"or set {MEMORY_LIMIT_ENV} to the GB a batch may use", fix
        )
    if device is not None and str(device).startswith("cuda"):
        from warpcut.sim._warp import wp

        free = getattr(wp.get_device(device), "free_memory", None)
        per_env = DEVICE_BYTES_PER_VERTEX * num_vertices + DEVICE_BYTES_PER_UPDATE * horizon_updates
        if free is not None and num_envs * per_env > free:
            _refuse(name, shape, num_envs * per_env, free, f"the free memory of {device}", "", fix)


def _refuse(
    name: str,
    shape: tuple[int, int, int, int],
    needed: float,
    limit: float,
    source: str,
    hint: str,
    fix: str | None = None,
) -> None:
    num_envs, envs_per_unit, num_vertices, horizon_updates = shape
    per_env = needed / max(num_envs, 1)
    fits = int(limit // (per_env * envs_per_unit))
    what = f"{num_envs} envs"
    if envs_per_unit != 1:
        what = f"{num_envs // envs_per_unit} x {envs_per_unit} = {what}"
    tail = f" ({hint})" if hint else ""
    if fits < 1:
        fix = None  # not a matter of batch size: said below
    if fix is not None and "{fits}" in fix:
        advice = fix.replace("{fits}", str(fits)) + tail
    elif fix is not None:
        advice = f"at most {fits} envs fit; {fix}" + tail
    elif fits < 1:  # not a matter of batch size: each env is too big
        advice = (
            f"even one is too big: its sheet has {num_vertices} vertices (resolution) and its episode "
            f"{horizon_updates} updates (the contour's length over trajectory_spacing_mm)"
            + (f"; {hint}" if hint else "")
        )
    else:
        advice = f"use at most {fits}" + tail
    raise ValueError(
        f"{name}: {what} would need about {needed / _GB:.3g} GB ({per_env / 1e3:.0f} kB per env), more "
        f"than the {limit / _GB:.3g} GB allowed ({source}); {advice}"
    )
