"""How the process noise spreads the trials (docs/physics.md, "Process noise"): for several noise levels,
the no-tension path error of every built-in contour and fixed tension at its feasible centroid, 10
trials each, single-loop cuts, all in one batch per method.

Run: python scripts/noise_calibration.py [--device cpu]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from warpcut import SimConfig
from warpcut.contours import builtin_contours
from warpcut.planning import default_pinch
from warpcut.scoring import ci95
from warpcut.task import CuttingTask

SIGMAS = (0.0, 0.01, 0.02, 0.03, 0.05)
TRIALS = 10


def main(device: str) -> None:
    suite = list(builtin_contours().values())
    envs = [c for c in suite for _ in range(TRIALS)]
    shape = (len(suite), TRIALS)
    for sigma in SIGMAS:
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
            f"median CI {np.median(cis):.2f}, contours with CI 0: {int((cis == 0).sum())} of {len(suite)} "
            f"({took:.0f} s)"
        )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--device", default="cpu")
    main(parser.parse_args().device)
