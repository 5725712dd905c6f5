"""What the PPO update costs by its passes and minibatches: one rollout of PPO (its discrete moves) on
``fls-circle`` is collected, then updated again and again with each (epochs, minibatches) pair in turn, over
rounds; the median time of each pair after its first round. The same stored rollout for every pair, so only
the update differs. The figures in docs/performance.md, "The whole step path" (three passes over each
rollout).

Run: python scripts/update_passes.py [--envs 256] [--rounds 6] [--threads 2] [--pairs 5x4,3x4,5x2,4x2]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=256)
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--threads", type=int, default=2, help="torch threads during the update")
    parser.add_argument(
        "--pairs", default="5x4,5x2,4x4,3x4,4x2,5x1", help="epochs x minibatches, comma-separated"
    )
    args = parser.parse_args()
    pairs = [tuple(int(n) for n in pair.split("x")) for pair in args.pairs.split(",")]

    import torch

    from agents.config import TrainConfig
    from agents.runner import Runner
    from agents.training import training_env
    from envs.options import PatternCutOptions

    cfg = TrainConfig(algo="ppo", num_envs=args.envs, save_interval=10**6)
    env = training_env(PatternCutOptions(contour="fls-circle", action_type="discrete"), cfg)
    with tempfile.TemporaryDirectory() as out:
        runner = Runner(env, cfg.to_rsl_rl(env.num_action_choices), out, cfg.torch_device)
        runner.learn(1)  # collects the rollout that every update below reuses
        torch.set_num_threads(args.threads)
        times: dict[tuple[int, int], list[float]] = {pair: [] for pair in pairs}
        for _ in range(args.rounds):
            for pair in pairs:
                runner.alg.num_learning_epochs, runner.alg.num_mini_batches = pair
                start = time.perf_counter()
                runner.alg.update()
                times[pair].append(time.perf_counter() - start)
    samples = args.envs * cfg.ppo.num_steps_per_env
    print(
        f"PPO update of {samples:,} samples ({args.envs} envs x {cfg.ppo.num_steps_per_env} steps), "
        f"{args.threads} torch threads"
    )
    for (epochs, minibatches), values in times.items():
        kept = values[1:] or values
        print(
            f"  {epochs} epochs x {minibatches} minibatches: {1e3 * statistics.median(kept):6.1f} ms "
            f"(rounds: {', '.join(f'{1e3 * v:.0f}' for v in values)})"
        )


if __name__ == "__main__":
    main()
