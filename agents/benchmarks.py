"""How fast a learner trains: :func:`benchmark_training`, the training half of ``warpcut bench``."""

from __future__ import annotations

import dataclasses

from agents.config import TrainConfig
from agents.training import train, training_env
from envs.options import PatternCutOptions

BENCH_EPISODES = 3
"""Whole episodes the steady-state window of :func:`benchmark_training` covers."""


def benchmark_training(
    device: str | None = None, num_envs: int = 256, episodes: int = BENCH_EPISODES, algo: str = "ppo"
) -> dict[str, float]:
    """A learner's throughput training ``fls-circle`` on ``num_envs`` envs (PPO's recipe for ``ppo``: discrete
    moves), in steady state: the env steps of the iterations after the first (start-up, kernel loading and
    the first iteration's allocations excluded; no validation runs) over their time, as many iterations as
    cover ``episodes`` whole episodes. The steps that end an episode (scoring, resets) cost several times a
    step; a median over iterations would leave them out.

    - ``train_steps_per_s``: env steps per second of those iterations, collection + update;
    - ``train_collection_steps_per_s``: of their collection alone (policy forward passes, env steps,
      storage);

    and ``train_overall_steps_per_s``, the whole call's steps over its wall time (what a short run sees).
    """
    import tempfile

    from agents.algorithms import algorithm as entry

    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes: the steady state needs at least 1 whole episode (got {episodes!r})")
    options = PatternCutOptions(contour="fls-circle", device=device, action_type=entry(algo).action_type)
    cfg = TrainConfig(algo=algo, num_envs=num_envs, save_interval=10**6, validation_trials=0)
    env = training_env(options, cfg, batch=("--train-envs", "give --train-envs batches of at most {fits}"))
    per_iteration = cfg.to_rsl_rl(None, (0, 1), int(env.max_episode_length))["num_steps_per_env"]
    steady_iterations = -(-episodes * env.max_episode_length // per_iteration)
    cfg = dataclasses.replace(cfg, iterations=1 + steady_iterations)
    with tempfile.TemporaryDirectory() as out:
        summary = train(env, cfg, out, progress=False)
    steady = summary["history"][1:]
    steps = len(steady) * num_envs * per_iteration

    def rate(key: str) -> float:
        return steps / sum(num_envs * per_iteration / m[key] for m in steady)

    return {
        "train_steps_per_s": rate("iteration_steps_per_s"),
        "train_collection_steps_per_s": rate("collection_steps_per_s"),
        "train_overall_steps_per_s": float(summary["steps_per_s"]),
    }
