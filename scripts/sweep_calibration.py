"""Calibrate the Chebyshev-accelerated sweeps (the default: SimConfig's 7 sweeps at rho 0.94) against the
sheet of 20 plain Gauss-Seidel sweeps: the figures in docs/physics.md, "Fewer sweeps".

1. Settled sheet (noise-free, 200 updates) per (sweeps, rho): centre sag, structural stretch, drift over
   100 more updates, RMS and largest distance of the vertices from the 20-sweep sheet, and the Chebyshev
   residual factor ``1 / T_K(1 / rho)`` (stability, ``warpcut.sim.config.chebyshev_rho_limit``).
2. No-tension path error of every built-in contour, 10 noisy trials each, for the 20-sweep sheet and the
   candidates: per-contour means with 95% CIs and how many contours differ beyond them.
3. Env updates/s at B = 1024 of each (one timing each, interleaved: compare ratios).
4. The default at every resolution: settles (sag), or is refused / diverges.

Run: python scripts/sweep_calibration.py [--quick]
     (--quick, a smoke run: part 1 for the default alone, part 2 at 2 trials, no parts 3 and 4)
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from warpcut import SimConfig, Simulator
from warpcut.bench import updates_per_second
from warpcut.contours import builtin_contours
from warpcut.sim.checks import settled_figures
from warpcut.sim.config import ConfigError, SimulationDiverged
from warpcut.stats import ci95
from warpcut.task import CuttingTask

REFERENCE = {"sweeps": 20, "chebyshev_rho": 0.0}
"""The sheet to reproduce: 20 plain Gauss-Seidel sweeps."""
CANDIDATES = {
    "8 sweeps, rho 0.92": {"sweeps": 8, "chebyshev_rho": 0.92},
    "7 sweeps, rho 0.94": {"sweeps": 7, "chebyshev_rho": 0.94},
    "6 sweeps, rho 0.95": {"sweeps": 6, "chebyshev_rho": 0.95},
    "7 plain sweeps": {"sweeps": 7, "chebyshev_rho": 0.0},
}


def settle(changes: dict) -> tuple[float, float, float, float, np.ndarray]:
    sim = Simulator(SimConfig(noise_std=0.0, **changes), 1)
    sag, stretch_max, stretch_mean = settled_figures(sim)
    settled = sim.settled_positions()[0]
    centre = (sim.grid.ny // 2) * sim.grid.nx + sim.grid.nx // 2
    sim.reset()
    for _ in range(100):
        sim.update()
    drift = abs(float(sim.positions()[0, centre, 2] - settled[centre, 2]))
    return sag, stretch_max, stretch_mean, drift, settled


def residual(sweeps: int, rho: float) -> float:
    return 0.0 if rho == 0 else 1.0 / math.cosh(sweeps * math.acosh(1.0 / rho))


def settle_table(sweep_counts: list[int], rhos: list[float]) -> None:
    ref = settle(REFERENCE)
    print(
        "| sweeps | rho | residual factor | centre sag (mm) | mean / max stretch (%) | drift (mm) | "
        "RMS / max distance from 20 plain sweeps (mm) |"
    )
    print("|---|---|---|---|---|---|---|")
    print(f"| 20 | 0 (plain) | - | {ref[0]:.2f} | {ref[2]:.2f} / {ref[1]:.1f} | {ref[3]:.2f} | 0 |")
    for sweeps in sweep_counts:
        for rho in rhos:
            row = f"| {sweeps} | {rho:g} | {residual(sweeps, rho):.3f} |"
            try:
                sag, smax, smean, drift, settled = settle({"sweeps": sweeps, "chebyshev_rho": rho})
            except (ConfigError, SimulationDiverged) as error:
                print(row + f" {type(error).__name__} | | | |")
                continue
            gap = np.linalg.norm(settled - ref[4], axis=-1)
            print(
                row + f" {sag:.2f} | {smean:.2f} / {smax:.1f} | {drift:.2f} | "
                f"{np.sqrt(np.mean(gap**2)):.3f} / {gap.max():.2f} |"
            )


def no_tension_table(trials: int) -> None:
    contours = list(builtin_contours().values())
    envs = [c for c in contours for _ in range(trials)]
    settings = {"20 plain sweeps": REFERENCE, **CANDIDATES}
    errors = {}
    for label, changes in settings.items():
        score = CuttingTask(SimConfig(**changes), envs).run(None)
        errors[label] = score.path_error_vertices.reshape(len(contours), trials)
    print(f"\nNo-tension path error (vertices), {trials} noisy trials per contour, mean ± 95% CI:\n")
    print("| contour | " + " | ".join(settings) + " |")
    print("|---|" + "---|" * len(settings))
    for k, contour in enumerate(contours):
        cells = [f"{e[k].mean():.1f} ± {ci95(e[k]):.1f}" for e in errors.values()]
        print(f"| {contour.name} | " + " | ".join(cells) + " |")
    ref = errors["20 plain sweeps"]
    print("| suite mean | " + " | ".join(f"{e.mean():.2f}" for e in errors.values()) + " |")
    for label, e in errors.items():
        if label == "20 plain sweeps":
            continue
        gap = e.mean(axis=1) - ref.mean(axis=1)
        se = np.sqrt(e.var(axis=1, ddof=1) / trials + ref.var(axis=1, ddof=1) / trials)
        print(
            f"{label}: suite mean {e.mean() - ref.mean():+.2f} vertices against 20 plain sweeps; "
            f"contours differing beyond 1.96 SE of the difference: {int((np.abs(gap) > 1.96 * se).sum())} "
            f"of {len(contours)}; mean |difference| {np.abs(gap).mean():.2f}"
        )


def speed_table(repeats: int) -> None:
    settings = {"20 plain sweeps": REFERENCE, **CANDIDATES}
    print("\nEnv updates/s at B = 1024 (interleaved, two rounds):")
    rates: dict[str, list[float]] = {label: [] for label in settings}
    for _ in range(2):
        for label, changes in settings.items():
            rates[label].append(updates_per_second(SimConfig(**changes), 1024, "cpu", repeats))
    ref = np.median(rates["20 plain sweeps"])
    for label, r in rates.items():
        print(f"  {label}: {np.median(r):,.0f} ({np.median(r) / ref:.2f}x)")


def resolution_table() -> None:
    print("\nThe default (sweeps, rho) at other resolutions (noise-free settle), sag in mm:")
    for resolution in (5, 9, 13, 17, 25, 35, 50, 75, 100):
        try:
            sag = settle({"resolution": resolution})[0]
            ref = settle({"resolution": resolution, **REFERENCE})[0]
            print(f"  {resolution} x {resolution}: {sag:.1f} (20 plain sweeps: {ref:.1f})")
        except (ConfigError, SimulationDiverged) as error:
            print(f"  {resolution} x {resolution}: {type(error).__name__}: {error}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="fewer settings and trials (a smoke run)")
    args = parser.parse_args()
    if args.quick:
        settle_table([7], [0.94])
        no_tension_table(trials=2)
    else:
        settle_table([5, 6, 7, 8], [0.88, 0.9, 0.92, 0.93, 0.94, 0.95, 0.96])
        no_tension_table(trials=10)
        speed_table(repeats=3)
        resolution_table()
