"""Memory and time of a differentiable rollout (warpcut.gradients): fls-circle, its default length, at the
default pinch point, for each batch size: the forward pass (with checkpoints), the backward pass (median of
``--repeats``), the process's peak resident memory and the estimate of ``rollout_memory``. The figures in
docs/architecture.md, "Differentiable rollouts".

Run: python scripts/gradient_memory.py [--batch-sizes 8,64] [--repeats 3] [--out FILE]
Each batch size runs in a fresh process, so each peak is its own. --out also writes the lines to FILE.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path


def measure(batch: int, repeats: int) -> dict:
    import numpy as np

    from warpcut import CuttingTask, SimConfig, load_contour
    from warpcut.gradients import DifferentiableRollout, rollout_memory
    from warpcut.planning import default_pinch

    config = SimConfig()
    contour = load_contour("fls-circle")
    pinch = default_pinch(contour, config)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    task = CuttingTask(config, [contour] * batch, pinch_points=[pinch] * batch)
    rollout = DifferentiableRollout(task)
    plan = np.zeros((batch, task.num_steps, 3), np.float32)
    start = time.perf_counter()
    forward = rollout.forward(plan)
    forward_s = time.perf_counter() - start
    backward = []
    for _ in range(repeats):
        start = time.perf_counter()
        rollout.backward(forward)
        backward.append(time.perf_counter() - start)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    estimate = rollout_memory(
        batch, task.grid.num_vertices, task.num_steps, config.updates_per_step, config.sweeps
    )
    return {
        "batch": batch,
        "steps": task.num_steps,
        "updates": task.horizon_updates,
        "forward_s": forward_s,
        "backward_s": statistics.median(backward),
        "backward_first_s": backward[0],
        "peak_rss_mb": peak / 1024,
        "rss_growth_mb": (peak - before) / 1024,
        "estimate_mb": {k: v / 2**20 for k, v in estimate.items()},
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--batch-sizes", default="8,64", help="comma-separated, one process each")
    parser.add_argument("--repeats", type=int, default=3, help="backward passes timed, the median kept")
    parser.add_argument("--out", type=Path, default=None, help="also write the lines to this file")
    parser.add_argument("--one", type=int, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one is not None:
        print(json.dumps(measure(args.one, args.repeats)))
        return
    lines = []
    for batch in (int(b) for b in args.batch_sizes.split(",")):
        command = [sys.executable, __file__, "--one", str(batch), "--repeats", str(args.repeats)]
        row = json.loads(subprocess.run(command, check=True, capture_output=True, text=True).stdout)
        est = row["estimate_mb"]
        lines.append(
            f"B={row['batch']:<4} {row['steps']} steps ({row['updates']} updates): "
            f"forward {row['forward_s']:.2f} s, backward {row['backward_s']:.2f} s "
            f"(median of {args.repeats}; "
            f"first {row['backward_first_s']:.2f} s), peak RSS {row['peak_rss_mb']:.0f} MB "
            f"(+{row['rss_growth_mb']:.0f} MB for the rollout); estimate: checkpoints "
            f"{est['checkpoints']:.0f} MB + one step's tape {est['tape']:.0f} MB"
        )
        print(lines[-1], flush=True)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
