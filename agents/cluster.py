"""Where a pipeline's independent units of work run: in this process (:class:`Serial`, the default), or
fanned out over a Ray cluster (:class:`RayCluster`, ``--ray ADDRESS``). A unit is one contour's plan, one
training run and its rollouts, one robustness batch; the driver gathers the results in the units' order,
so a run directory and its ``results.json`` are the same, bit for bit, either way (but for ``ran_on``, where
each unit ran, and the seconds it took).

Ray is imported only when ``--ray`` is given (an optional extra: ``pip install -e ".[ray]"``).

- ``local`` starts a Ray instance on this machine for the command (``local:N``: N CPUs of it) and stops it
  afterwards; ``auto`` or ``HOST:PORT`` joins a running cluster (``ray start --head``; docs/cluster.md).
- Each unit declares :data:`UNIT_CPUS` CPU (and one GPU where the device is CUDA), and warpcut's simulator
  steps on that many threads, so workers do not oversubscribe a node. torch runs on as many threads as in
  the driver: a policy's forward pass (and PPO's update) can differ in the last bit with torch's thread
  count, so this keeps a unit's results those of a serial run on the driver's machine; the simulator's
  results do not depend on its threads.
- Warp's kernel cache is filled once before the units start: by this process for a local instance (its
  workers use this process's cache), else by one task per node, so N workers never compile from cold.
- A unit writes its files (a training run) into a folder of its own on the worker, and the driver writes
  them into the run directory, which it holds locked as a serial run does: no worker needs the driver's
  filesystem. A resumed unit gets the run directory's files back first (its checkpoints).
- A worker that dies mid-unit has its unit retried (:data:`RETRIES` times); Ctrl-C or SIGTERM cancels what
  is still running (the units that finished are in the run directory, and ``--resume`` runs the rest).
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, NamedTuple

from warpcut.cores import CORES_VARIABLE

UNIT_CPUS = 1
"""CPUs each unit declares (and the threads its simulator steps on): one unit a core keeps every core busy
while the units outnumber the cores (docs/cluster.md has the scaling measured)."""

RETRIES = 3
"""How often a unit whose worker died is run again before the command fails."""

CONNECT_TIMEOUT_S = 5.0
"""How long joining a cluster at ``HOST:PORT`` waits for its head to answer."""

WAIT_S = 0.5
"""How long the driver waits for a unit before it looks at its signals (Ctrl-C, SIGTERM) again."""

RAY_AUTH_LOGGER = "ray._private.authentication.authentication_token_setup"
"""The logger of Ray's notice that a new local instance uses token authentication, its default: a
``--ray local`` command keeps the default and does not print the notice (docs/cluster.md)."""

RUN_KEYS = ("ran_on", "unit_seconds")
"""A result row's fields that say where and how long its units ran: the rest of a row is the same in every
run of the job at its seed, here or on a cluster."""


def same_results(row: dict) -> dict:
    """``row`` without :data:`RUN_KEYS`: what two runs of a job at one seed give alike."""
    return {key: value for key, value in row.items() if key not in RUN_KEYS}


LOCAL = "local"


class Done(NamedTuple):
    """A unit's result: its value, where it ran (``HOST:PID``) and how long it took there (s)."""

    value: Any
    ran_on: str
    seconds: float


def ran_here() -> str:
    """Where this process runs: ``HOST:PID``, what a row's ``ran_on`` records."""
    return f"{socket.gethostname()}:{os.getpid()}"


def parse_address(value: str | None) -> tuple[str | None, int | None]:
    """``--ray``'s value as ``(address, cpus)``: ``(None, None)`` for no Ray, ``("local", N or None)``,
    ``("auto", None)`` or ``("HOST:PORT", None)``; a ``ValueError`` names a malformed one."""
    if value is None:
        return None, None
    value = str(value).strip()
    fix = "give local, local:N (N CPUs), auto (a cluster 'ray start' runs here) or HOST:PORT of a head node"
    if value == LOCAL:
        return LOCAL, None
    if value.startswith(LOCAL + ":"):
        count = value.split(":", 1)[1]
        if not count.isdigit() or int(count) < 1:
            raise ValueError(f"--ray: {value!r}: local:N takes a positive number of CPUs; {fix}")
        return LOCAL, int(count)
    if value == "auto":
        return value, None
    host, _, port = value.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"--ray: {value!r} is not an address; {fix}")
    if ":" in host and not (host.startswith("[") and host.endswith("]")):
        raise ValueError(f"--ray: {value!r}: an IPv6 address goes in brackets, [HOST]:PORT (e.g. [::1]:6379)")
    return value, None


class Serial:
    """Run the units one after another in this process (no ``--ray``): what every pipeline did before."""

    address = None
    workers = 1

    def map(
        self,
        fn: Callable,
        items: Sequence[Any],
        *,
        dirs: Sequence[Path | None] | None = None,
        done: Callable[[int, Done], None] = lambda k, result: None,
        gpu: bool = False,
        start: Callable[[int], None] = lambda k: None,
    ) -> list[Done]:
        """Each item's :class:`Done`, ``fn(item)`` (``fn(item, dirs[k])`` where ``dirs`` are given: the
        folder unit k works in, or None), in the items' order, calling ``start(k)`` as each starts and
        ``done(k, result)`` as each finishes."""
        results = []
        for k, item in enumerate(items):
            start(k)
            started = time.perf_counter()
            value = fn(item) if dirs is None else fn(item, None if dirs[k] is None else Path(dirs[k]))
            results.append(Done(value, ran_here(), time.perf_counter() - started))
            done(k, results[-1])
        return results


class RayCluster:
    """Run the units as Ray tasks (module docstring); made by :func:`executor`."""

    def __init__(self, address: str, cpus: int | None, device: str | None, log: Callable[[str], None]):
        import ray

        self.ray = ray
        self.address = address
        self.device = device
        env = {CORES_VARIABLE: str(UNIT_CPUS)}
        local = address == LOCAL
        if local:  # its workers share this process's kernel cache, filled before any unit starts
            env["WARP_CACHE_PATH"] = _warm_cache(device)
        else:
            _check_reachable(address)
        settings = {"runtime_env": {"env_vars": env}, "log_to_driver": True, "configure_logging": False}
        handlers = _signal_handlers()
        if local:  # Ray's default for a new local instance (a token) is said once in the docs, not each run
            import logging

            logging.getLogger(RAY_AUTH_LOGGER).setLevel(logging.ERROR)
        try:
            if local:
                ray.init(num_cpus=cpus, include_dashboard=False, **settings)
            else:
                ray.init(address=address, **settings)
        except ConnectionError as exc:
            raise ValueError(f"--ray {address}: {_first_line(exc)}; {_START_HINT}") from None
        except (RuntimeError, ray.exceptions.RayError) as exc:  # a head that failed to start, a refused token
            raise ValueError(
                f"--ray {address}: Ray did not start ({type(exc).__name__}: {_first_line(exc)}); see Ray's "
                "logs under /tmp/ray, or run without --ray"
            ) from None
        finally:  # Ray's core puts its own in (SIGTERM: a stack dump, then abort): stop as the command does
            for signum, handler in handlers.items():
                signal.signal(signum, handler)
        try:
            self.workers = max(1, int(ray.cluster_resources().get("CPU", 1)) // UNIT_CPUS)
            nodes = [n for n in ray.nodes() if n.get("Alive")]
            log(f"  ray: {len(nodes)} node(s), {self.workers} worker(s) at {address}")
            if not local:
                self._warm_nodes(nodes)
        except BaseException:
            ray.shutdown()
            raise

    def _warm_nodes(self, nodes: list[dict]) -> None:
        """Fill each node's kernel cache with one task there, before the units start (and check that each
        node runs this warpcut)."""
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

        import warpcut

        warm = self.ray.remote(_warm_node)
        refs = [
            warm.options(
                num_cpus=0, scheduling_strategy=NodeAffinitySchedulingStrategy(n["NodeID"], soft=False)
            ).remote(self.device)
            for n in nodes
        ]
        for node, version in zip(nodes, self.ray.get(refs), strict=True):
            if version != warpcut.__version__:
                raise ValueError(
                    f"--ray: node {node.get('NodeManagerAddress')} runs warpcut {version}, this one "
                    f"{warpcut.__version__}; install the same warpcut on every node"
                )

    def map(
        self,
        fn: Callable,
        items: Sequence[Any],
        *,
        dirs: Sequence[Path | None] | None = None,
        done: Callable[[int, Done], None] = lambda k, result: None,
        gpu: bool = False,
        start: Callable[[int], None] = lambda k: None,
    ) -> list[Done]:
        """:meth:`Serial.map`'s results, the units run as Ray tasks (``start`` is not called: they start
        on their workers); where ``dirs`` are given, each unit works in a folder of its own on its worker,
        given the files ``dirs[k]`` holds now (None: no folder), and the files it wrote there are written
        into ``dirs[k]`` here as it finishes, before ``done``."""
        from warpcut.io import write_atomic

        ray = self.ray
        task = ray.remote(_run_unit).options(
            num_cpus=UNIT_CPUS, num_gpus=1 if gpu else 0, max_retries=RETRIES, retry_exceptions=False
        )
        threads = torch_threads()
        refs = [
            task.remote(
                fn,
                item,
                dirs is not None,
                None if dirs is None or dirs[k] is None else _files(dirs[k]),
                threads,
            )
            for k, item in enumerate(items)
        ]
        order = {ref: k for k, ref in enumerate(refs)}
        results: list = [None] * len(refs)
        pending = list(refs)
        try:
            while pending:
                # a timeout lets Ctrl-C and SIGTERM through while the units run
                ready, pending = ray.wait(pending, num_returns=1, timeout=WAIT_S)
                if not ready:
                    continue
                k = order[ready[0]]
                value, files, where, seconds = self._get(ready[0])
                for name, data in (files or {}).items():
                    write_atomic(Path(dirs[k]) / name, data)
                results[k] = Done(value, where, seconds)
                done(k, results[k])
        except BaseException:
            for ref in pending:  # Ctrl-C, SIGTERM or a failed unit: stop the rest
                ray.cancel(ref, force=True)
            raise
        return results

    def _get(self, ref) -> Any:
        """A task's result; its own exception where it raised one (a ``ValueError`` reads as in a serial
        run), a one-line ``ValueError`` where its worker died more than :data:`RETRIES` times."""
        from ray.exceptions import RayTaskError, WorkerCrashedError

        try:
            return self.ray.get(ref)
        except RayTaskError as exc:
            cause = getattr(exc, "cause", None)
            if isinstance(cause, BaseException):
                raise cause from None
            raise
        except WorkerCrashedError as exc:
            raise ValueError(
                f"--ray: a unit's worker died {RETRIES + 1} times ({_first_line(exc)}); see the worker logs "
                "(ray logs, or /tmp/ray/session_latest/logs) for why, e.g. memory"
            ) from None

    def close(self) -> None:
        self.ray.shutdown()


_START_HINT = (
    "start one with 'ray start --head' (docs/cluster.md), or use --ray local for a cluster on this machine"
)


def _signal_handlers() -> dict:
    """This process's handlers of Ctrl-C, SIGTERM and SIGHUP (the main thread's only: none elsewhere)."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {signum: signal.getsignal(signum) for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}


def _first_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text[:300] if text else type(exc).__name__


def _check_reachable(address: str) -> None:
    """A ``ValueError`` naming ``address`` where nothing answers there (Ray itself would wait a minute)."""
    if address == "auto":
        return  # Ray finds the cluster this machine runs, or says it found none at once
    host, _, port = address.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host  # an IPv6 address
    try:
        with socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S):
            pass
    except OSError as exc:
        why = exc.strerror or type(exc).__name__
        raise ValueError(f"--ray {address}: no Ray cluster answers there ({why}); {_START_HINT}") from None


def _kernel_modules() -> list:
    from warpcut.sim import kernels, kernels_simd, kernels_simd_reads
    from warpcut.sim._warp import wp

    return [wp.get_module(m.__name__) for m in (kernels, kernels_simd, kernels_simd_reads)]


def _warm_cache(device: str | None) -> str:
    """Load (compiling where the cache lacks them) warpcut's kernel modules for ``device`` here; returns
    Warp's kernel cache folder."""
    from warpcut.sim._warp import init, load_module, wp
    from warpcut.sim.devices import resolve_device

    init()
    device = resolve_device(device)
    for module in _kernel_modules():
        load_module(module, device)
    return str(wp.config.kernel_cache_dir)


def _warm_node(device: str | None) -> str:
    """A node's warm-up task: its kernel cache filled; returns its warpcut's version."""
    import warpcut

    _warm_cache(device)
    return warpcut.__version__


def _files(folder: Path) -> dict[str, bytes]:
    """The files under ``folder`` (relative name: bytes), none where it does not exist."""
    if not folder.is_dir():
        return {}
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def torch_threads() -> int:
    """torch's threads in this process (the driver's: what a unit runs torch on)."""
    import torch

    return torch.get_num_threads()


def _run_unit(
    fn: Callable, item: Any, in_folder: bool, given: dict[str, bytes] | None, threads: int
) -> tuple[Any, dict | None, str, float]:
    """A Ray task: ``fn(item)``, or (``in_folder``) ``fn(item, folder)`` in a fresh folder holding the
    ``given`` files (None: ``fn(item, None)``), torch on ``threads`` threads (the driver's); returns the
    value, the folder's files that are new or changed, where it ran and its seconds."""
    import torch

    from warpcut.io import RUN_MARKER, claim_run_dir, write_atomic

    torch.set_num_threads(threads)
    started = time.perf_counter()
    if not in_folder or given is None:
        value = fn(item) if not in_folder else fn(item, None)
        return value, None, ran_here(), time.perf_counter() - started
    with (
        tempfile.TemporaryDirectory(prefix="warpcut-unit-") as tmp,
        claim_run_dir(Path(tmp) / "unit", command=None) as folder,  # held as the driver holds its own
    ):
        for name, data in given.items():
            write_atomic(folder / name, data)
        value = fn(item, folder)
        # the folder's own run marker (its claim there) stays: the run directory's claim lists the files
        files = {
            name: data
            for name, data in _files(folder).items()
            if given.get(name) != data and Path(name).name != RUN_MARKER
        }
    return value, files, ran_here(), time.perf_counter() - started


@contextlib.contextmanager
def executor(
    ray: str | None, device: str | None = None, log: Callable[[str], None] = lambda _: None
) -> Iterator[Serial | RayCluster]:
    """The executor of ``--ray``'s value (None: :class:`Serial`, and Ray is not imported); a local instance
    is stopped, a joined cluster left, when the block ends."""
    address, cpus = parse_address(ray)
    if address is None:
        yield Serial()
        return
    try:
        import ray as _  # noqa: F401
    except ImportError:
        raise ValueError(
            "--ray: Ray is not installed; install it (pip install -e '.[ray]', or pip install 'ray>=2.40')"
        ) from None
    started = time.perf_counter()
    cluster = RayCluster(address, cpus, device, log)
    log(f"  ray: ready in {time.perf_counter() - started:.1f} s")
    try:
        yield cluster
    finally:
        cluster.close()


Executor = Serial | RayCluster
"""Where a pipeline's units run."""
