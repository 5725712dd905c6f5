"""How much recording an episode with rerun slows a run down (docs/performance.md, "Recording overhead").

Times, interleaved in one process so that machine load hits all variants alike, the median wall time of

* ``plain``: ``CuttingTask(...).run(None)`` (no step callback: recording off);
* ``worker thread``: the same run with ``Recorder(path, envs=1, background=True).on_step(...)`` as the
  callback, the recorder's creation and ``close()`` (the finished ``.rrd`` file) included: the stepping
  loop copies the recorded env's state, a worker thread scores it and sends it to rerun;
* ``no thread``: the same with ``background=False``: all the recording work in the stepping thread
  (``Recorder``'s default, ``background=None``, picks the worker when the machine has more cores than
  the simulator's stepping threads),

on (a) one 25 x 25 ``fls-circle`` sheet without tension, and (b) a batch of 64 such sheets with env 0
recorded (N = 1), and prints each recording's overhead over ``plain`` in %.

    python scripts/recording_overhead.py [--repeats 15] [--json PATH]
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

VARIANTS = ("plain", "worker thread", "no thread")


def time_case(num_envs: int, repeats: int, out_dir: Path, device: str) -> dict[str, list[float]]:
    """Wall times (s) of every variant on a batch of ``num_envs`` fls-circle sheets, interleaved."""
    task = CuttingTask(SimConfig(), load_contour("fls-circle"), num_envs=num_envs, device=device)
    counter = iter(range(10**9))

    def run(variant: str) -> float:
        start = time.perf_counter()
        if variant == "plain":
            task.run(None)
        else:
            path = out_dir / f"r{next(counter)}.rrd"
            with Recorder(path, envs=1, background=variant == "worker thread") as recorder:
                task.run(None, on_step=recorder.on_step("none"))
        elapsed = time.perf_counter() - start
        if variant != "plain":
            path.unlink()
        return elapsed

    for variant in VARIANTS:  # warm-up: kernels, rerun's and the blueprint's first use
        run(variant)
    times: dict[str, list[float]] = {v: [] for v in VARIANTS}
    for _ in range(repeats):
        for variant in VARIANTS:
            times[variant].append(run(variant))
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=15, help="timed runs per variant (default 15)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args()
    report = {}
    with tempfile.TemporaryDirectory(prefix="warpcut-rec-") as tmp:
        for label, num_envs in (("B = 1", 1), ("B = 64, env 0 recorded", 64)):
            times = time_case(num_envs, args.repeats, Path(tmp), args.device)
            medians = {v: statistics.median(t) for v, t in times.items()}
            task = CuttingTask(SimConfig(), load_contour("fls-circle"), num_envs=num_envs, device=args.device)
            steps, threads = task.num_steps, task.sim.threads
            report[label] = {
                "num_envs": num_envs,
                "steps": steps,
                "stepping_threads": threads,
                "cores": os.cpu_count(),
                "default": "worker thread" if (os.cpu_count() or 1) > threads else "no thread",
                "median_s": medians,
                "overhead_pct": {
                    v: 100.0 * (medians[v] / medians["plain"] - 1.0) for v in VARIANTS if v != "plain"
                },
            }
            print(
                f"fls-circle 25 x 25, no tension, {label} ({steps} steps + reset; medians of {args.repeats}; "
                f"{threads} stepping thread(s) on {os.cpu_count()} cores: default {report[label]['default']})"
            )
            for variant in VARIANTS:
                extra = "" if variant == "plain" else f"  {report[label]['overhead_pct'][variant]:+6.1f}%"
                print(f"  {variant:<22} {1e3 * medians[variant]:8.1f} ms{extra}")
    if args.json:
        args.json.write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
