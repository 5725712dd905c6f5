"""Print the figures quoted in docs/physics.md: settled sag and stretch per spring set, and the
no-tension error of every built-in contour (all contours cut at once, one env each).

Run: python scripts/physics_report.py [--device cpu]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from warpcut import SimConfig, Simulator
from warpcut.contours import builtin_contours
from warpcut.task import CuttingTask


def settle_table(device: str) -> None:
    print(
        "| setting | springs | sweeps | centre sag (mm) | mean / max structural stretch (%) | drift over "
        "100 more updates (mm) |"
    )
    print("|---|---|---|---|---|---|")
    settings = [
        ("default (corners)", SimConfig()),
        ("corners", SimConfig(springs=("structural", "shear", "bending"))),
        ("corners", SimConfig(springs=("structural",))),
        ("corners", SimConfig(springs=("structural",), iterations=5)),
        ("authors preset (rows)", SimConfig.authors()),
    ]
    for label, config in settings:
        sim = Simulator(config, 1, device=device)
        settled = sim.settled_positions()[0]
        g = sim.grid
        p = settled.reshape(g.ny, g.nx, 3)
        hx, hy = g.spacing_mm
        stretch = np.concatenate(
            [
                (np.linalg.norm(p[:, 1:] - p[:, :-1], axis=-1) / hx - 1).ravel(),
                (np.linalg.norm(p[1:] - p[:-1], axis=-1) / hy - 1).ravel(),
            ]
        )
        centre = (g.ny // 2) * g.nx + g.nx // 2
        sim.reset()
        for _ in range(100):
            sim.update()
        drift = abs(sim.positions()[0, centre, 2] - settled[centre, 2])
        print(
            f"| {label} | {'+'.join(config.springs)} | {config.iterations} | {-settled[centre, 2]:.1f} | "
            f"{100 * stretch.mean():.1f} / {100 * stretch.max():.0f} | {drift:.2f} |"
        )


def no_tension_table(device: str) -> None:
    suite = builtin_contours()
    contours = list(suite.values())
    start = time.perf_counter()
    task = CuttingTask(SimConfig(), contours, device=device)
    score = task.run(None)
    elapsed = time.perf_counter() - start
    print(
        f"\nNo-tension error, 25x25 default sheet ({len(contours)} contours in one batch, {elapsed:.1f} s):\n"
    )
    print(
        "| contour | kind | length (mm) | intended area (mm^2) | error (vertices) | error (mm^2) "
        "| error / area |"
    )
    print("|---|---|---|---|---|---|---|")
    for k, c in enumerate(contours):
        print(
            f"| {c.name} | {'closed' if c.closed else 'open'} | {c.length:.1f} | {c.area_mm2:.0f} | "
            f"{score.error_vertices[k]:.0f} | {score.error_mm2[k]:.0f} | "
            f"{score.error_mm2[k] / c.area_mm2:.2f} |"
        )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()
    settle_table(args.device)
    no_tension_table(args.device)
