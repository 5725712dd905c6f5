"""``warpcut bench``: simulator and training throughput."""

from __future__ import annotations

from pathlib import Path

import click

from agents.algorithms import DEFAULT_ALGORITHM
from agents.cli import options, outputs, settings
from warpcut import bench


@click.command("bench", cls=settings.Command)
@options.device_option
@options.count_option("repeats", bench.REPEATS, "Timed repeats (median).")
@click.option(
    "--batch-sizes",
    default=",".join(map(str, bench.BATCH_SIZES)),
    show_default=True,
    help="Comma-separated batch sizes.",
)
@options.count_option("rollout-envs", bench.ROLLOUT_ENVS, "Batch size of the fls-circle rollout measurement.")
@click.option(
    "--train-envs",
    default=",".join(map(str, bench.ENV_STEP_ENVS)),
    show_default=True,
    help="Comma-separated batch sizes of the tensioned env-step measurement and of training beside it (the "
    "default learner and PPO; gps and es need multiples of es's population, 64).",
)
@options.json_option
def command(
    device: str | None,
    repeats: int,
    batch_sizes: str,
    rollout_envs: int,
    train_envs: str,
    json_path: Path | None,
) -> None:
    """Measure simulator and training throughput (medians over repeats, all in one run): the simulator's
    updates and env steps, and the env steps of the default learner's training and of PPO's at the same
    batches, each also as a share of the simulator's own rate."""
    import functools

    from agents.benchmarks import benchmark_training

    outputs.check_outputs({"--json": json_path})
    train_envs_sizes = _sizes(train_envs, "--train-envs")
    learners = list(dict.fromkeys([DEFAULT_ALGORITHM, "ppo"]))
    _check_batches(learners, train_envs_sizes)
    result = bench.run_bench(
        device,
        repeats=repeats,
        batch_sizes=_sizes(batch_sizes, "--batch-sizes"),
        rollout_envs=rollout_envs,
        env_step_envs=train_envs_sizes,
        progress=lambda what: click.echo(f"  measuring {what} ...", err=True),
        training={algo: functools.partial(benchmark_training, device, algo=algo) for algo in learners},
    )
    result["default_learner"] = DEFAULT_ALGORITHM
    click.echo(f"device {result['device']} ({result['device_name']}), 25x25 sheet, median of {repeats}")
    click.echo(
        f"cold start (compile) {result['cold_start_s']:.2f} s, warm start {result['warm_start_s']:.2f} s"
    )
    click.echo(f"{'batch':>6} {'updates/s (default physics)':>38} {'updates/s (paper: 5 sweeps)':>28}")
    for b in result["updates_per_s"]:
        click.echo(
            f"{b:>6} {result['updates_per_s'][b]:>38,.0f} {result['updates_per_s_paper_sweeps'][b]:>28,.0f}"
        )
    for b, rate in result["updates_per_s_noise_free"].items():
        click.echo(f"default physics without process noise, B={b}: {rate:,.0f} updates/s")
    click.echo(
        f"fls-circle no-tension rollouts/s (B={result['rollout_envs']}): {result['rollouts_per_s']:,.1f} "
        f"default physics, {result['rollouts_per_s_paper_sweeps']:,.1f} paper sweeps; the path score adds "
        f"{result['scoring_overhead_pct']:.1f}%"
    )
    click.echo(
        f"NumPy reference updates/s: {result['numpy_updates_per_s']:,.1f}  "
        f"(Warp best / NumPy = {result['speedup_vs_numpy']:,.0f}x)"
    )
    for b, sim in result["sim_env_steps_per_s"].items():
        click.echo(f"env steps/s at {b} envs (tensioned fls-circle): simulator {sim:,.0f}")
        for algo, figures in result["training"].items():
            runs = ", ".join(f"{r:.0f}%" for r in figures["train_vs_sim_pct_runs"][b])
            name = f"{algo} (the default learner)" if algo == DEFAULT_ALGORITHM else algo
            click.echo(
                f"  {name} training in steady state {figures['train_steps_per_s'][b]:,.0f} "
                f"({figures['train_vs_sim_pct'][b]:.0f}% of the simulator around each run, median of {runs}; "
                f"collection alone {figures['train_collection_steps_per_s'][b]:,.0f}; a whole short run "
                f"{figures['train_overall_steps_per_s'][b]:,.0f})"
            )
    if json_path:
        from warpcut.io import write_json

        write_json(json_path, result)
        click.echo(f"wrote {json_path}")


def _sizes(text: str, hint: str) -> tuple[int, ...]:
    """Positive batch sizes from comma-separated ``text``; ``click.BadParameter`` naming ``hint``."""
    try:
        sizes = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise click.BadParameter(
            f"expected integers like 1,64,1024 (got {text!r})", param_hint=hint
        ) from None
    if not sizes or min(sizes) < 1:
        raise click.BadParameter("batch sizes must be positive", param_hint=hint)
    return sizes


def _check_batches(learners: list[str], sizes: tuple[int, ...]) -> None:
    """Refuse, before any work, a batch of ``--train-envs`` that a learner cannot train on (es: its population
    must divide it)."""
    from agents.algorithms import algorithm
    from agents.config import TrainConfig

    for algo in learners:
        for size in sizes:
            try:
                TrainConfig(algo=algo, num_envs=size).check()
            except ValueError as error:
                raise click.BadParameter(
                    f"{size}: {algo} cannot train on {size} envs ({str(error).split('; ')[0]}); give batches "
                    f"it trains on, e.g. its default {algorithm(algo).num_envs}",
                    param_hint="--train-envs",
                ) from None
