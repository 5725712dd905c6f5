"""Env updates/s of the simulator's CPU backends side by side, by batch size, and the cost of packing the
``simd`` backend's state: the figures in docs/performance.md, "CPU backends".

    python scripts/simd_bench.py --repeats 3                      # simd and colours, B = 1, 8, 64, 1024
    python scripts/simd_bench.py --batches 1024 --threads 2       # two threads (simd steps block slices)

Settings: the default physics (``SimConfig()``: structural + shear springs, 7 Chebyshev-accelerated sweeps,
process noise) and the paper's (``warpcut.bench.PAPER_SWEEPS``: structural springs, 5 plain sweeps,
noise-free). Each backend runs as ``Simulator(config, B, backend=..., threads=...)`` with cutting active,
``--updates`` whole-batch updates per timed repeat (at least 256 env updates); the backends alternate within
each repeat (the machine may be shared, so compare numbers of one run), and the table gives the median over
``--repeats`` (and the range) and the ratio to the first backend. Packing the env-major state into the SIMD
blocks (per reset) and unpacking it (per read-back) are timed last, at the largest batch.
"""

import argparse
import statistics
import time

import numpy as np

from warpcut.bench import PAPER_SWEEPS
from warpcut.sim._warp import wp
from warpcut.sim.config import SimConfig
from warpcut.sim.simulator import Simulator


def stepping(sim: Simulator, updates: int):
    """A function that advances ``sim`` by ``updates`` updates, cutting across the middle of the sheet."""
    sim.reset(np.tile([[50.0, 50.0]], (sim.num_envs, 1)))
    sim.set_tip(np.tile([[50.0, 50.0, -15.0, 1.0]], (sim.num_envs, 1)))

    def run() -> None:
        for _ in range(updates):
            sim.update()

    return run


def bench_setting(label: str, config: SimConfig, args) -> None:
    sweeps = f"{config.sweeps} sweeps" + (
        f" (Chebyshev rho {config.chebyshev_rho:g})" if config.chebyshev_rho else ""
    )
    print(
        f"\n{label}: {config.resolution}x{config.resolution}, {'+'.join(config.springs)} springs, {sweeps}, "
        f"noise {config.noise_std:g} mm; env updates/s, median of {args.repeats}"
    )
    for b in args.batches:
        updates = max(args.updates, 256 // b)  # small batches: enough updates to time
        runners = {
            backend: stepping(Simulator(config, b, backend=backend, threads=args.threads), updates)
            for backend in args.backends
        }
        for run in runners.values():  # warm-up: compile, fault pages in
            run()
        times = {backend: [] for backend in runners}
        for _ in range(args.repeats):
            for backend, run in runners.items():
                t0 = time.perf_counter()
                run()
                times[backend].append(time.perf_counter() - t0)
        first = None
        for backend, ts in times.items():
            rate = b * updates / statistics.median(ts)
            first = first or rate
            low, high = b * updates / max(ts), b * updates / min(ts)
            print(
                f"  B = {b:<5} {backend:8s} {rate:10,.0f}   ({low:,.0f} to {high:,.0f})   x{rate / first:.2f}"
            )


def bench_packing(config: SimConfig, args) -> None:
    sim = Simulator(config, max(args.batches), backend="simd", threads=1)
    stepping(sim, 1)()
    pack, unpack = [], []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        sim._simd.load(sim.x, sim.x_prev, sim.alive, sim.pin, sim.anchor)
        t1 = time.perf_counter()
        sim._simd.store(sim.x, sim.x_prev, sim.alive)
        t2 = time.perf_counter()
        pack.append(t1 - t0)
        unpack.append(t2 - t1)
    print(
        f"\nsimd whole-state pack {statistics.median(pack) * 1e3:.1f} ms, "
        f"unpack {statistics.median(unpack) * 1e3:.1f} ms (B = {sim.num_envs})"
    )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--backends", nargs="+", default=["simd", "colours"])
    parser.add_argument("--batches", type=int, nargs="+", default=[1, 8, 64, 1024])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--updates", type=int, default=2, help="updates per timed repeat")
    parser.add_argument("--threads", type=int, default=1, help="CPU threads per simulator")
    args = parser.parse_args()
    wp.init()
    bench_setting("default physics", SimConfig(), args)
    bench_setting("paper sweeps", PAPER_SWEEPS, args)
    if "simd" in args.backends:
        bench_packing(SimConfig(), args)


if __name__ == "__main__":
    main()
