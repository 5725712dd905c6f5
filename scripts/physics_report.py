"""The figures quoted in docs/physics.md: the settled sheet's sag, stretch and drift per spring set and
sweep setting, the authors' preset against their released code's sheet, and the no-tension error of every
built-in contour (path error, separated error, how many trials came free; all contours and trials cut in one
batch). Under a minute on a CPU.

Run: python scripts/physics_report.py [--device cpu] [--trials 10]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from warpcut import SimConfig, Simulator
from warpcut.contours import builtin_contours
from warpcut.sim.checks import settled_figures
from warpcut.stats import ci95
from warpcut.task import CuttingTask


def sweeps_label(config: SimConfig) -> str:
    """``7 (Chebyshev 0.94)`` or ``20`` (plain Gauss-Seidel)."""
    return (
        f"{config.sweeps} (Chebyshev {config.chebyshev_rho:g})"
        if config.chebyshev_rho
        else str(config.sweeps)
    )


def settle_table(device: str) -> None:
    print(
        "| setting | springs | sweeps | centre sag (mm) | mean / max structural stretch (%) | drift over "
        "100 more updates (mm) |"
    )
    print("|---|---|---|---|---|---|")
    settings = [
        ("default (corners)", SimConfig()),
        ("corners, 20 plain Gauss-Seidel sweeps", SimConfig(sweeps=20, chebyshev_rho=0.0)),
        ("corners", SimConfig(springs=("structural", "shear", "bending"))),
        ("corners", SimConfig(springs=("structural",))),
        ("corners", SimConfig(springs=("structural",), sweeps=20, chebyshev_rho=0.0)),
        ("corners", SimConfig(springs=("structural",), sweeps=5, chebyshev_rho=0.0)),
        ("authors preset (rows)", SimConfig.authors()),
    ]
    for label, config in settings:
        sim = Simulator(config, 1, device=device)
        sag, stretch_max, stretch_mean = settled_figures(sim)
        g = sim.grid
        centre = (g.ny // 2) * g.nx + g.nx // 2
        settled = sim.settled_positions()[0]
        sim.reset()
        for _ in range(100):
            sim.update()
        drift = abs(sim.positions()[0, centre, 2] - settled[centre, 2])
        print(
            f"| {label} | {'+'.join(config.springs)} | {sweeps_label(config)} | {sag:.1f} | "
            f"{stretch_mean:.1f} / {stretch_max:.0f} | {drift:.2f} |"
        )


def no_tension_table(device: str, trials: int = 10) -> None:
    suite = builtin_contours()
    contours = list(suite.values())
    envs = [c for c in contours for _ in range(trials)]
    start = time.perf_counter()
    task = CuttingTask(SimConfig(), envs, device=device)
    score = task.run(None)
    elapsed = time.perf_counter() - start
    shape = (len(contours), trials)
    path = score.path_error_vertices.reshape(shape)
    separated = score.separated_error_vertices.reshape(shape)
    came_free = score.separated.reshape(shape)
    dropped = score.dropped_fraction.reshape(shape)
    vertex = task.grid.vertex_area_mm2
    print(
        f"\nNo-tension error, 25x25 default sheet, default single-loop trajectories, {trials} noisy trials "
        f"(sigma {SimConfig().noise_std} mm) per contour ({len(envs)} envs in one batch, {elapsed:.1f} s):\n"
    )
    print(
        "| contour | kind | area (vertices) | path error (vertices) | 95% CI | path / area | dropped "
        "| separated error (vertices) | came free |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for k, c in enumerate(contours):
        print(
            f"| {c.name} | {'closed' if c.closed else 'open'} | {c.area_mm2 / vertex:.1f} | "
            f"{path[k].mean():.1f} | ±{ci95(path[k]):.1f} | {path[k].mean() * vertex / c.area_mm2:.2f} | "
            f"{np.nanmean(dropped[k]):.0%} | {separated[k].mean():.1f} | {came_free[k].sum()}/{trials} |"
        )
    ratio = path.mean(axis=1) * vertex / np.array([c.area_mm2 for c in contours])
    print(
        f"\npath / area: median {np.median(ratio):.2f}, max {ratio.max():.2f}; contours whose trials differ: "
        f"{int((path.std(axis=1) > 0).sum())} of {len(contours)}; median spread (std / mean) of the path "
        f"error between trials {100 * np.median(path.std(axis=1) / path.mean(axis=1)):.1f}%"
    )


def authors_sheet(device: str) -> None:
    """The authors' preset against their released code's settled sheet (rows, 200 updates)."""
    sim = Simulator(SimConfig.authors(), 1, device=device)
    sag, stretch_max, stretch_mean = settled_figures(sim)
    print(
        f"\nSimConfig.authors(), settled: centre sag {sag:.1f} mm, structural stretch max {stretch_max:.1f}% "
        f"mean {stretch_mean:.1f}% (their code: 12.5 mm, 10.0%, 2.3%)"
    )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--device", default="cpu", help="Warp device: cpu or cuda")
    parser.add_argument("--trials", type=int, default=10, help="noisy trials per contour (default 10)")
    args = parser.parse_args()
    settle_table(args.device)
    authors_sheet(args.device)
    no_tension_table(args.device, args.trials)
