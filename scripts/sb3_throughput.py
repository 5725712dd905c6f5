"""Stable-Baselines3 PPO throughput: the batched Warp adapter (envs.sb3) against SB3 on single envs (the
README's SB3 speed figures).

Three ways to give SB3 the same scenario, each trained with the same PPO settings and the same rollout size
(``--rollout`` env steps per PPO iteration, split over the envs):

* ``batched adapter``: ``envs.sb3.make_sb3_env(B)``, one Warp batch of B sheets;
* ``one env``: ``PPO("MlpPolicy", PatternCutEnv(...))`` (SB3 wraps it in a ``DummyVecEnv`` of one);
* ``DummyVecEnv``: SB3's ``DummyVecEnv`` of B single ``PatternCutEnv`` (B Warp tasks of one sheet).

Per repeat it times ``model.learn`` over ``--iterations`` PPO iterations and, through a callback, the
rollouts alone (env steps plus policy forward passes, no gradient updates). It prints medians over
``--repeats`` (and, with ``--json``, writes them there).

Run: python scripts/sb3_throughput.py [--num-envs 64] [--repeats 3] [--device cpu] [--json PATH]
Needs stable-baselines3 (pip install -e ".[sb3]").
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import torch
import warp as wp
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

from envs import PatternCutEnv
from envs.sb3 import make_sb3_env


class RolloutTimer(BaseCallback):
    """Sums the wall time of SB3's rollouts (``collect_rollouts``: env steps and policy forward passes)."""

    def __init__(self):
        super().__init__()
        self.seconds = 0.0
        self._start = 0.0

    def _on_rollout_start(self) -> None:
        self._start = time.perf_counter()

    def _on_rollout_end(self) -> None:
        self.seconds += time.perf_counter() - self._start

    def _on_step(self) -> bool:
        return True


def measure(make_env: Callable[[], VecEnv | PatternCutEnv], num_envs: int, args: argparse.Namespace) -> dict:
    """Median learn and rollout env steps/s of PPO on fresh envs from ``make_env``, over ``args.repeats``."""
    n_steps = args.rollout // num_envs
    total = n_steps * num_envs * args.iterations
    learn, rollout = [], []
    for repeat in range(args.repeats):
        env = make_env()
        model = PPO(
            "MlpPolicy",
            env,
            n_steps=n_steps,
            batch_size=args.batch_size,
            n_epochs=args.epochs,
            device="cpu",
            seed=repeat,
        )
        timer = RolloutTimer()
        start = time.perf_counter()
        model.learn(total_timesteps=total, callback=timer)
        seconds = time.perf_counter() - start
        learn.append(total / seconds)
        rollout.append(total / timer.seconds)
        env.close()
    return {
        "num_envs": num_envs,
        "n_steps": n_steps,
        "env_steps": total,
        "learn_steps_per_s": statistics.median(learn),
        "rollout_steps_per_s": statistics.median(rollout),
        "learn_repeats": learn,
        "rollout_repeats": rollout,
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--num-envs", type=int, default=64, help="B: the adapter's and DummyVecEnv's envs")
    parser.add_argument("--rollout", type=int, default=5120, help="env steps per PPO iteration (all envs)")
    parser.add_argument("--iterations", type=int, default=2, help="PPO iterations per repeat")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--batch-size", type=int, default=256, help="PPO minibatch size")
    parser.add_argument("--epochs", type=int, default=4, help="PPO epochs per iteration")
    parser.add_argument("--contour", default="fls-circle")
    parser.add_argument("--resolution", type=int, default=None, help="vertices per side (default: 25)")
    parser.add_argument("--action-type", default="discrete", choices=["discrete", "continuous"])
    parser.add_argument("--device", default="cpu", help="Warp device of the simulator")
    parser.add_argument("--torch-threads", type=int, default=1, help="torch threads (0: torch's default)")
    parser.add_argument("--skip-dummy", action="store_true", help="leave out the DummyVecEnv of B envs")
    parser.add_argument("--json", type=Path, default=None, help="also write the settings and medians here")
    args = parser.parse_args()
    if args.rollout % args.num_envs:
        parser.error(f"--rollout ({args.rollout}) must be a multiple of --num-envs ({args.num_envs})")
    if args.torch_threads:
        torch.set_num_threads(args.torch_threads)
    wp.config.quiet = True
    options = {"contour": args.contour, "action_type": args.action_type, "device": args.device}
    if args.resolution is not None:
        options["resolution"] = args.resolution
    b = args.num_envs
    runs = {
        f"batched adapter (B={b})": (lambda: make_sb3_env(b, **options), b),
        "one env": (lambda: PatternCutEnv(**options), 1),
    }
    if not args.skip_dummy:
        runs[f"DummyVecEnv ({b} single envs)"] = (
            lambda: DummyVecEnv([lambda: Monitor(PatternCutEnv(**options))] * b),
            b,
        )
    results = {}
    for name, (make_env, num_envs) in runs.items():
        results[name] = measure(make_env, num_envs, args)
        r = results[name]
        print(f"  {name}: learn {r['learn_steps_per_s']:.0f}, rollout {r['rollout_steps_per_s']:.0f} steps/s")
    base = results["one env"]["rollout_steps_per_s"]
    title = f"SB3 PPO, {args.contour}, {args.action_type}"
    print(f"\n| {title} | envs | learn steps/s | rollout steps/s | rollout x |")
    print("|---|---:|---:|---:|---:|")
    for name, r in results.items():
        ratio = r["rollout_steps_per_s"] / base
        print(
            f"| {name} | {r['num_envs']} | {r['learn_steps_per_s']:.0f} | {r['rollout_steps_per_s']:.0f} "
            f"| {ratio:.1f} |"
        )
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    report = {
        "settings": {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()},
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "load_average": load},
        "median_of_repeats": results,
    }
    print(f"\nload average {load}")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=2) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
