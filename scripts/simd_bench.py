"""Env updates/s: the fused backend against the SIMD prototype (``warpcut/sim/kernels_simd.py``).

    python scripts/simd_bench.py                      # 25 x 25, B = 1024, median of 5, one thread
    python scripts/simd_bench.py --threads 2          # ...and both backends on two threads as well

Settings: default physics (structural + shear springs, 20 sweeps) and the paper's (structural only, 5
sweeps). Every variant times ``--updates`` whole-batch updates per repeat; the variants alternate within
each repeat (the machine is shared, so compare numbers of one run) and the table gives the median over
``--repeats`` (and the range). The fused backend runs as ``Simulator(..., backend="fused", threads=1)``
does; the SIMD state is packed once before timing, as a plugged-in backend would keep it, and its
per-update control packing (grasp displacement and tip) is timed with it. Packing and unpacking the
whole state (per reset and per read-back) are timed separately.
"""

import argparse
import statistics
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import warp as wp

wp.config.quiet = True


def bench_setting(label: str, config, args) -> None:
    from warpcut import Simulator
    from warpcut.sim.kernels_simd import SimdModel, SimdState

    b = args.batch
    rng = np.random.default_rng(0)
    pinches = np.column_stack([rng.uniform(30, 70, b), rng.uniform(30, 70, b)])
    sims = {1: Simulator(config, b, backend="fused", threads=1)}
    if args.threads > 1:
        sims[args.threads] = Simulator(config, b, backend="fused", threads=args.threads)
    for sim in sims.values():
        sim.reset(pinches)
    sim = sims[1]
    n = sim.grid.num_vertices
    p = sim._wp_params
    model = SimdModel.from_arrays(
        n,
        config.iterations,
        sim._spring_a,
        sim._spring_b,
        sim._spring_rest,
        sim._colour_start,
        int(config.first_order_z),
        config.cut_radius,
        config.cut_height,
    )

    def packed(lanes: int) -> SimdState:
        state = SimdState(b, n, lanes)
        state.load(sim.x, sim.x_prev, sim.alive, sim.pin, sim.anchor)
        state.load_params(p["damping"], p["dt"], p["gravity"], p["noise_std"], p["elasticity"])
        state.load_controls(sim.displacement, sim.tip)
        return state

    def fused(s: Simulator):
        def run():
            for _ in range(args.updates):
                s.update()

        return run

    def simd(state: SimdState, relax: str, threads: int):
        pool = ThreadPoolExecutor(threads) if threads > 1 else None
        parts = [(len(c), int(c[0])) for c in np.array_split(np.arange(state.blocks), threads)]

        def one(part):
            count, offset = part
            state.step(model, 0, block_offset=offset, block_count=count, relax=relax)

        def run():
            for _ in range(args.updates):
                state.load_controls(sim.displacement, sim.tip)  # per update, as a backend would
                if pool is None:
                    one(parts[0])
                else:
                    list(pool.map(one, parts))

        return run

    runners = {}
    for threads, s in sims.items():
        runners[f"fused, {threads} thread(s)"] = fused(s)
        for lanes in args.lanes:
            state = packed(lanes)
            for relax in ("warp", "native"):
                runners[f"simd L={lanes} {relax}, {threads} thread(s)"] = simd(state, relax, threads)
    for run in runners.values():  # warm-up: compile, fault pages in
        run()
    times = {name: [] for name in runners}
    for _ in range(args.repeats):
        for name, run in runners.items():
            t0 = time.perf_counter()
            run()
            times[name].append(time.perf_counter() - t0)
    print(
        f"\n{label}: {args.resolution}x{args.resolution}, B = {b}, {config.iterations} sweeps, "
        f"springs {'+'.join(config.springs)}; env updates/s, median of {args.repeats}"
    )
    base = {}
    for name, ts in times.items():
        threads = name.rsplit(", ", 1)[1]
        rate = b * args.updates / statistics.median(ts)
        base.setdefault(threads, rate)
        low, high = b * args.updates / max(ts), b * args.updates / min(ts)
        print(f"  {name:32s} {rate:9,.0f}   ({low:,.0f} to {high:,.0f})   x{rate / base[threads]:.2f}")
    state = packed(args.lanes[0])
    pack, unpack = [], []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        state.load(sim.x, sim.x_prev, sim.alive, sim.pin, sim.anchor)
        t1 = time.perf_counter()
        state.store(sim.x, sim.x_prev, sim.alive)
        t2 = time.perf_counter()
        pack.append(t1 - t0)
        unpack.append(t2 - t1)
    print(
        f"  whole-state pack {statistics.median(pack) * 1e3:.1f} ms, "
        f"unpack {statistics.median(unpack) * 1e3:.1f} ms (B = {b}, L = {args.lanes[0]})"
    )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--batch", type=int, default=1024)
    parser.add_argument("--resolution", type=int, default=25)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--updates", type=int, default=2, help="updates per timed repeat")
    parser.add_argument("--lanes", type=int, nargs="+", default=[8, 16])
    parser.add_argument("--threads", type=int, default=1, help="also time this many threads (if > 1)")
    args = parser.parse_args()
    wp.init()
    from warpcut import SimConfig

    bench_setting("default physics", SimConfig(resolution=args.resolution), args)
    paper = SimConfig(resolution=args.resolution, springs=("structural",), iterations=5)
    bench_setting("paper sweeps", paper, args)


if __name__ == "__main__":
    main()
