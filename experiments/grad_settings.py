"""Settings of the gradient optimiser (agents.plan_optimizer.optimizer.optimize_plan) side by side on a few
contours: why ``grad.*`` defaults are what they are. Each contour is planned once (noise-free), then every
setting optimises a plan at the planned pinch and order and is evaluated on the default protocol (``--trials``
paired noisy trials, seed 0) against no tension; fixed tension at the same pinch is the reference.

Run: python experiments/grad_settings.py --contours fls-circle,kidney,crescent,arc-top,s-curve,e-shape
     [--settings "learning_rate=0.1;learning_rate=0.2,window=5;estimator=es"] [--trials 10] [--out FILE]
A setting is a comma-separated list of ``grad.*`` fields (``warpcut optimize --print-config``) on top of its
estimator's defaults, e.g. "learning_rate=0.3,window=10,iterations=20" or "estimator=es,iterations=40";
settings are separated by ';'.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from agents.config_io import apply, parse_override
from agents.plan_optimizer.config import GradConfig, grad_config
from agents.plan_optimizer.optimizer import optimize_plan
from agents.plan_optimizer.plan import PlanResult
from warpcut import SimConfig, load_contour, plan_cut
from warpcut.stats import paired_improvement
from warpcut.task import CuttingTask

DEFAULT_SETTINGS = (
    "learning_rate=0.1;learning_rate=0.2;learning_rate=0.2,window=5;learning_rate=0.3,window=10"
)


def parse_setting(text: str) -> GradConfig:
    """``"key=value,key=value"`` as a GradConfig: its estimator's defaults with these fields."""
    fields = dict(parse_override(item) for item in text.split(",") if item.strip())
    estimator = fields.pop("estimator", GradConfig().estimator)
    return apply(grad_config(estimator), fields, f"--settings {text!r}").validated()


def trial_errors(config, contour, segments, policy, pinch, trials: int) -> np.ndarray:
    """The path error of ``trials`` paired noisy trials (seed 0) of ``policy`` at ``pinch`` (None: no
    grasp)."""
    pinches = None if pinch is None else [pinch] * trials
    task = CuttingTask(config, [contour] * trials, pinch_points=pinches, segments=[segments] * trials, seed=0)
    return task.run(policy).error_vertices


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--contours", required=True, help="comma-separated contour names")
    parser.add_argument("--settings", default=DEFAULT_SETTINGS, help="';'-separated settings (see above)")
    parser.add_argument("--trials", type=int, default=10, help="paired noisy trials of the evaluation")
    parser.add_argument("--candidates", type=int, default=None, help="pinch candidates (default: the plan's)")
    parser.add_argument("--out", type=Path, default=None, help="also write the lines to this file")
    args = parser.parse_args()
    settings = {text: parse_setting(text) for text in args.settings.split(";")}
    config = SimConfig()
    sampled = {} if args.candidates is None else {"num_candidates": args.candidates}
    improvements: dict[str, list[float]] = {"fixed": []}
    lines = []
    for name in args.contours.split(","):
        contour = load_contour(name)
        plan = plan_cut(contour, config.replace(noise_std=0.0), **sampled)
        pinch, segments = plan.chosen["pinch"], plan.ordered_segments()

        def errors(policy, at, contour=contour, segments=segments):
            return trial_errors(config, contour, segments, policy, at, args.trials)

        none = errors(None, None)
        fixed = float(np.mean(paired_improvement(none, errors(None, pinch))))
        improvements["fixed"].append(fixed)
        line = f"{name:<16} fixed {fixed:+6.1f}"
        for text, setting in settings.items():
            start = time.perf_counter()
            result = optimize_plan(contour, pinch, segments, config, setting)
            value = float(
                np.mean(
                    paired_improvement(none, errors(PlanResult.policy([result], args.trials), result.pinch))
                )
            )
            improvements.setdefault(text, []).append(value)
            line += (
                f" | {text} {value:+6.1f} (it {result.best_iteration}, {time.perf_counter() - start:.0f} s)"
            )
        lines.append(line)
        print(line, flush=True)
    lines.append("mean: " + ", ".join(f"{k} {np.mean(v):+.1f}" for k, v in improvements.items()))
    print(lines[-1])
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
