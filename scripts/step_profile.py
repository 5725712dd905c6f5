"""Where an env step's time goes: a tensioned ``fls-circle`` cut at the training batch (256 envs), layer by
layer, each timed alone over whole episodes (median of repeats), from the simulator's updates up to a whole
learning iteration (PPO's by default, as docs/performance.md, "The whole step path", quotes it).

Layers (each includes the ones above it):
  1. updates     ``Simulator.update`` x ``updates_per_step``, path tracing on (as a cut runs)
  2. task step   + the grasp move and the scissor tips' upload (``CuttingTask.step``)
  3. env step    + observations, rewards, divergence checks, episode bookkeeping (``PatternCutVecEnv.step``)
  4. rsl-rl step + torch conversions and the TensorDict (``PatternCutRslEnv.step``)
  5. collection  + the policy's forward pass, sampling and rollout storage (rsl-rl's runner)
  6. iteration   + the learner's update (collection + learning)

Layers 1-4 play a fixed continuous pull (the env's default actions); layers 5-6 train the ``--algo``
learner with its own actions (PPO: discrete moves). With ``--profile``, a cProfile of layer 4 (the functions
with the largest own time) and of the training run.

Run: python scripts/step_profile.py [--envs 256] [--repeats 5] [--iterations 6] [--algo ppo|es] [--profile]
"""

from __future__ import annotations

import argparse
import cProfile
import dataclasses
import io
import pstats
import statistics
import tempfile
import time

import numpy as np
import torch
from gymnasium.vector import AutoresetMode

from agents.algorithms import algorithm
from agents.config import TrainConfig
from agents.training import train, training_env
from envs.options import PatternCutOptions
from envs.rsl import PatternCutRslEnv
from envs.vector import PatternCutVecEnv


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
    options = PatternCutOptions(contour="fls-circle", action_type="continuous")
    vec = PatternCutVecEnv(num_envs, options, autoreset_mode=AutoresetMode.SAME_STEP)
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

    rsl = PatternCutRslEnv(PatternCutVecEnv(num_envs, options, autoreset_mode=AutoresetMode.SAME_STEP))
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


def learning(algo: str, num_envs: int, iterations: int) -> tuple[dict[str, float], cProfile.Profile]:
    """Layers 5 and 6: ``algo`` training on its own actions, no validation, the iterations after the first."""
    cfg = TrainConfig(algo=algo, num_envs=num_envs, iterations=iterations, save_interval=10**6)
    if algo == "es":  # the default population where it divides the batch, else the largest even one that does
        largest = min(num_envs, cfg.es.population)
        population = max(p for p in range(2, largest + 1, 2) if num_envs % p == 0)
        cfg = dataclasses.replace(cfg, es=dataclasses.replace(cfg.es, population=population))
    options = PatternCutOptions(contour="fls-circle", action_type=algorithm(algo).action_type)
    profile = cProfile.Profile()
    with tempfile.TemporaryDirectory() as out:
        env = training_env(options, cfg)
        steps = cfg.ppo.num_steps_per_env if algo == "ppo" else int(env.max_episode_length)
        profile.enable()
        summary = train(env, cfg, out, progress=False)
        profile.disable()
    steady = summary["history"][1:] or summary["history"]
    per_iteration = num_envs * steps
    collect = statistics.median(per_iteration / m["collection_steps_per_s"] for m in steady)
    whole = statistics.median(per_iteration / m["iteration_steps_per_s"] for m in steady)
    name = algo.upper() if algo != "es" else "es"
    return {
        f"5. {name} collection": 1e6 * collect / steps,
        f"6. {name} iteration": 1e6 * whole / steps,
    }, profile


def top(profile: cProfile.Profile, count: int = 15) -> str:
    text = io.StringIO()
    pstats.Stats(profile, stream=text).sort_stats("tottime").print_stats(count)
    return "\n".join(line for line in text.getvalue().splitlines() if line.strip())


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--envs", type=int, default=256, help="the batch (default 256, the training batch)")
    parser.add_argument("--repeats", type=int, default=5, help="timed episodes per layer, the median kept")
    parser.add_argument("--iterations", type=int, default=6, help="training iterations (the first not timed)")
    parser.add_argument("--algo", default="ppo", choices=["ppo", "es"], help="the learner of layers 5-6")
    parser.add_argument("--profile", action="store_true", help="print the cProfile tables too")
    parser.add_argument("--torch-threads", type=int, default=None, help="default: torch's (the CLI's)")
    args = parser.parse_args()
    if args.torch_threads:
        torch.set_num_threads(args.torch_threads)
    times, env_profile, _ = layers(args.envs, args.repeats)
    learn_times, learn_profile = learning(args.algo, args.envs, args.iterations)
    times.update(learn_times)
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
        print(f"\ncProfile of the {args.algo} run (own time):\n" + top(learn_profile, 25))
