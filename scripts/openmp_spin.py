"""What GNU OpenMP's spin count does to PPO at the training batch: per ``GOMP_SPINCOUNT`` value, the env
steps' times inside a PPO training run by their place in the iteration (the first after each PPO update, the
next six, the rest), the update's time and a whole iteration's, median over the steady iterations. Each
value runs in its own process (libgomp reads the variable once, when torch loads), alternating over rounds.
The figures in docs/performance.md, "The whole step path" (OpenMP spin count).

Run: python scripts/openmp_spin.py [--envs 256] [--iterations 10] [--rounds 4] [--values 300000,30000]
     (300000 is libgomp's default; importing ``agents`` sets :data:`agents.OPENMP_SPIN_COUNT` unless set)
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

CHILD = r"""
import json, sys, tempfile, time
import numpy as np
from agents.config import TrainConfig
from agents.ppo.algorithm import PPO
from agents.training import train, training_env
from envs.options import PatternCutOptions

n, iterations = int(sys.argv[1]), int(sys.argv[2])
cfg = TrainConfig(algo="ppo", num_envs=n, iterations=iterations, save_interval=10**6)
env = training_env(PatternCutOptions(contour="fls-circle", action_type="discrete"), cfg)
steps, updates = [], []
env_step, update = env.step, PPO.update
def timed_step(action):
    start = time.perf_counter(); out = env_step(action); steps.append(time.perf_counter() - start); return out
def timed_update(self, *args, **kwargs):
    start = time.perf_counter(); out = update(self, *args, **kwargs)
    updates.append(time.perf_counter() - start); return out
env.step, PPO.update = timed_step, timed_update
with tempfile.TemporaryDirectory() as out:
    train(env, cfg, out, progress=False)
per = cfg.ppo.num_steps_per_env
t = 1e3 * np.array(steps[per:]).reshape(-1, per)  # the iterations after the first (which follow an update)
u = 1e3 * np.array(updates[:-1])  # the update before each of them
print(json.dumps({"first": float(np.median(t[:, 0])), "next 6": float(np.median(t[:, 1:7])),
                  "rest": float(np.median(t[:, 7:])), "update": float(np.median(u)),
                  "iteration": float(np.median(t.sum(axis=1) + u))}))
"""


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--envs", type=int, default=256, help="the batch (default 256, PPO's)")
    parser.add_argument("--iterations", type=int, default=10, help="PPO iterations per run (at least 2)")
    parser.add_argument("--rounds", type=int, default=4, help="runs per value, alternating")
    parser.add_argument("--values", default="300000,30000", help="GOMP_SPINCOUNT values, comma-separated")
    args = parser.parse_args()
    values = args.values.split(",")
    rows = {v: [] for v in values}
    for r in range(args.rounds):
        for value in values:
            env = dict(os.environ, GOMP_SPINCOUNT=value)
            cmd = [sys.executable, "-c", CHILD, str(args.envs), str(args.iterations)]
            out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
            rows[value].append(json.loads(out.stdout.strip().splitlines()[-1]))
            print(
                f"round {r + 1} GOMP_SPINCOUNT={value}: "
                + ", ".join(f"{k} {x:.2f} ms" for k, x in rows[value][-1].items()),
                flush=True,
            )
    print(
        f"\nMedian over {args.rounds} rounds, ms ({args.envs} envs; env steps by place in the iteration):\n"
    )
    keys = list(rows[values[0]][0])
    print("| GOMP_SPINCOUNT | " + " | ".join(keys) + " |")
    print("|---|" + "---|" * len(keys))
    for value, runs in rows.items():
        medians = [statistics.median(run[k] for run in runs) for k in keys]
        print(f"| {value} | " + " | ".join(f"{m:.2f}" for m in medians) + " |")


if __name__ == "__main__":
    main()
