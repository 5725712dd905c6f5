"""How much recording an episode with rerun slows a run down (docs/performance.md, "Recording overhead").

Times, interleaved in one process so that machine load hits all variants alike, the median wall time of

* ``plain``: ``CuttingTask(...).run(None)`` (no step callback: recording off);
* ``process``: the same run with ``Recorder(path, envs=1, background="process").on_step(...)`` as the
  callback, the recorder's creation and ``close()`` (the finished ``.rrd`` file, written and renamed by
  the recorder process) included: the stepping loop copies the recorded env's state into a pipe, the
  recorder process scores it, sends it to rerun and writes the file (``Recorder``'s default on a machine
  with more than one core). The process is started by the warm-up run and reused by the timed ones, as
  later recorders of one Python process reuse it;
* ``worker thread``: the same with ``background="thread"``: a worker thread of the stepping process scores
  the frames and sends them to rerun;
* ``no thread``: the same with ``background=False``: all the recording work in the stepping thread,

on (a) one 25 x 25 ``fls-circle`` sheet without tension, and (b) a batch of 64 such sheets with env 0
recorded (N = 1), and prints each recording's overhead over ``plain`` in %: of the median wall times, the
median of the overheads of neighbouring runs (paired, less sensitive to load that comes and goes), and of
the process CPU time (all threads of the stepping process; for ``process`` the recorder process's CPU
time, from ``/proc``, is added: what recording costs where no core is free), and the median time spent
in ``close()``.

    python scripts/recording_overhead.py [--repeats 15] [--batches 1,64] [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

from warpcut.config import SimConfig
from warpcut.contours import load_contour
from warpcut.recording import Recorder
from warpcut.task import CuttingTask

VARIANTS = ("plain", "process", "worker thread", "no thread")
BACKGROUND = {"process": "process", "worker thread": "thread", "no thread": False}


def time_case(num_envs: int, repeats: int, out_dir: Path, device: str) -> dict[str, list[tuple[float, ...]]]:
    """(wall, CPU, close) times (s) of every variant on a batch of ``num_envs`` fls-circle sheets,
    interleaved."""
    task = CuttingTask(SimConfig(), load_contour("fls-circle"), num_envs=num_envs, device=device)
    counter = iter(range(10**9))
    process_cpu = {}  # the recorder process's CPU time at its last close, by pid

    def run(variant: str) -> tuple[float, float, float]:
        start, cpu = time.perf_counter(), time.process_time()
        if variant == "plain":
            task.run(None)
            return time.perf_counter() - start, time.process_time() - cpu, 0.0
        path = out_dir / f"r{next(counter)}.rrd"
        recorder = Recorder(path, envs=1, background=BACKGROUND[variant])
        try:
            task.run(None, on_step=recorder.on_step("none"))
        finally:
            closing = time.perf_counter()
            recorder.close()
        end = time.perf_counter()
        cpu = time.process_time() - cpu
        if variant == "process":
            child = recorder._sink.child.process.pid
            used = recorder._sink.process_cpu_s
            cpu += used - process_cpu.get(child, used)
            process_cpu[child] = used
        path.unlink()
        return end - start, cpu, end - closing

    for variant in VARIANTS:  # warm-up: kernels, rerun's first use, the recorder process's start
        run(variant)
    times: dict[str, list[tuple[float, ...]]] = {v: [] for v in VARIANTS}
    for _ in range(repeats):
        for variant in VARIANTS:
            times[variant].append(run(variant))
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=15, help="timed runs per variant (default 15)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    parser.add_argument(
        "--batches", default="1,64", help="batch sizes to time, env 0 recorded (default 1,64)"
    )
    args = parser.parse_args()
    report = {"load_average": os.getloadavg()}
    with tempfile.TemporaryDirectory(prefix="warpcut-rec-") as tmp:
        for num_envs in (int(b) for b in args.batches.split(",")):
            label = "B = 1" if num_envs == 1 else f"B = {num_envs}, env 0 recorded"
            times = time_case(num_envs, args.repeats, Path(tmp), args.device)
            wall = {v: [t[0] for t in ts] for v, ts in times.items()}
            cpu = {v: [t[1] for t in ts] for v, ts in times.items()}
            medians = {v: statistics.median(t) for v, t in wall.items()}
            task = CuttingTask(SimConfig(), load_contour("fls-circle"), num_envs=num_envs, device=args.device)
            steps, threads = task.num_steps, task.sim.threads
            recorded = [v for v in VARIANTS if v != "plain"]
            report[label] = {
                "num_envs": num_envs,
                "steps": steps,
                "stepping_threads": threads,
                "cores": os.cpu_count(),
                "median_wall_s": medians,
                "median_cpu_s": {v: statistics.median(t) for v, t in cpu.items()},
                "median_close_s": {v: statistics.median(t[2] for t in times[v]) for v in recorded},
                "overhead_pct": {v: 100.0 * (medians[v] / medians["plain"] - 1.0) for v in recorded},
                "paired_overhead_pct": {
                    v: 100.0
                    * statistics.median(r / p - 1.0 for r, p in zip(wall[v], wall["plain"], strict=True))
                    for v in recorded
                },
                "cpu_overhead_pct": {
                    v: 100.0 * (statistics.median(cpu[v]) / statistics.median(cpu["plain"]) - 1.0)
                    for v in recorded
                },
            }
            print(
                f"fls-circle 25 x 25, no tension, {label} ({steps} steps + reset; medians of {args.repeats}; "
                f"{threads} stepping thread(s) on {os.cpu_count()} cores)"
            )
            head = ("wall", 9), ("overhead", 9), ("paired", 8), ("CPU", 9), ("overhead", 9), ("close", 8)
            print(f"  {'':<14}" + "".join(f" {name:>{width}}" for name, width in head))
            for variant in VARIANTS:
                line = f"  {variant:<14} {1e3 * medians[variant]:6.1f} ms"
                cpu_ms = 1e3 * report[label]["median_cpu_s"][variant]
                if variant == "plain":
                    line += f" {'':>9} {'':>8} {cpu_ms:6.1f} ms"
                else:
                    r = report[label]
                    line += (
                        f" {r['overhead_pct'][variant]:+8.1f}% {r['paired_overhead_pct'][variant]:+7.1f}%"
                        f" {cpu_ms:6.1f} ms {r['cpu_overhead_pct'][variant]:+8.1f}%"
                        f" {1e3 * r['median_close_s'][variant]:5.1f} ms"
                    )
                print(line)
    load = report["load_average"], os.getloadavg()
    print(f"load average (1, 5, 15 min) at the start {load[0]}, at the end {load[1]}")
    report["load_average_end"] = load[1]
    if args.json:
        args.json.write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
