"""How the simulator's cost grows with resolution and batch size, and where an update's time goes (by stage at
the largest batch, and a task step's Python overhead at B = 1): the tables quoted in docs/performance.md and
its figure, docs/img/scaling.png (+ .svg).

Run: python scripts/perf_scaling.py [--device cpu] [--repeats 3]
     [--resolutions 10,15,25,35,50] [--batches 1,16,64,256,1024] [--out docs/img/scaling]
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

RESOLUTIONS = "10,15,25,35,50"
BATCHES = "1,16,64,256,1024"


def scaling(device: str, repeats: int, resolutions: list[int], batches: list[int]) -> dict:
    table = {}
    for res in resolutions:
        for b in batches:
            table[(res, b)] = updates_per_second(SimConfig(resolution=res), b, device, repeats)
    return table


def breakdown(device: str, repeats: int, b: int) -> list[tuple[str, float]]:
    """Per-update time at batch ``b`` split by stage, from runs that switch stages off one at a time."""
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
        (f"relaxation, {sweeps} sweeps with their Chebyshev steps (B={b}, per update)", sweeps * per_sweep),
        (f"integrate + cut (B={b}, per update)", integrate_cut),
        (f"whole update (B={b})", full),
        ("kernel launch + update (B=1)", kernel_b1),
        ("task step overhead per update (B=1: tip upload, bookkeeping)", max(step_time - kernel_b1, 0.0)),
    ]


def plot(table: dict, resolutions: list[int], batches: list[int], path: Path) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for b in batches:
        axes[0].plot([r * r for r in resolutions], [table[(r, b)] for r in resolutions], "o-", label=f"B={b}")
    axes[0].set(
        xscale="log",
        yscale="log",
        xlabel="vertices per sheet",
        ylabel="env updates / s",
        title="cost vs resolution",
    )
    for r in resolutions:
        axes[1].plot(batches, [table[(r, b)] for b in batches], "o-", label=f"{r}x{r}")
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


def numbers(text: str) -> list[int]:
    return [int(v) for v in text.split(",")]


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--device", default="cpu", help="Warp device: cpu or cuda")
    parser.add_argument("--repeats", type=int, default=3, help="timings per figure, the median kept")
    parser.add_argument("--resolutions", type=numbers, default=RESOLUTIONS, help=f"default {RESOLUTIONS}")
    parser.add_argument(
        "--batches", type=numbers, default=BATCHES, help=f"default {BATCHES}; the stages at the largest"
    )
    parser.add_argument(
        "--out", type=Path, default=Path("docs/img/scaling"), help="the figure, without suffix (.png, .svg)"
    )
    args = parser.parse_args()
    start = time.perf_counter()
    table = scaling(args.device, args.repeats, args.resolutions, args.batches)
    print("| resolution | " + " | ".join(f"B={b}" for b in args.batches) + " |")
    print("|---|" + "---|" * len(args.batches))
    for r in args.resolutions:
        print(f"| {r}x{r} | " + " | ".join(f"{table[(r, b)]:,.0f}" for b in args.batches) + " |")
    print("\n| stage | time (ms) |\n|---|---|")
    for label, seconds in breakdown(args.device, args.repeats, max(args.batches)):
        print(f"| {label} | {1e3 * seconds:.3f} |")
    plot(table, args.resolutions, args.batches, args.out)
    print(f"\n({time.perf_counter() - start:.0f} s; wrote {args.out}.png and .svg)")
