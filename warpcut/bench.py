"""``warpcut bench``: throughput of the simulator, measured in one run so ratios are comparable.

Every figure is the median over ``repeats`` timed repetitions, after a warm-up. The machines this runs
on are shared and noisy: compare ratios measured in one run, not absolute figures across runs. What lies
above the simulator (the learners' training) is measured by the caller's ``training`` functions
(:func:`run_bench`).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Mapping

import numpy as np

from warpcut.sim.config import SimConfig

BATCH_SIZES = (1, 64, 1024, 4096)
"""Batch sizes of the update-rate measurements."""
REPEATS = 3
"""Timed repeats of each measurement (the median is reported)."""
ROLLOUT_ENVS = 256
"""Batch of the fls-circle rollout measurements."""
ENV_STEP_ENVS = (64, 256)
"""Batches of the tensioned env-step measurement (``sim_env_steps_per_s``) and of the learners' training
beside it: 64, a small training batch, and 256, the envs es and PPO train with by default
(``agents.algorithms``; docs/performance.md, section 6)."""
PAPER_SWEEPS = SimConfig(springs=("structural",), sweeps=5, chebyshev_rho=0.0, noise_std=0.0)
"""The paper's unit of work: one update = integrate + 5 structural relaxation sweeps,
without process noise (the authors' code had none)."""
NOISE_FREE = SimConfig(noise_std=0.0)
"""The default physics without its process noise: what the noise costs (one hashed draw per vertex)."""


def median_time(fn: Callable[[], None], repeats: int, sync: Callable[[], None]) -> float:
    """Median wall time (s) of ``fn`` over ``repeats`` runs, after one untimed warm-up."""
    fn()
    sync()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        sync()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def updates_per_second(
    config: SimConfig, num_envs: int, device: str, repeats: int, min_updates: int = 1, **sim_options
) -> float:
    """Env updates per second (``num_envs`` x updates / s) with cutting active somewhere on the sheet.
    ``sim_options`` go to :class:`Simulator` (e.g. ``capture=False``); default: its own choices."""
    from warpcut.sim._warp import wp
    from warpcut.sim.simulator import Simulator

    sim = Simulator(config, num_envs, device=device, **sim_options)
    sim.reset()
    sim.set_tip(np.tile([[50.0, 50.0, -15.0, 1.0]], (num_envs, 1)))
    # Enough updates per timing that launch latency and timer resolution do not dominate small batches.
    updates = max(min_updates, int(np.ceil(2048 / num_envs)))
    for _ in range(6):  # untimed: records the graphs of every buffer arrangement where capture is on
        sim.update()

    def run() -> None:
        for _ in range(updates):
            sim.update()

    return num_envs * updates / median_time(run, repeats, lambda: wp.synchronize_device(device))


def rollouts_per_second(num_envs: int, device: str, repeats: int, config: SimConfig | None = None) -> float:
    """Complete no-tension ``fls-circle`` rollouts per second; settling and trajectories are built once
    (amortised), the timed part is reset + every step + scoring (the path score included: traced every
    update). ``config``: default physics if None."""
    from warpcut.contours import load_contour
    from warpcut.sim._warp import wp
    from warpcut.task import CuttingTask

    task = CuttingTask(config or SimConfig(), load_contour("fls-circle"), num_envs=num_envs, device=device)
    return num_envs / median_time(lambda: task.run(None), repeats, lambda: wp.synchronize_device(device))


def env_steps_per_second(num_envs: int, device: str, repeats: int) -> float:
    """Env steps per second of a tensioned ``fls-circle`` cut (default physics, grasp at the centroid):
    a step is one grasp move plus the scissors' ``updates_per_step`` updates, as a training env steps the
    simulator (its observations and rewards not included). Timed: reset + every step."""
    from warpcut.contours import load_contour
    from warpcut.sim._warp import wp
    from warpcut.task import CuttingTask

    contour = load_contour("fls-circle")
    # A timing: the grasp at the centroid, under the arm, does the same work as a feasible one.
    task = CuttingTask(
        SimConfig(), contour, num_envs=num_envs, pinch_points=contour.centroid, device=device,
        allow_infeasible_pinch=True,
    )  # fmt: skip
    action = np.tile([[0.5, 0.0, 0.5]], (num_envs, 1))

    def rollout() -> None:
        task.reset()
        while not task.done:
            task.step(action)

    seconds = median_time(rollout, repeats, lambda: wp.synchronize_device(device))
    return num_envs * task.num_steps / seconds


def scoring_overhead_pct(num_envs: int, device: str, repeats: int) -> float:
    """What the path score adds to a no-tension ``fls-circle`` rollout (reset, every step, scoring), in %:
    tracing the tip through the mesh every update and scoring both ways, against the same rollout scored
    only by separated material. The two are timed alternately, ``2 * repeats + 1`` times each; the ratio of
    their medians."""
    from warpcut.contours import load_contour
    from warpcut.sim._warp import wp
    from warpcut.task import CuttingTask

    contour = load_contour("fls-circle")
    tasks = {
        traced: CuttingTask(
            SimConfig(score="path" if traced else "separated"),
            contour,
            num_envs=num_envs,
            device=device,
            trace_path=traced,
        )
        for traced in (True, False)
    }
    times: dict[bool, list[float]] = {True: [], False: []}
    for task in tasks.values():
        task.run(None)  # warm-up
    for _ in range(2 * repeats + 1):
        for traced, task in tasks.items():
            start = time.perf_counter()
            task.run(None)
            wp.synchronize_device(device)
            times[traced].append(time.perf_counter() - start)
    return 100.0 * (statistics.median(times[True]) / statistics.median(times[False]) - 1.0)


def numpy_updates_per_second(repeats: int) -> float:
    """Updates per second of the NumPy reference (one sheet, default physics without process noise)."""
    from warpcut.sim.reference import ReferenceSheet
    from warpcut.sim.simulator import Simulator

    config = SimConfig(noise_std=0.0)
    sim = Simulator(config, 1, device="cpu")
    sheet = ReferenceSheet(config, sim.settled_positions()[0])
    tip = np.array([50.0, 50.0, -15.0, 1.0], dtype=np.float32)
    updates = 20

    def run() -> None:
        for _ in range(updates):
            sheet.update(tip)

    return updates / median_time(run, repeats, lambda: None)


def start_times(device: str) -> dict[str, float]:
    """Seconds to import warpcut and run one update in a fresh process: with an empty kernel cache
    (cold: compiles the kernels) and again with the cache it filled (warm)."""
    code = (
        "import time; t = time.perf_counter(); import warpcut, numpy as np; "
        f"s = warpcut.Simulator(warpcut.SimConfig(settle_updates=1), 1, device={device!r}); s.reset_flat(); "
        "s.update(); import warp as wp; wp.synchronize(); print(time.perf_counter() - t)"
    )
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, WARP_CACHE_PATH=cache)
        for label in ("cold_start_s", "warm_start_s"):
            proc = subprocess.run(
                [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
            )
            out[label] = float(proc.stdout.strip().splitlines()[-1])
    return out


def run_bench(
    device: str,
    *,
    repeats: int = REPEATS,
    batch_sizes: tuple[int, ...] = BATCH_SIZES,
    rollout_envs: int = ROLLOUT_ENVS,
    env_step_envs: tuple[int, ...] = ENV_STEP_ENVS,
    progress: Callable[[str], None] = lambda _: None,
    training: Mapping[str, Callable[[int], dict[str, float]]] | None = None,
) -> dict:
    """Measure the simulator as ``warpcut bench`` reports it; then, if given, each learner of ``training``
    (``{name: training(num_envs)}``: what lies above the simulator, its steady-state figures,
    ``train_steps_per_s`` among them) at each batch of ``sim_env_steps_per_s`` (``env_step_envs``), into
    ``training[name]``, with ``train_vs_sim_pct``, its rate as a percentage of the simulator's at the same
    batch (:func:`_training_against_simulator`). Per-batch figures are dicts keyed by the batch, as
    ``updates_per_s``. Returns the JSON-ready dict."""
    from warpcut.sim._warp import wp
    from warpcut.sim.simulator import Simulator

    result: dict = {
        "device": device,
        "device_name": str(wp.get_device(device).name),
        "resolution": 25,
        "cpu_threads": os.cpu_count(),
        "repeats": repeats,
    }
    probe = Simulator(SimConfig(resolution=5, settle_updates=1), 1, device=device)
    result["backend"], result["graph_capture"] = probe.backend, probe.capture
    progress("cold and warm start")
    result.update(start_times(device))
    ups, ups_paper = {}, {}
    for b in batch_sizes:
        progress(f"updates/s at B={b}")
        with _named("--batch-sizes", b):
            ups[str(b)] = updates_per_second(SimConfig(), b, device, repeats)
            ups_paper[str(b)] = updates_per_second(PAPER_SWEEPS, b, device, repeats)
    result["updates_per_s"] = ups
    result["updates_per_s_paper_sweeps"] = ups_paper
    b = max(batch_sizes)
    progress(f"updates/s at B={b} without process noise")
    with _named("--batch-sizes", b):
        result["updates_per_s_noise_free"] = {str(b): updates_per_second(NOISE_FREE, b, device, repeats)}
    if probe.capture:
        # What the graphs save: the same updates launched one by one, at the largest batch.
        b = max(batch_sizes)
        progress(f"updates/s at B={b} without graph capture")
        with _named("--batch-sizes", b):
            result["updates_per_s_no_capture"] = {
                str(b): updates_per_second(SimConfig(), b, device, repeats, capture=False)
            }
    progress(f"fls-circle rollouts at B={rollout_envs}")
    result["rollout_envs"] = rollout_envs
    with _named("--rollout-envs"):
        result["rollouts_per_s"] = rollouts_per_second(rollout_envs, device, repeats)
        result["rollouts_per_s_paper_sweeps"] = rollouts_per_second(
            rollout_envs, device, repeats, PAPER_SWEEPS
        )
    result["sim_env_steps_per_s"] = {}
    for b in env_step_envs:
        progress(f"tensioned env steps at B={b}")
        with _named("--train-envs", b):
            result["sim_env_steps_per_s"][str(b)] = env_steps_per_second(b, device, repeats)
    progress(f"path-scoring overhead at B={rollout_envs}")
    with _named("--rollout-envs"):
        result["scoring_overhead_pct"] = scoring_overhead_pct(rollout_envs, device, repeats)
    progress("NumPy reference")
    result["numpy_updates_per_s"] = numpy_updates_per_second(repeats)
    best = max(ups.values())
    result["speedup_vs_numpy"] = best / result["numpy_updates_per_s"]
    if not training:
        return result
    result["training"] = {name: {} for name in training}
    for b in map(str, env_step_envs):
        names = " and ".join(training)
        progress(f"{names} training at B={b}, alternating with the simulator ({repeats} x)")
        with _named("--train-envs", b):
            result.update(_training_against_simulator(result, int(b), device, repeats, training))
    return result


def _named(option: str, size: int | str | None = None):
    """A measurement's batch, named by the option that sizes it where it does not fit in memory."""
    from warpcut.sim.memory import batch_named

    name = option if size is None else f"{option} (B={size})"
    return batch_named(name, f"give {option} of at most {{fits}}")


def _training_against_simulator(
    result: dict,
    num_envs: int,
    device: str,
    repeats: int,
    training: Mapping[str, Callable[[int], dict[str, float]]],
) -> dict:
    """``repeats`` rounds of every learner's ``training[name](num_envs)``, each run between two measurements
    of the simulator's env-step rate at that batch (the first is the one already in ``result``); the learners
    take turns within a round, so a drift hits them alike. On a shared machine the rate drifts by tens of
    percent within minutes, so each run is compared with the simulator just before and after it:
    ``train_vs_sim_pct`` is the median over a learner's runs of its rate as a percentage of that pair's mean
    (``train_vs_sim_pct_runs``: each run's). ``sim_env_steps_per_s`` becomes the median of every simulator
    measurement at the batch; ``training[name]`` holds the learner's figures, medians over its runs, each a
    dict keyed by the batch."""
    b = str(num_envs)
    sims = [result["sim_env_steps_per_s"][b]]
    runs: dict[str, list[dict]] = {name: [] for name in training}
    ratios: dict[str, list[float]] = {name: [] for name in training}
    for _ in range(repeats):
        for name, learner in training.items():
            runs[name].append(learner(num_envs))
            sims.append(env_steps_per_second(num_envs, device, repeats))
            ratios[name].append(100 * runs[name][-1]["train_steps_per_s"] / ((sims[-2] + sims[-1]) / 2))
    trained = {
        name: {k: dict(v) for k, v in figures.items()} for name, figures in result.get("training", {}).items()
    }
    for name in training:
        figures = trained.setdefault(name, {})
        for key in runs[name][0]:
            figures.setdefault(key, {})[b] = statistics.median(run[key] for run in runs[name])
        figures.setdefault("train_vs_sim_pct", {})[b] = statistics.median(ratios[name])
        figures.setdefault("train_vs_sim_pct_runs", {})[b] = ratios[name]
    return {
        "sim_env_steps_per_s": {**result["sim_env_steps_per_s"], b: statistics.median(sims)},
        "training": trained,
    }
