"""Error of constant grasp moves (stay, +-x, +-y, +-z every step, 1 mm a step up to the 10 mm limit) against
no tension, for every built-in contour cut as one loop with the grasp at the centroid (or the nearest
feasible point), noisy (one trial each): which contours need the sheet lifted (why the moves include z:
``env.allow_z``), which need a pull, and where holding still is enough.

Run: python experiments/constant_moves.py [--device cpu]
"""

from __future__ import annotations

import argparse

import numpy as np

from warpcut import SimConfig
from warpcut.contours import builtin_contours
from warpcut.planning import default_pinch
from warpcut.task import CuttingTask

MOVES = {
    "none": None,
    "stay": (0, 0, 0),
    "+x": (1, 0, 0),
    "-x": (-1, 0, 0),
    "+y": (0, 1, 0),
    "-y": (0, -1, 0),
    "+z": (0, 0, 1),
    "-z": (0, 0, -1),
}


def main(device: str | None) -> None:
    config = SimConfig()
    suite = builtin_contours()
    contours, pinches, actions = [], [], []
    for contour in suite.values():
        pinch = default_pinch(contour, config)
        for move in MOVES.values():
            contours.append(contour)
            pinches.append([np.nan, np.nan] if move is None else pinch)
            actions.append((0, 0, 0) if move is None else move)
    moves = np.asarray(actions, dtype=np.float32)  # 1 mm per step, clipped at 10 mm in all
    task = CuttingTask(config, contours, pinch_points=np.asarray(pinches), device=device)
    errors = task.run(lambda _task: moves).error_vertices.reshape(len(suite), len(MOVES))
    print("| contour | " + " | ".join(MOVES) + " |")
    print("|---|" + "---|" * len(MOVES))
    for name, row in zip(suite, errors, strict=True):
        print(f"| {name} | " + " | ".join(f"{v:.0f}" for v in row) + " |")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--device", default=None, help="Warp device: cpu or cuda (default: Warp's)")
    main(parser.parse_args().device)
