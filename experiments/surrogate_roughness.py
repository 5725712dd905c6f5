"""Is the tape gradient of the path surrogate a descent direction for finite steps? A line search along it
on the same noisy episodes (the same noise seed), against the change the gradient promises: the measurement
behind smoothing the gradient (es's estimate, ``grad.estimator=es``) and behind the tape's window
(``grad.window``).

Each contour is cut as planned (pinch point and order) by ``--envs`` noisy episodes of one seed, holding
still (fixed tension) or playing ``--plan FILE`` (a grad plan, ``{"plan": [[dx, dy, dz], ...]}``). The
gradient of the surrogate's sum with respect to every move (``DifferentiableRollout.backward``, whole
episodes and windows of 5 and 10 steps) gives the direction ``d = -g / max|g|`` (the largest move change is
``eps`` mm). For each ``eps`` the same episodes are run again with the moves ``+ eps * d``:

- ``change``: the surrogate's sum, after minus before (mm^2; negative is better);
- ``predicted``: ``eps * g . d``, the first-order change the gradient promises;
- the same for ``--random`` random directions of the same size (the roughness floor: how much any change
  of that size moves the surrogate).

Run: python experiments/surrogate_roughness.py [--contours fls-circle,blob-lumpy] [--envs 8] [--random 5]
     [--plan FILE] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from warpcut import SimConfig, plan_cut
from warpcut.contours import load_contour
from warpcut.gradients import DifferentiableRollout
from warpcut.task import CuttingTask

STEPS_MM = (1e-5, 1e-4, 1e-3, 1e-2, 3e-2, 1e-1, 3e-1)
WINDOWS = (None, 10, 5)


def measure(name: str, envs: int, plan_file: Path | None, random: int, seed: int) -> list[str]:
    config = SimConfig()
    contour = load_contour(name)
    plan = plan_cut(contour, config.replace(noise_std=0.0), seed=seed)
    task = CuttingTask(
        config, [contour] * envs, pinch_points=[plan.chosen["pinch"]] * envs,
        segments=[plan.ordered_segments()] * envs, seed=seed,
    )  # fmt: skip
    engine = DifferentiableRollout(task)
    moves = np.zeros((envs, task.num_steps, 3), np.float32)
    if plan_file is not None:
        given = np.asarray(json.loads(plan_file.read_text())["plan"], dtype=np.float32)[: task.num_steps]
        moves[:, : len(given)] = given
    episode_seed = seed + 1
    base = engine.forward(moves, seed=episode_seed)
    before = float(np.nansum(base.surrogate))
    rng = np.random.default_rng(seed)
    lines = [f"{name}: {envs} episodes, surrogate sum {before:.2f} mm^2 ({'plan' if plan_file else 'still'})"]
    floors = []
    for eps in STEPS_MM:
        changes = []
        for _ in range(random):
            d = rng.normal(size=moves.shape).astype(np.float32)
            d /= np.abs(d).max()
            after = engine.forward(np.clip(moves + eps * d, -1, 1), seed=episode_seed)
            changes.append(abs(float(np.nansum(after.surrogate)) - before))
        floors.append(float(np.median(changes)))
    lines.append("  random directions, median |change|: " + ", ".join(
        f"{eps:g} mm {f:.3g}" for eps, f in zip(STEPS_MM, floors, strict=True)))  # fmt: skip
    for window in WINDOWS:
        g = engine.backward(base, window).actions
        d = -g / np.abs(g).max()
        slope = float((g * d).sum())
        row = []
        for eps in STEPS_MM:
            after = engine.forward(np.clip(moves + eps * d, -1, 1), seed=episode_seed)
            row.append(f"{eps:g} mm {float(np.nansum(after.surrogate)) - before:+.3g} ({eps * slope:+.3g})")
        lines.append(f"  gradient, window {window or 'whole'}: change (predicted): " + ", ".join(row))
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--contours", default="fls-circle,blob-lumpy", help="comma-separated names")
    parser.add_argument("--envs", type=int, default=8, help="noisy episodes (one seed)")
    parser.add_argument("--plan", type=Path, default=None, help="a grad plan JSON to start from")
    parser.add_argument("--random", type=int, default=5, help="random directions per step size")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None, help="also write the lines to this file")
    args = parser.parse_args()
    lines = []
    for name in args.contours.split(","):
        for line in measure(name, args.envs, args.plan, args.random, args.seed):
            print(line, flush=True)
            lines.append(line)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
