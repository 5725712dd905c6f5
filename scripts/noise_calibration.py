"""How the process noise spreads the trials (docs/physics.md, "Process noise"): for each noise level, the
no-tension path error of every built-in contour and fixed tension at its feasible centroid, single-loop cuts,
all contours and trials in one batch per method. Prints the mean no-tension error, the median spread between
trials, fixed tension's mean improvement, the median 95% CI of that improvement and how many contours have a
CI of (numerically) zero, i.e. trials that do not differ. About 5 minutes on a CPU with the defaults.

Run: python scripts/noise_calibration.py [--device cpu] [--sigmas 0,0.01,0.02,0.03,0.05] [--trials 10]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from warpcut import SimConfig
from warpcut.contours import builtin_contours
from warpcut.planning import default_pinch
from warpcut.stats import ci95
from warpcut.task import CuttingTask

SIGMAS = "0,0.01,0.02,0.03,0.05"
"""The noise levels (mm) of the calibration."""
ZERO_CI = 1e-6
"""A CI (percentage points) below this counts as zero: the trials do not differ."""


def main(device: str, sigmas: list[float], trials: int) -> None:
    suite = list(builtin_contours().values())
    envs = [c for c in suite for _ in range(trials)]
    shape = (len(suite), trials)
    for sigma in sigmas:
        config = SimConfig(noise_std=sigma)
        start = time.perf_counter()
        none = CuttingTask(config, envs, device=device).run(None).path_error_vertices.reshape(shape)
        pinch = np.array([default_pinch(c, config) for c in envs])
        fixed = CuttingTask(config, envs, pinch_points=pinch, device=device).run(None)
        fixed = fixed.path_error_vertices.reshape(shape)
        improvement = 100 * (none - fixed) / none
        cis = np.array([ci95(row) for row in improvement])
        spread = np.median(none.std(axis=1) / none.mean(axis=1))
        took = time.perf_counter() - start
        print(
            f"sigma {sigma} mm: no-tension mean {none.mean():.1f} vertices, median spread between trials "
            f"{100 * spread:.1f}%; fixed improvement {np.mean(improvement):.1f}%, "
            f"median CI {np.median(cis):.2f}, contours with CI 0: {int((np.abs(cis) < ZERO_CI).sum())} of "
            f"{len(suite)} ({took:.0f} s)",
            flush=True,
        )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--device", default="cpu", help="Warp device: cpu or cuda")
    parser.add_argument(
        "--sigmas", default=SIGMAS, help=f"noise levels, mm, comma-separated (default {SIGMAS})"
    )
    parser.add_argument("--trials", type=int, default=10, help="noisy trials per contour (default 10)")
    args = parser.parse_args()
    if args.trials < 2:
        parser.error("--trials: at least 2 (the CI and the spread compare trials)")
    main(args.device, [float(s) for s in args.sigmas.split(",")], args.trials)
