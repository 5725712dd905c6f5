"""How much recording an episode with rerun slows a run down (docs/performance.md, "Recording overhead";
the README quotes its whole-command figure).

Times, interleaved with runs without recording so that machine load hits all variants alike, the median
wall time of

* ``plain``: ``CuttingTask(...).run(None)`` (no step callback: recording off);
* ``process``: the same run with ``Recorder(path, envs=1, background="process").step_callback(...)`` as the
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
the CPU time (all threads of the stepping process; for ``process`` plus the recorder process's, which it
reports when it closes a file: what recording costs where no core is free), and the median time spent in
``close()``.

Two phases, each interleaved with its own plain runs: first ``process`` for every batch size, in a
process that has not imported rerun (as in the CLI); then the in-process variants, which import it.

With ``--cli-repeats K`` (default 5; 0 skips it) it also times what a user sees: the whole command
``warpcut simulate --contour fls-circle --policy none --trials 1 --set plots=false`` with and without
``--record`` (default N = 1), K runs of each, interleaved, and prints the median overhead.

    python scripts/recording_overhead.py [--repeats 15] [--batches 1,64] [--phases 1,2] [--cli-repeats 5]
        [--json PATH]

(``--phases 1``: only ``process`` and its plain runs.)
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from warpcut.contours import load_contour
from warpcut.sim.config import SimConfig
from warpcut.task import CuttingTask
from warpcut.viz.recorder import Recorder

PHASES = (("plain", "process"), ("plain", "worker thread", "no thread"))
BACKGROUND = {"process": "process", "worker thread": "thread", "no thread": False}


def time_variants(
    task: CuttingTask, variants: tuple[str, ...], repeats: int, out_dir: Path
) -> dict[str, list[tuple[float, float, float]]]:
    """(wall, CPU, close) times (s) of ``variants`` on ``task``, interleaved."""
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
            task.run(None, on_step=recorder.step_callback("none"))
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

    for variant in variants:  # warm-up: kernels, rerun's first use, the recorder process's start
        run(variant)
    times: dict[str, list[tuple[float, float, float]]] = {v: [] for v in variants}
    for _ in range(repeats):
        for variant in variants:
            times[variant].append(run(variant))
    return times


def summarize(times: dict[str, list[tuple[float, float, float]]]) -> dict:
    wall = {v: [t[0] for t in ts] for v, ts in times.items()}
    cpu = {v: [t[1] for t in ts] for v, ts in times.items()}
    medians = {v: statistics.median(t) for v, t in wall.items()}
    recorded = [v for v in times if v != "plain"]
    return {
        "median_wall_s": medians,
        "median_cpu_s": {v: statistics.median(t) for v, t in cpu.items()},
        "median_close_s": {v: statistics.median(t[2] for t in times[v]) for v in recorded},
        "overhead_pct": {v: 100.0 * (medians[v] / medians["plain"] - 1.0) for v in recorded},
        "paired_overhead_pct": {
            v: 100.0 * statistics.median(r / p - 1.0 for r, p in zip(wall[v], wall["plain"], strict=True))
            for v in recorded
        },
        "cpu_overhead_pct": {
            v: 100.0 * (statistics.median(cpu[v]) / statistics.median(cpu["plain"]) - 1.0) for v in recorded
        },
    }


def time_cli(repeats: int, out_dir: Path) -> dict:
    """Median wall times (s) of ``warpcut simulate`` without and with ``--record``, interleaved."""
    base = [sys.executable, "-m", "warpcut", "simulate", "--contour", "fls-circle", "--policy", "none"]
    base += ["--trials", "1", "--device", "cpu", "--set", "plots=false"]
    times: dict[str, list[float]] = {"plain": [], "record": []}
    for k in range(repeats + 1):  # the first pair warms the kernel cache and the file system
        for variant in times:
            args = base + ["--json", str(out_dir / f"cli{k}-{variant}" / "results.json")]
            if variant == "record":
                args.append("--record")
            start = time.perf_counter()
            subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            if k:
                times[variant].append(time.perf_counter() - start)
    medians = {v: statistics.median(t) for v, t in times.items()}
    return {
        "median_wall_s": medians,
        "overhead_pct": 100.0 * (medians["record"] / medians["plain"] - 1.0),
        "paired_overhead_pct": 100.0
        * statistics.median(r / p - 1.0 for r, p in zip(times["record"], times["plain"], strict=True)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=15, help="timed runs per variant (default 15)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    parser.add_argument(
        "--batches", default="1,64", help="batch sizes to time, env 0 recorded (default 1,64)"
    )
    parser.add_argument(
        "--phases", default="1,2", help="1: process; 2: worker thread and no thread (default 1,2)"
    )
    parser.add_argument(
        "--cli-repeats", type=int, default=5, help="runs of the whole simulate command per variant (0: skip)"
    )
    args = parser.parse_args()
    batches = [int(b) for b in args.batches.split(",")]
    phases = [int(p) - 1 for p in args.phases.split(",") if p.strip().isdigit()]
    if len(phases) != len(args.phases.split(",")) or any(p not in range(len(PHASES)) for p in phases):
        parser.error(f"--phases: comma-separated numbers from 1 to {len(PHASES)} (got {args.phases!r})")
    tasks = {
        b: CuttingTask(SimConfig(), load_contour("fls-circle"), num_envs=b, device=args.device)
        for b in batches
    }
    report: dict = {"load_average_start": os.getloadavg(), "cores": os.cpu_count()}
    with tempfile.TemporaryDirectory(prefix="warpcut-rec-") as tmp:
        for phase in phases:
            variants = PHASES[phase]
            for b in batches:
                if phase == 0:
                    assert "rerun" not in sys.modules, "the process variant must run without rerun loaded"
                times = time_variants(tasks[b], variants, args.repeats, Path(tmp))
                entry = report.setdefault(f"B = {b}", {"steps": tasks[b].num_steps})
                entry["stepping_threads"] = tasks[b].sim.threads
                entry[f"phase {phase + 1}"] = summarize(times)
        if args.cli_repeats:
            report["cli"] = time_cli(args.cli_repeats, Path(tmp))
    report["load_average_end"] = os.getloadavg()
    for b in batches:
        entry = report[f"B = {b}"]
        label = "B = 1" if b == 1 else f"B = {b}, env 0 recorded"
        print(
            f"fls-circle 25 x 25, no tension, {label} ({entry['steps']} steps + reset; medians of "
            f"{args.repeats}; {entry['stepping_threads']} stepping thread(s) on {os.cpu_count()} cores)"
        )
        head = ("wall", 9), ("overhead", 9), ("paired", 8), ("CPU", 9), ("overhead", 9), ("close", 8)
        print(f"  {'':<14}" + "".join(f" {name:>{width}}" for name, width in head))
        for phase in phases:
            variants, r = PHASES[phase], entry[f"phase {phase + 1}"]
            for variant in variants:
                line = f"  {variant:<14} {1e3 * r['median_wall_s'][variant]:6.1f} ms"
                cpu_ms = 1e3 * r["median_cpu_s"][variant]
                if variant == "plain":
                    line += f" {'':>9} {'':>8} {cpu_ms:6.1f} ms"
                else:
                    line += (
                        f" {r['overhead_pct'][variant]:+8.1f}% {r['paired_overhead_pct'][variant]:+7.1f}%"
                        f" {cpu_ms:6.1f} ms {r['cpu_overhead_pct'][variant]:+8.1f}%"
                        f" {1e3 * r['median_close_s'][variant]:5.1f} ms"
                    )
                print(line)
    if "cli" in report:
        cli = report["cli"]
        print(
            f"warpcut simulate (fls-circle, one trial, no plots; medians of {args.cli_repeats}): "
            f"{cli['median_wall_s']['plain']:.2f} s, with --record {cli['median_wall_s']['record']:.2f} s: "
            f"{cli['overhead_pct']:+.1f}% (paired {cli['paired_overhead_pct']:+.1f}%)"
        )
    start, end = report["load_average_start"], report["load_average_end"]
    print(f"load average (1, 5, 15 min): {tuple(round(x, 2) for x in start)} at the start, ", end="")
    print(f"{tuple(round(x, 2) for x in end)} at the end")
    if args.json:
        args.json.write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
