"""``warpcut bench``: the simulator's throughput and, beside it at the same batches, the training throughput
of the default learner and of PPO, each also as a share of the simulator's own rate."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

import warpcut.bench as bench
from agents.algorithms import DEFAULT_ALGORITHM, algorithm
from agents.cli import main
from warpcut.sim.config import SimConfig

LEARNERS = {DEFAULT_ALGORITHM, "ppo"}
TRAINING_KEYS = (
    "train_steps_per_s",
    "train_collection_steps_per_s",
    "train_overall_steps_per_s",
    "train_vs_sim_pct",
    "train_vs_sim_pct_runs",
)


def invoke(args):
    result = CliRunner().invoke(main, args, standalone_mode=True, catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def assert_documented_json(result: dict, batches: set[str]) -> None:
    assert result["device"] == "cpu"
    assert set(result["updates_per_s"]) == {"1", "4"}
    for key in ("rollouts_per_s", "rollouts_per_s_paper_sweeps", "numpy_updates_per_s", "speedup_vs_numpy"):
        assert result[key] > 0, key
    assert result["speedup_vs_numpy"] == pytest.approx(
        max(result["updates_per_s"].values()) / result["numpy_updates_per_s"]
    )
    assert isinstance(result["scoring_overhead_pct"], float)  # may be negative at B = 2 (noise)
    assert set(result["updates_per_s_noise_free"]) == {"4"} and result["updates_per_s_noise_free"]["4"] > 0
    assert set(result["sim_env_steps_per_s"]) == batches and min(result["sim_env_steps_per_s"].values()) > 0
    assert result["default_learner"] == DEFAULT_ALGORITHM == "gps"
    assert set(result["training"]) == LEARNERS
    for learner, figures in result["training"].items():
        assert set(figures) == set(TRAINING_KEYS), learner
        for key in TRAINING_KEYS:
            assert set(figures[key]) == batches, (learner, key)
        for b in batches:
            (ratio,) = figures["train_vs_sim_pct_runs"][b]  # --repeats 1: one run between two simulator runs
            assert figures["train_vs_sim_pct"][b] == ratio > 0
            assert figures["train_steps_per_s"][b] > 0


def test_bench_reports_the_default_learners_and_ppos_training_beside_the_simulator(tmp_path, monkeypatch):
    """The command's printout and JSON, with the training runs and the start-up times stubbed (fast)."""
    import agents.benchmarks

    calls = []

    def training(device, num_envs, episodes=3, algo="ppo"):
        calls.append((algo, num_envs))
        rate = {"gps": 300.0, "ppo": 100.0}[algo]
        return {
            "train_steps_per_s": rate,
            "train_collection_steps_per_s": 2 * rate,
            "train_overall_steps_per_s": rate,
        }

    monkeypatch.setattr(agents.benchmarks, "benchmark_training", training)
    monkeypatch.setattr(bench, "start_times", lambda device: {"cold_start_s": 2.0, "warm_start_s": 1.0})
    monkeypatch.setattr(bench, "env_steps_per_second", lambda num_envs, device, repeats: 1000.0)
    out = tmp_path / "bench.json"
    args = ["bench", "--device", "cpu", "--batch-sizes", "1,4", "--rollout-envs", "2", "--train-envs", "64"]
    code, stdout, _ = invoke([*args, "--repeats", "1", "--json", str(out)])
    assert code == 0, stdout
    assert sorted(calls) == [("gps", 64), ("ppo", 64)]
    result = json.loads(out.read_text())
    assert_documented_json(result, {"64"})
    assert result["training"]["gps"]["train_vs_sim_pct"]["64"] == pytest.approx(30.0)
    assert result["training"]["ppo"]["train_vs_sim_pct"]["64"] == pytest.approx(10.0)
    assert "env steps/s at 64 envs (tensioned fls-circle): simulator 1,000" in stdout
    assert "gps (the default learner) training in steady state 300 (30% of the simulator" in stdout
    assert "ppo training in steady state 100 (10% of the simulator" in stdout


@pytest.mark.slow
def test_bench_writes_the_documented_json(tmp_path):
    out = tmp_path / "bench.json"
    args = ["bench", "--device", "cpu", "--batch-sizes", "1,4", "--rollout-envs", "2", "--train-envs", "64"]
    code, stdout, _ = invoke([*args, "--repeats", "1", "--json", str(out)])
    assert code == 0, stdout
    result = json.loads(out.read_text())
    assert_documented_json(result, {"64"})
    for key in ("cold_start_s", "warm_start_s"):
        assert result[key] > 0, key
    ppo = result["training"]["ppo"]
    assert ppo["train_collection_steps_per_s"]["64"] > ppo["train_steps_per_s"]["64"]  # + the update


@pytest.mark.parametrize("option", ["--batch-sizes", "--train-envs"])
@pytest.mark.parametrize("value", ["64,x", "0,64"])
def test_bench_names_a_bad_batch_list(option, value):
    code, stdout, stderr = invoke(["bench", option, value])
    assert code == 2 and option in stderr and "Traceback" not in stdout + stderr


def test_bench_refuses_a_batch_the_default_learner_cannot_train_on():
    """es's population must divide the batch: refused before anything is measured."""
    code, stdout, stderr = invoke(["bench", "--train-envs", "64,4"])
    assert code == 2 and not stdout
    assert (
        "--train-envs: 4: gps cannot train on 4 envs (train.gps.refine.population: 64 must divide "
        "num_envs (4)" in stderr
    )


def test_bench_measures_training_at_the_default_batches():
    """The env-step and training measurements include the batch es and PPO train with by default."""
    for learner in LEARNERS:
        assert algorithm(learner).num_envs in bench.ENV_STEP_ENVS


def test_bench_compares_each_run_with_the_simulator_around_it(monkeypatch):
    """Each learner's rate is a percentage of the simulator's measured just before and after each of its runs
    (a shared machine drifts; the learners take turns), and the median over runs is reported."""
    sims = iter([30.0, 50.0, 20.0, 40.0, 60.0, 30.0])  # measured after each run; 40.0 is the one before
    monkeypatch.setattr(bench, "env_steps_per_second", lambda num_envs, device, repeats: next(sims))
    rates = {"es": iter([9.0, 14.0, 8.0]), "ppo": iter([4.0, 5.0, 6.0])}
    order = []

    def learner(name):
        def run(num_envs):
            order.append(name)
            return {"train_steps_per_s": next(rates[name]), "other": 1.0}

        return run

    result = {"sim_env_steps_per_s": {"4": 40.0}, "training": {"es": {"train_steps_per_s": {"2": 1.0}}}}
    out = bench._training_against_simulator(result, 4, "cpu", 3, {"es": learner("es"), "ppo": learner("ppo")})
    assert order == ["es", "ppo"] * 3
    es = [100 * 9 / 35, 100 * 14 / 35, 100 * 8 / 50]  # the simulator around each: 40|30, 50|20, 40|60
    ppo = [100 * 4 / 40, 100 * 5 / 30, 100 * 6 / 45]  # 30|50, 20|40, 60|30
    assert out["training"]["es"]["train_vs_sim_pct_runs"]["4"] == pytest.approx(es)
    assert out["training"]["es"]["train_vs_sim_pct"]["4"] == pytest.approx(np.median(es))
    assert out["training"]["ppo"]["train_vs_sim_pct_runs"]["4"] == pytest.approx(ppo)
    assert out["sim_env_steps_per_s"] == {"4": 40.0}  # the median of 40, 30, 50, 20, 40, 60, 30
    assert out["training"]["es"]["train_steps_per_s"] == {"2": 1.0, "4": 9.0}
    assert out["training"]["ppo"]["other"] == {"4": 1.0}


@pytest.mark.parametrize("episodes", [0, 1.5, True])
def test_bench_training_names_a_bad_window(episodes):
    from agents.benchmarks import benchmark_training

    with pytest.raises(ValueError, match="episodes: the steady state needs at least 1 whole episode"):
        benchmark_training(num_envs=2, episodes=episodes)


def test_bench_times_the_captured_colours_update_on_cpu():
    """The path ``warpcut bench --device cuda`` takes (colours backend replayed from graphs) also runs on
    the CPU, so it is exercised without a GPU."""
    from warpcut.bench import updates_per_second

    rate = updates_per_second(
        SimConfig(resolution=7, settle_updates=2), 3, "cpu", 1, backend="colours", capture=True
    )
    assert np.isfinite(rate) and rate > 0
