"""What replaying recorded launches saves (``warpcut.sim._warp.LaunchRecord``): tensioned ``fls-circle`` cuts
(a grasp move and the scissors' updates per step, as a training env steps the simulator), whole episodes,
alternately with the per-update launches replayed (as warpcut runs) and launched afresh through ``wp.launch``
(its arguments packed at every call), in one process. Prints the median milliseconds per step of each, and
checks that both leave the same sheets bit for bit. The figures in docs/performance.md, "The whole step
path" (replayed launches).

Run: python scripts/launch_replay.py [--envs 64,256] [--rounds 8]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", default="64,256", help="comma-separated batch sizes")
    parser.add_argument("--rounds", type=int, default=8, help="episodes each way, alternating")
    args = parser.parse_args()

    import warpcut.sim._warp as warp_module
    from warpcut import SimConfig
    from warpcut.contours import load_contour
    from warpcut.task import CuttingTask

    replay = warp_module.LaunchRecord.__call__

    def afresh(self, kernel, dim, inputs=(), outputs=(), device=None) -> None:
        warp_module.launch(kernel, dim, inputs, outputs, device)

    for num_envs in (int(b) for b in args.envs.split(",")):
        contour = load_contour("fls-circle")
        # A timing: the grasp at the centroid, under the arm, does the same work as a feasible one.
        centroids, contours = [[50.0, 50.0]] * num_envs, [contour] * num_envs
        task = CuttingTask(SimConfig(), contours, pinch_points=centroids, allow_infeasible_pinch=True)
        moves = np.tile(np.float32([[0.5, 0.0, 0.0]]), (num_envs, 1))
        per_step: dict[str, list[float]] = {"replayed": [], "afresh": []}
        sheets = {}
        for r in range(args.rounds):
            for mode in ("replayed", "afresh") if r % 2 else ("afresh", "replayed"):
                warp_module.LaunchRecord.__call__ = replay if mode == "replayed" else afresh
                task.reset()
                start, steps = time.perf_counter(), 0
                while not task.done:
                    task.step(moves)
                    steps += 1
                per_step[mode].append((time.perf_counter() - start) / steps)
                sheets[mode] = task.sim.positions()
        warp_module.LaunchRecord.__call__ = replay
        same = np.array_equal(sheets["replayed"], sheets["afresh"])
        a, b = (1e3 * statistics.median(per_step[m]) for m in ("afresh", "replayed"))
        print(
            f"{num_envs} envs: {a:.3f} ms a step launched afresh, {b:.3f} replayed "
            f"({100 * (b / a - 1):+.1f}%); the same sheets bit for bit: {same}"
        )


if __name__ == "__main__":
    main()
