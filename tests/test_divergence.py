"""Nothing a user made is lost, and no wrong result is reported as right: batches too big for
memory are refused before they are allocated, blow-ups are detected and never scored, absurd physical
parameters and non-finite pinch points are rejected in one line, a corrupt Warp kernel cache is named."""

import os
import re
import shutil
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from click.testing import CliRunner

from agents.cli import main
from agents.evaluation import Method, MethodResult, compare_policies, evaluate_suite, run_method
from envs import ENV_ID, PatternCutEnv, PatternCutVecEnv
from warpcut import SimConfig, Simulator
from warpcut.contours import load_contour
from warpcut.sim.config import ConfigError
from warpcut.sim.memory import MEMORY_LIMIT_ENV, batch_bytes, memory_limit
from warpcut.task import CuttingTask, SimulationDiverged

SMALL = SimConfig(resolution=9)
CONTOUR = load_contour("circle-small")
PAPER = {"action_type": "discrete", "allow_z": False, "contour_features": False, "dense_reward": False}
ENV = {"contour": "circle-small", "resolution": 9, "device": "cpu", **PAPER}
"""The paper's env on a small sheet: x-y moves of 1 mm (1: +x), 12 fiducials observed, the final reward."""


def invoke(args):
    """Run the CLI in-process: (exit code, stdout, stderr)."""
    result = CliRunner().invoke(main, args, standalone_mode=True, catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def one_line_error(stderr: str) -> str:
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr
    return lines[0]


# ------------------------------------------------------------------ 1. memory


def test_batches_too_big_for_memory_are_refused_naming_the_parameter(monkeypatch, tmp_path):
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "0.01")  # 10 MB: ~80 envs of 25 x 25
    assert memory_limit() == (1e7, f"{MEMORY_LIMIT_ENV}=0.01")
    config = SimConfig()
    with pytest.raises(
        ValueError,
        match=r"^num_envs: 1000 envs would need about 0\.\d+ GB \(\d+ kB per env\).* use at most \d+",
    ):
        Simulator(config, 1000, device="cpu")
    with pytest.raises(
        ValueError, match=r"^num_envs: 500 envs .*GB.*0\.01 GB allowed .*WARPCUT_MEMORY_LIMIT_GB"
    ):
        CuttingTask(config, CONTOUR, num_envs=500, device="cpu")
    with pytest.raises(ValueError, match=r"^num_envs: 400 envs"):
        PatternCutVecEnv(400, contour="circle-small", device="cpu")
    with pytest.raises(ValueError, match=r"^trials: 300 x 2 = 600 envs .* use at most \d+"):
        run_method([CONTOUR, CONTOUR], [None, None], None, 300, config, "cpu", 0)
    code, _, stderr = invoke(
        ["simulate", "--contour", "circle-small", "--trials", "1000", "--device", "cpu",
         "--set", "plots=false", "--json", str(tmp_path / "r.json")]
    )  # fmt: skip
    assert code == 2 and one_line_error(stderr).startswith("error: trials: 1000 envs would need")
    # A batch that fits runs, under the same limit.
    assert CuttingTask(SimConfig(resolution=9), CONTOUR, num_envs=4, device="cpu").num_envs == 4


def test_the_memory_limit_reads_the_machine_or_a_valid_override(monkeypatch):
    monkeypatch.delenv(MEMORY_LIMIT_ENV, raising=False)
    limit, source = memory_limit()
    assert 0 < limit < float("inf") and "memory" in source
    for bad in ("lots", "-1", "0", "nan"):
        monkeypatch.setenv(MEMORY_LIMIT_ENV, bad)
        with pytest.raises(ValueError, match=f"^{MEMORY_LIMIT_ENV}: must be a positive number of GB"):
            memory_limit()
    # The estimate: about 112 kB per env measured for a 25 x 25 sheet and a 160-update cut.
    assert 100e3 < batch_bytes(1, 625, 160) < 130e3


# ------------------------------------------------------------------ 2. blow-ups


@pytest.mark.usefixtures("unbounded_noise")
@pytest.mark.parametrize("backend", ["simd", "colours"])
def test_a_blow_up_is_flagged_and_never_scored(backend):
    # env 1 overflows to NaN, env 2 flings vertices kilometres away (finite), env 0 is fine
    config = SMALL.replace(noise_std=[0.03, 1e30, 1e6])
    task = CuttingTask(config, CONTOUR, num_envs=3, device="cpu", backend=backend)
    score = task.run(None)
    path = task.cut_path().copy()
    np.testing.assert_array_equal(task.diverged(), [False, True, True])
    assert task.divergence_reasons() == [
        None,
        "non-finite vertex positions",
        "vertices flung far from the sheet",
    ]
    np.testing.assert_array_equal(score.diverged, [False, True, True])
    for values in (score.error_vertices, score.error_mm2, score.path_error_mm2, score.separated_error_mm2):
        assert np.isfinite(values[0]) and np.all(np.isnan(values[1:]))
    assert not score.separated[1:].any() and score.info()["diverged"].tolist() == [False, True, True]
    task.score()
    np.testing.assert_array_equal(task.cut_path(), path)  # scoring left the simulator's own path alone
    task.reset()  # a reset clears the flags
    assert not task.diverged().any()


def test_a_sane_noisy_run_is_not_flagged():
    task = CuttingTask(SimConfig(resolution=13, noise_std=0.3), CONTOUR, num_envs=4, device="cpu", seed=1)
    score = task.run(None)
    assert not task.diverged().any() and np.isfinite(score.error_vertices).all()
    assert score.info()["diverged"].tolist() == [False] * 4


def test_a_sheet_the_springs_cannot_hold_is_refused_and_episodes_stay_short():
    # gravity * dt^2 = 25.6 mm per update: the "settled" sheet hangs 196 mm below its clips
    with pytest.raises(
        SimulationDiverged, match=r"^simulation diverged while settling .*gravity 100000 .*lower"
    ):
        CuttingTask(SimConfig(gravity=1e5), CONTOUR, device="cpu")
    with pytest.raises(SimulationDiverged, match="while settling"):
        Simulator(SMALL.replace(gravity=1e5, dt=0.1), 2, device="cpu").reset()
    # what settles keeps an episode about as long as the contour (~1 update per mm)
    task = CuttingTask(SimConfig(gravity=2e4), CONTOUR, device="cpu")  # sags 74 mm
    assert task.horizon_updates < 1.3 * CONTOUR.length


def test_huge_dt_or_gravity_are_rejected_in_one_line():
    for field, value in (("gravity", 1e9), ("gravity", -521.0), ("dt", 100.0), ("dt", [0.016, 2.0])):
        with pytest.raises(ConfigError, match=rf"^SimConfig\.{field}: a number in") as error:
            CuttingTask(SimConfig(**{field: value}), CONTOUR, num_envs=2, device="cpu")
        assert "\n" not in str(error.value)
    for noise in (1e300, 1000.0, [0.03, 1.5]):  # ten sheets of noise is not a sheet of gauze
        with pytest.raises(ConfigError, match=r"^SimConfig\.noise_std: a number in \[0, 1\] mm.* \(got "):
            SimConfig(noise_std=noise).validated()
    SimConfig(noise_std=[0.0, 1.0]).validated()  # the bound itself is accepted
    with pytest.raises(ConfigError, match=r"^SimConfig\.width_mm: a number > 0 mm \(got inf\)"):
        SimConfig(width_mm=float("inf")).validated()


@pytest.mark.usefixtures("unbounded_noise")
def test_the_single_env_ends_a_diverged_episode_with_zero_observation_and_nan_score():
    env = PatternCutEnv(noise_std=1e30, **{**ENV, "contour_features": True})
    obs, _ = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(1)
    assert terminated and not truncated and reward == 0.0 and info["diverged"] is True
    assert np.all(obs == 0.0) and obs in env.observation_space
    assert np.isnan(info["error_vertices"]) and np.isnan(info["relative_error"])
    with pytest.raises(RuntimeError, match="episode is over"):
        env.step(1)
    obs, _ = env.reset(seed=1)
    assert np.isfinite(obs).all()
    # through gym.make as well
    env = gym.make(ENV_ID, noise_std=1e30, **ENV)
    env.reset(seed=0)
    assert env.step(0)[4]["diverged"] is True


@pytest.mark.usefixtures("unbounded_noise")
def test_the_vector_env_terminates_only_the_diverged_env():
    vec = PatternCutVecEnv(3, noise_std=[0.03, 1e30, 0.03], autoreset_mode="same_step", **ENV)
    vec.reset(seed=0)
    obs, rewards, terminated, truncated, info = vec.step(np.array([1, 1, 1]))
    assert terminated.tolist() == [False, True, False] and not truncated.any()
    assert info["diverged"].tolist() == [False, True, False] and info["_diverged"].all()
    assert info["_final_obs"].tolist() == [False, True, False] and np.all(info["final_obs"][1] == 0.0)
    assert info["final_info"]["diverged"].tolist() == [False, True, False]
    assert "error_mm2" not in info["final_info"]  # no score for an episode that diverged
    assert np.all(obs[1] == 0.0) and np.isfinite(obs).all() and np.all(rewards == 0.0)
    steps = 1
    while True:
        obs, rewards, terminated, truncated, info = vec.step(np.array([1, 1, 1]))
        steps += 1
        assert np.isfinite(obs).all() and np.isfinite(rewards).all()
        if terminated.any():
            break
        assert np.all(obs[1] == 0.0) and rewards[1] == 0.0 and not terminated[1]  # idles
    assert steps == vec.scene.episode_steps and terminated.all()
    final = info["final_info"]
    assert info["_final_info"].tolist() == [True, False, True] == info["_final_obs"].tolist()
    assert np.isfinite(final["error_mm2"][[0, 2]]).all() and np.isnan(final["error_mm2"][1])
    assert final["diverged"].tolist() == [False, True, False] and rewards[1] == 0.0
    assert np.isfinite(rewards).all()
    # the new episode starts clean
    assert np.isfinite(obs).all() and not vec.scene.diverged.any()


@pytest.mark.usefixtures("unbounded_noise")
def test_evaluation_counts_diverged_trials_and_stops_with_one_line(tmp_path):
    with pytest.raises(
        SimulationDiverged,
        match=r"^none: simulation diverged in 2 of 2 trials of circle-small \(non-finite vertex positions\);"
        r".*lower noise_std \(now 1e\+30 mm per update\)",
    ):
        compare_policies(
            CONTOUR, ["none", "fixed"], trials=2, config=SMALL.replace(noise_std=1e30), device="cpu"
        )
    # a result run elsewhere (e.g. rl) with NaN errors is counted too, never averaged
    nan_result = MethodResult(np.array([[1.0, np.nan]]), np.array([[1.0, np.nan]]), [None])
    assert nan_result.diverged_trials().tolist() == [[False, True]]
    with pytest.raises(
        SimulationDiverged, match=r"^rl: simulation diverged in 1 of 2 trials of circle-small"
    ):
        evaluate_suite([CONTOUR], [Method("rl", result=nan_result)], trials=2, config=SMALL, device="cpu")
    code, _, stderr = invoke(
        ["simulate", "--contour", "circle-small", "--policy", "none", "--set", "sim.noise_std=1.0e+30",
         "--set", "sim.resolution=9", "--device", "cpu", "--set", "plots=false",
         "--json", str(tmp_path / "r.json")]
    )  # fmt: skip
    assert code == 2 and "simulation diverged in 1 of 1 trials of circle-small" in one_line_error(stderr)
    assert not (tmp_path / "r.json").exists()


# ------------------------------------------------------------------ 4. kernel cache


def test_a_corrupt_kernel_cache_is_named_in_one_line(tmp_path):
    import warp as wp

    wp.init()
    Simulator(SimConfig(resolution=5, settle_updates=1), 1, device="cpu").reset()  # in the cache now
    source = wp.config.kernel_cache_dir
    cache = tmp_path / "cache"
    target = cache / os.path.basename(source)  # WARP_CACHE_PATH/<warp version>
    # the module the first launch needs (builds in progress elsewhere end in _p<pid>_t<thread>)
    modules = [
        d for d in os.listdir(source) if re.fullmatch(r"wp_warpcut\.sim\.kernels_simd_L8_[0-9a-f]+", d)
    ]
    assert modules
    for name in modules:
        shutil.copytree(os.path.join(source, name), target / name)
    for path in target.rglob("*"):  # truncated binaries, garbled metadata
        if path.suffix == ".o" or path.suffix.startswith(".cu") or path.suffix in (".ptx", ".cubin"):
            path.write_bytes(path.read_bytes()[:100])
        elif path.suffix == ".meta":
            path.write_text("{garbage")
    env = dict(os.environ, WARP_CACHE_PATH=str(cache))
    env.pop("WARPCUT_VERBOSE", None)
    proc = subprocess.run(
        [sys.executable, "-m", "warpcut", "simulate", "--contour", "circle-small", "--policy", "none",
         "--set", "sim.resolution=5", "--device", "cpu", "--set", "plots=false",
         "--json", str(tmp_path / "r.json")],
        env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    line = one_line_error(proc.stderr)
    assert "Warp kernels: could not load module 'warpcut.sim.kernels_simd_L8'" in line
    assert str(target) in line and "delete that directory (rm -rf" in line


# ------------------------------------------------------------------ 5. no fiducials


def test_envs_without_fiducials_observe_time_and_grasp():
    env = PatternCutEnv(num_fiducials=0, **ENV)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.shape == (4,) and obs in env.observation_space
    obs, reward, *_ = env.step(1)
    assert obs.shape == (4,) and obs[1] > 0  # the grasp moved +x
    vec = PatternCutVecEnv(2, num_fiducials=0, **{**ENV, "contour_features": True})
    obs, _ = vec.reset(seed=0)
    assert obs.shape == (2, 11) and obs in vec.observation_space
    with pytest.raises(ValueError, match=r"^PatternCutOptions\.num_fiducials: an integer >= 0 \(got -1\)"):
        PatternCutEnv(num_fiducials=-1, **ENV)


# ------------------------------------------------------------------ 6. pinch points


@pytest.mark.parametrize("point", [(np.nan, 50.0), (np.inf, np.inf), (50.0, -np.inf), (np.nan, np.nan)])
def test_non_finite_pinch_points_are_rejected(point):
    with pytest.raises(ValueError, match=r"^pinch_points: .*pinch point .* is not finite"):
        CuttingTask(SMALL, CONTOUR, num_envs=2, pinch_points=point, device="cpu")
    with pytest.raises(ValueError, match=r"^PatternCutOptions\.pinch_point: a finite point .*\(got \("):
        PatternCutEnv(pinch_point=point, **ENV)
    with pytest.raises(ValueError, match=r"^pinch_point: circle-small's pinch point .* is not finite"):
        compare_policies(CONTOUR, ["none", "fixed"], config=SMALL, pinch=point, device="cpu")


def test_a_half_finite_pinch_row_is_rejected_and_a_nan_row_still_means_no_grasp():
    with pytest.raises(ValueError, match=r"^pinch_points: env 1's pinch point \[nan, 40\.0\] is not finite"):
        CuttingTask(SMALL, CONTOUR, num_envs=2, pinch_points=[[50.0, 40.0], [np.nan, 40.0]], device="cpu")
    sim = Simulator(SMALL, 2, device="cpu")
    with pytest.raises(ValueError, match=r"^pinch_points: env 0's pinch point \[inf, 40\.0\]"):
        sim.reset(np.array([[np.inf, 40.0], [50.0, 50.0]]))
    task = CuttingTask(
        SMALL, CONTOUR, num_envs=2, pinch_points=[[50.0, 40.0], [np.nan, np.nan]], device="cpu",
        allow_infeasible_pinch=True,
    )  # fmt: skip
    task.reset()
    assert task.sim.grasped.tolist() == [True, False]


def test_planning_never_chooses_a_diverged_candidate(monkeypatch):
    import warpcut.planning.search as search
    from warpcut.contours import load_contour
    from warpcut.planning import plan_cut

    real = search.search_orders

    def with_a_blow_up(*args, **kwargs):
        orders, errors = real(*args, **kwargs)
        errors = errors.copy()
        errors[0, 0] = np.nan  # argmin would pick it
        return orders, errors

    monkeypatch.setattr(search, "search_orders", with_a_blow_up)
    with pytest.raises(SimulationDiverged, match="1 of .* trials of circle-small"):
        plan_cut(load_contour("circle-small"), SimConfig(resolution=13), num_candidates=2)
