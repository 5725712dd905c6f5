"""Compare settings of the gradient optimiser (agents.gradient.optimize_plan) on a few contours: each
contour is planned once (30 candidates, noise-free), then every setting optimises a plan at the planned
pinch and order and is evaluated on the default protocol (10 paired noisy trials, seed 0) against no
tension; fixed tension at the same pinch is the reference. The figures in docs/learning.md, "Gradient-based
tensioning".

Run: python scripts/grad_settings.py --contours fls-circle,kidney,crescent,arc-top,s-curve,e-shape
     [--settings lr=0.1;lr=0.2,window=5;...] [--out logs/grad-settings.txt]
A setting is a list of GradConfig fields (lr is learning_rate, sigma es_sigma_mm, population es_population),
e.g. "lr=0.3,window=10,iterations=20" or "estimator=es,iterations=40,lr=0.1".
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from agents.config import GradConfig
from agents.gradient import PlanPolicy, optimize_plan
from warpcut import SimConfig, load_contour, plan_cut
from warpcut.scoring import paired_improvement
from warpcut.task import CuttingTask

DEFAULT_SETTINGS = "lr=0.1;lr=0.2;lr=0.2,window=5;lr=0.3,window=10"


def parse_setting(text: str) -> GradConfig:
    fields = {}
    for item in text.split(","):
        key, value = item.split("=")
        key = {"lr": "learning_rate", "sigma": "es_sigma_mm", "population": "es_population"}.get(
            key.strip(), key.strip()
        )
        if key == "estimator":
            fields[key] = value.strip()
        else:
            fields[key] = float(value) if key.endswith(("rate", "_mm")) else int(value)
    return GradConfig(**fields).validated()


def trial_errors(config, contour, segments, policy, pinch) -> np.ndarray:
    """The path error of 10 paired noisy trials (seed 0) of ``policy`` at ``pinch`` (None: no grasp)."""
    pinches = None if pinch is None else [pinch] * 10
    task = CuttingTask(config, [contour] * 10, pinch_points=pinches, segments=[segments] * 10, seed=0)
    return task.run(policy).error_vertices


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--contours", required=True)
    parser.add_argument("--settings", default=DEFAULT_SETTINGS)
    parser.add_argument("--out", type=Path, default=Path("logs/grad-settings.txt"))
    args = parser.parse_args()
    settings = {text: parse_setting(text) for text in args.settings.split(";")}
    config = SimConfig()
    improvements: dict[str, list[float]] = {"fixed": []}
    lines = []
    for name in args.contours.split(","):
        contour = load_contour(name)
        plan = plan_cut(contour, config.replace(noise_std=0.0))
        pinch, segments = plan.chosen["pinch"], plan.ordered_segments()

        none = trial_errors(config, contour, segments, None, None)
        fixed = float(np.mean(paired_improvement(none, trial_errors(config, contour, segments, None, pinch))))
        improvements["fixed"].append(fixed)
        line = f"{name:<16} fixed {fixed:+6.1f}"
        for text, setting in settings.items():
            start = time.perf_counter()
            result = optimize_plan(contour, pinch, segments, config, setting)
            grad = trial_errors(config, contour, segments, PlanPolicy([result.plan], 10), result.pinch)
            value = float(np.mean(paired_improvement(none, grad)))
            improvements.setdefault(text, []).append(value)
            line += (
                f" | {text} {value:+6.1f} (it {result.best_iteration}, {time.perf_counter() - start:.0f} s)"
            )
        lines.append(line)
        print(line, flush=True)
    lines.append("mean: " + ", ".join(f"{k} {np.mean(v):+.1f}" for k, v in improvements.items()))
    print(lines[-1])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
