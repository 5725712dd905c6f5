"""How many CPU cores this process may use (the simulator's stepping threads and the gradient passes
default to it): :data:`CORES_VARIABLE` where set, else the cores the OS lets the process run on."""

from __future__ import annotations

import os

CORES_VARIABLE = "WARPCUT_CPU_THREADS"
"""The environment variable that caps warpcut's CPU threads in a process: a Ray task sets it to the CPUs it
declared (``agents.cluster``), and a user may set it by hand (e.g. beside other jobs on a shared node)."""


def cpu_cores() -> int:
    """:data:`CORES_VARIABLE` where set (a positive integer), else the cores this process may run on
    (``os.sched_getaffinity``: what ``taskset``, a cgroup's cpuset or a SLURM allocation leave it), else
    ``os.cpu_count()``."""
    value = os.environ.get(CORES_VARIABLE, "").strip()
    if value:
        if not value.isdigit() or int(value) < 1:
            raise ValueError(
                f"{CORES_VARIABLE}: must be a positive integer, the CPU threads warpcut may use "
                f"(got {value!r}); set it to e.g. 1, or unset it to use every core"
            )
        return int(value)
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return os.cpu_count() or 1
