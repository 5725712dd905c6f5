"""Where an env step's time goes: a tensioned ``fls-circle`` cut at the training batch (64 envs), layer by
layer, each timed alone over whole episodes (median of repeats), from the simulator's updates up to a PPO
iteration. The figures in docs/performance.md, "The whole step path".

Layers (each includes the ones above it):
  1. updates     ``Simulator.update`` x ``updates_per_step``, path tracing on (as a cut runs)
  2. task step   + the grasp move and the scissor tips' upload (``CuttingTask.step``)
  3. env step    + observations, rewards, divergence checks, episode bookkeeping (``PatternCutVecEnv.step``)
  4. rsl-rl step + torch conversions and the TensorDict (``PatternCutRslEnv.step``)
  5. PPO collection: + the policy's forward pass, sampling and rollout storage (rsl-rl's runner)
  6. PPO iteration: + the PPO update (collection + learning)

Then a cProfile of layer 4 (the functions with the largest own time) and of one PPO iteration.

Run: python scripts/step_profile.py [--envs 64] [--repeats 5]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import statistics
import tempfile
import time

import numpy as np
import torch

from agents.config import RECIPE, TrainConfig
from agents.rl import training_env
from agents.train import train
from envs.options import PatternCutOptions
from envs.rsl import PatternCutRslEnv
from envs.vector import PatternCutVecEnv

RECIPE_OPTIONS = {k: v for k, v in RECIPE.items() if k != "action_type"}
"""The observations and rewards training uses (warpcut's recipe), with continuous actions for a fixed pull."""


def per_step(fn, steps: int, repeats: int) -> float:
    """Median microseconds per env step (whole batch) of ``fn``, which runs ``steps`` steps."""
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return 1e6 * statistics.median(times) / steps


def layers(num_envs: int, repeats: int) -> dict[str, float]:
    options = PatternCutOptions(contour="fls-circle", action_type="continuous", **RECIPE_OPTIONS)
    vec = PatternCutVecEnv(num_envs, options)
    vec.reset(seed=0)
    task = vec.scene.task
    steps = task.num_steps
    action = np.tile([[0.5, 0.0, 0.5]], (num_envs, 1))
    per = task.config.updates_per_step
    tips = [[task.tip_positions(u) for u in range(k * per, (k + 1) * per)] for k in range(steps)]

    def updates() -> None:
        task.reset()
        for k in range(steps):
            for tip in tips[k]:
                task.sim.set_tip(tip)
                task.sim.update()

    def task_steps() -> None:
        task.reset()
        while not task.done:
            task.step(action)

    env_action = np.tile([[0.5, 0.0, 0.5]], (num_envs, 1)).astype(np.float32)[
        :, : vec.single_action_space.shape[0]
    ]

    # Episodes back to back, each reset inside the step that ends the last one (the autoreset training uses;
    # a seeded reset would also redraw the fiducials, which training does once).
    def env_steps() -> None:
        for _ in range(steps):
            vec.step(env_action)

    rsl = PatternCutRslEnv(PatternCutVecEnv(num_envs, options))
    torch_action = torch.as_tensor(env_action)

    def rsl_steps() -> None:
        for _ in range(steps):
            rsl.step(torch_action)

    out = {
        "1. updates": per_step(updates, steps, repeats),
        "2. task step": per_step(task_steps, steps, repeats),
    }
    vec.reset(seed=0)
    out |= {
        "3. env step": per_step(env_steps, steps, repeats),
        "4. rsl-rl step": per_step(rsl_steps, steps, repeats),
    }
    profile = cProfile.Profile()
    profile.enable()
    rsl_steps()
    profile.disable()
    return out, profile, rsl


def ppo(num_envs: int, iterations: int) -> tuple[dict[str, float], cProfile.Profile]:
    cfg = TrainConfig(num_envs=num_envs, iterations=iterations, num_steps_per_env=32, save_interval=10**6)
    options = PatternCutOptions(contour="fls-circle", **RECIPE)
    profile = cProfile.Profile()
    with tempfile.TemporaryDirectory() as out:
        env = training_env(options, cfg)
        profile.enable()
        summary = train(env, cfg, out, progress=False)
        profile.disable()
    steady = summary["history"][1:]
    per_iteration = cfg.num_envs * cfg.num_steps_per_env
    collect = statistics.median(per_iteration / m["collection_steps_per_s"] for m in steady)
    whole = statistics.median(per_iteration / m["iteration_steps_per_s"] for m in steady)
    steps = cfg.num_steps_per_env
    return {"5. PPO collection": 1e6 * collect / steps, "6. PPO iteration": 1e6 * whole / steps}, profile


def top(profile: cProfile.Profile, count: int = 15) -> str:
    text = io.StringIO()
    pstats.Stats(profile, stream=text).sort_stats("tottime").print_stats(count)
    return "\n".join(line for line in text.getvalue().splitlines() if line.strip())


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--envs", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--iterations", type=int, default=6)
    parser.add_argument("--profile", action="store_true", help="print the cProfile tables too")
    parser.add_argument("--torch-threads", type=int, default=None, help="default: torch's (the CLI's)")
    args = parser.parse_args()
    if args.torch_threads:
        torch.set_num_threads(args.torch_threads)
    times, env_profile, _ = layers(args.envs, args.repeats)
    ppo_times, ppo_profile = ppo(args.envs, args.iterations)
    times.update(ppo_times)
    print(
        f"\nMicroseconds per env step of the whole batch ({args.envs} envs, tensioned fls-circle), median:\n"
    )
    print("| layer | us per step | added by the layer | env steps/s |")
    print("|---|---|---|---|")
    before = 0.0
    for name, us in times.items():
        print(f"| {name} | {us:,.0f} | {us - before:+,.0f} | {args.envs * 1e6 / us:,.0f} |")
        before = us
    if args.profile:
        print("\ncProfile of the rsl-rl env steps (own time):\n" + top(env_profile))
        print("\ncProfile of a PPO run (own time):\n" + top(ppo_profile, 25))
