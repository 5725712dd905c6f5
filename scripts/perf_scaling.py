"""Measure how simulator cost grows with resolution and batch size, and where an update's time goes.

Writes docs/img/scaling.png (+ .svg) and prints the markdown tables quoted in docs/performance.md.
Run: python scripts/perf_scaling.py [--device cpu] [--repeats 3]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from warpcut import SimConfig  # noqa: E402
from warpcut.bench import updates_per_second  # noqa: E402
from warpcut.contours import load_contour  # noqa: E402
from warpcut.task import CuttingTask  # noqa: E402

RESOLUTIONS = (10, 15, 25, 35, 50)
BATCHES = (1, 16, 64, 256, 1024)


def scaling(device: str, repeats: int) -> dict:
    table = {}
    for res in RESOLUTIONS:
        for b in BATCHES:
            table[(res, b)] = updates_per_second(SimConfig(resolution=res), b, device, repeats)
    return table


def breakdown(device: str, repeats: int) -> list[tuple[str, float]]:
    """Per-update time at B=1024 split by stage, from runs that switch stages off one at a time."""
    b = 1024
    sweeps = SimConfig().sweeps
    full = b / updates_per_second(SimConfig(), b, device, repeats)
    one_sweep = b / updates_per_second(SimConfig(sweeps=1), b, device, repeats)
    per_sweep = (full - one_sweep) / (sweeps - 1)
    integrate_cut = one_sweep - per_sweep
    # Python-side cost of a task step at B=1: everything that is not the kernel.
    task = CuttingTask(SimConfig(), load_contour("fls-circle"), num_envs=1, device=device)
    steps = 20
    times = []
    for _ in range(repeats + 1):
        task.reset()
        start = time.perf_counter()
        for _ in range(steps):
            task.step(None)
        times.append((time.perf_counter() - start) / (steps * task.config.updates_per_step))
    step_time = sorted(times[1:])[len(times[1:]) // 2]
    kernel_b1 = 1 / updates_per_second(SimConfig(), 1, device, repeats)
    return [
        (f"relaxation, {sweeps} sweeps with their Chebyshev steps (B=1024, per update)", sweeps * per_sweep),
        ("integrate + cut (B=1024, per update)", integrate_cut),
        ("whole update (B=1024)", full),
        ("kernel launch + update (B=1)", kernel_b1),
        ("task step overhead per update (B=1: tip upload, bookkeeping)", max(step_time - kernel_b1, 0.0)),
    ]


def plot(table: dict, path: Path) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for b in BATCHES:
        axes[0].plot([r * r for r in RESOLUTIONS], [table[(r, b)] for r in RESOLUTIONS], "o-", label=f"B={b}")
    axes[0].set(
        xscale="log",
        yscale="log",
        xlabel="vertices per sheet",
        ylabel="env updates / s",
        title="cost vs resolution",
    )
    for r in RESOLUTIONS:
        axes[1].plot(BATCHES, [table[(r, b)] for b in BATCHES], "o-", label=f"{r}x{r}")
    axes[1].set(
        xscale="log",
        yscale="log",
        xlabel="batch size B",
        ylabel="env updates / s",
        title="throughput vs batch size",
    )
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path.with_suffix(".png"), dpi=120)
    fig.savefig(path.with_suffix(".svg"))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    start = time.perf_counter()
    table = scaling(args.device, args.repeats)
    print("| resolution | " + " | ".join(f"B={b}" for b in BATCHES) + " |")
    print("|---|" + "---|" * len(BATCHES))
    for r in RESOLUTIONS:
        print(f"| {r}x{r} | " + " | ".join(f"{table[(r, b)]:,.0f}" for b in BATCHES) + " |")
    print("\n| stage | time (ms) |\n|---|---|")
    for label, seconds in breakdown(args.device, args.repeats):
        print(f"| {label} | {1e3 * seconds:.3f} |")
    plot(table, Path("docs/img/scaling"))
    print(f"\n({time.perf_counter() - start:.0f} s; wrote docs/img/scaling.png and .svg)")
