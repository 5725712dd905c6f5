"""Stable-Baselines3 on the Warp batch (:mod:`envs.sb3`): the VecEnv contract, and PPO training through it
(small sheets, short cuts). Skipped without the ``sb3`` extra."""

import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.env_checker import check_env  # noqa: E402
from stable_baselines3.common.evaluation import evaluate_policy  # noqa: E402
from stable_baselines3.common.monitor import Monitor  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv  # noqa: E402

import envs  # noqa: E402
from envs import PatternCutEnv, PatternCutVecEnv  # noqa: E402
from envs.sb3 import PatternCutSB3Env, make_sb3_env  # noqa: E402

pytestmark = pytest.mark.usefixtures("one_torch_thread")

ROOT = Path(__file__).resolve().parents[1]

PAPER = {"action_type": "discrete", "contour_features": False, "allow_z": False, "dense_reward": False}
"""The paper's env: x-y moves of 1 mm (``Discrete(5)``), 12 fiducials observed, the final reward alone."""
SMALL = {"contour": "circle-small", "resolution": 9, "device": "cpu", **PAPER}
"""A 9 x 9 sheet and a 94 mm contour: 48 steps per episode."""
STEPS = 48
OBS_DIM = 4 + 3 * 12
SCORE_KEYS = {"relative_error", "error_mm2", "error_vertices", "path_error_mm2", "separated"}


def test_steps_autoreset_and_infos_match_a_dummy_vec_env_of_single_envs():
    env = make_sb3_env(3, monitor=False, **SMALL)
    assert env.num_envs == 3 and env.action_space == gym.spaces.Discrete(5) and env.render_mode is None
    assert env.observation_space == env.env.single_observation_space
    obs = env.reset()
    assert obs.shape == (3, OBS_DIM) and obs.dtype == np.float32
    assert all(o in env.observation_space for o in obs)
    single = DummyVecEnv([lambda: PatternCutEnv(**SMALL)])
    single.reset()
    rng = np.random.default_rng(0)
    for k in range(STEPS):
        actions = rng.integers(0, 5, size=3)
        obs, rewards, dones, infos = env.step(actions)
        _, _, single_dones, single_infos = single.step(actions[:1])
        assert obs.shape == (3, OBS_DIM) and rewards.shape == (3,) and rewards.dtype == np.float32
        assert dones.dtype == bool and dones.tolist() == [k == STEPS - 1] * 3 == [bool(single_dones[0])] * 3
        assert len(infos) == 3 and all(sorted(info) == sorted(single_infos[0]) for info in infos)
        assert all(isinstance(info["cut_deviation_mm"], float) for info in infos)
    for i, info in enumerate(infos):
        assert SCORE_KEYS <= set(info) and info["TimeLimit.truncated"] is False
        assert info["relative_error"] == pytest.approx(-rewards[i]) and rewards[i] < 0.0
        terminal = info["terminal_observation"]
        assert terminal.shape == (OBS_DIM,) and terminal[0] == pytest.approx(1.0)  # the clock at the end
    assert np.all(obs[:, 0] == 0.0) and all(o in env.observation_space for o in obs)  # new episodes


def test_truncated_continuous_episodes_are_flagged_for_bootstrapping():
    env = make_sb3_env(2, monitor=False, max_episode_steps=2, **{**SMALL, "action_type": "continuous"})
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    env.reset()
    _, _, dones, infos = env.step(np.zeros((2, 2), dtype=np.float32))
    assert not dones.any() and not any(info["TimeLimit.truncated"] for info in infos)
    obs, rewards, dones, infos = env.step(np.ones((2, 2), dtype=np.float32))
    assert dones.all() and all(info["TimeLimit.truncated"] for info in infos) and np.all(rewards == 0.0)
    assert not SCORE_KEYS & set(infos[0])  # a truncated cut has no score
    assert infos[0]["terminal_observation"][0] == pytest.approx(2 / env.env.task.num_steps)
    assert np.all(obs[:, 0] == 0.0)


@pytest.mark.usefixtures("unbounded_noise")
def test_a_diverged_env_ends_alone_then_idles_until_the_batch_ends():
    env = PatternCutSB3Env(
        PatternCutVecEnv(3, autoreset_mode="same_step", noise_std=[0.03, 1e30, 0.03], **SMALL)
    )
    env.reset()
    obs, rewards, dones, infos = env.step(np.ones(3, dtype=np.int64))
    assert dones.tolist() == [False, True, False] and [i["diverged"] for i in infos] == [False, True, False]
    assert np.all(infos[1]["terminal_observation"] == 0.0) and infos[1]["TimeLimit.truncated"] is False
    assert "relative_error" not in infos[1] and "terminal_observation" not in infos[0]
    for _ in range(STEPS - 2):
        obs, rewards, dones, infos = env.step(np.ones(3, dtype=np.int64))
        assert not dones.any() and np.all(obs[1] == 0.0) and rewards[1] == 0.0
    obs, rewards, dones, infos = env.step(np.ones(3, dtype=np.int64))
    assert dones.all() and SCORE_KEYS <= set(infos[0]) and not SCORE_KEYS & set(infos[1])
    assert np.all(infos[1]["terminal_observation"] == 0.0) and infos[1]["TimeLimit.truncated"] is False
    assert np.isfinite(obs).all() and np.all(obs[:, 0] == 0.0)


def test_seeds_attributes_and_methods_act_on_the_one_batch():
    env = PatternCutSB3Env(PatternCutVecEnv(2, autoreset_mode="same_step", **SMALL))
    assert env.seed(3) == [3, 4]
    first = env.reset()
    env.seed(3)
    np.testing.assert_array_equal(env.reset(), first)
    env.seed(5)
    assert not np.array_equal(env.reset(), first) and not np.array_equal(first[0], first[1])
    assert env.get_attr("num_envs") == [2, 2] and env.get_attr("options", indices=[1]) == [env.options]
    assert env.has_attr("task") and not env.has_attr("no_such_attribute")
    env.set_attr("marker", 7)
    assert env.env.marker == 7 and env.env_is_wrapped(Monitor) == [False, False]
    obs, info = env.env_method("reset", seed=3)[0]
    np.testing.assert_array_equal(obs, first)
    with pytest.raises(ValueError, match="indices: the 2 envs are one batched"):
        env.set_attr("marker", 8, indices=[0])
    with pytest.raises(ValueError, match="indices"):
        env.env_method("reset", indices=1)
    with pytest.raises(RuntimeError, match="step_async"):
        env.step_wait()
    env.set_options({"pinch": 1})
    with pytest.raises(ValueError, match="reset: unknown options"):
        env.reset()
    assert env.reset().shape == (2, OBS_DIM)  # the options were used (and refused) once
    with pytest.raises(ValueError, match="env: expected an envs.PatternCutVecEnv"):
        PatternCutSB3Env(PatternCutEnv(**SMALL))
    with pytest.raises(ValueError, match="num_envs"):
        make_sb3_env(0, **SMALL)


def test_renders_the_batch_and_refuses_next_step_autoreset():
    env = make_sb3_env(2, monitor=False, render_mode="rgb_array", render_size=32, **SMALL)
    assert env.render_mode == "rgb_array"
    env.reset()
    images = env.get_images()
    assert len(images) == 2 and all(i.shape == (32, 32, 3) and i.dtype == np.uint8 for i in images)
    assert env.render().shape == (64, 32, 3)  # SB3 tiles them
    with pytest.warns(UserWarning, match="render_mode='rgb_array'"):
        assert make_sb3_env(2, monitor=False, **SMALL).get_images() == [None, None]
    with pytest.raises(ValueError, match="env: SB3 resets envs inside step.*SAME_STEP"):
        PatternCutSB3Env(PatternCutVecEnv(2, autoreset_mode="next_step", **SMALL))
    with pytest.raises(ValueError, match="env: SB3 resets envs inside step.*SAME_STEP"):
        PatternCutSB3Env(PatternCutVecEnv(2, **SMALL))  # the vector env's default, Gymnasium's: NEXT_STEP


@pytest.mark.parametrize("action_type", ["discrete", "continuous"])
def test_sb3_env_checker_passes_on_the_single_env(action_type):
    check_env(PatternCutEnv(**{**SMALL, "action_type": action_type}), warn=True)


@pytest.mark.parametrize("action_type", ["discrete", "continuous"])
def test_sb3_ppo_trains_on_the_batch(action_type):
    env = make_sb3_env(4, **{**SMALL, "action_type": action_type})
    model = PPO(
        "MlpPolicy", env, n_steps=64, batch_size=128, n_epochs=1, policy_kwargs={"net_arch": [16]}, seed=0
    )
    model.learn(total_timesteps=2048)  # 8 rollouts of 4 x 64 steps: across several 48-step episodes
    assert model.num_timesteps == 2048
    episodes = list(model.ep_info_buffer)
    assert len(episodes) == 4 * (2048 // 4 // STEPS) and {e["l"] for e in episodes} == {STEPS}
    assert all(e["r"] < 0.0 for e in episodes)
    returns, lengths = evaluate_policy(model, env, n_eval_episodes=4, return_episode_rewards=True)
    assert lengths == [STEPS] * 4 and all(np.isfinite(returns))


def test_ppo_builds_the_registered_env_from_its_id():
    """SB3 makes a string env with ``gym.make(id, render_mode="rgb_array")`` (retrying without only on a
    TypeError), so the single env must accept that render mode."""
    model = PPO("MlpPolicy", envs.ENV_ID, n_steps=128, batch_size=64, n_epochs=1, device="cpu", seed=0)
    model.learn(total_timesteps=256)
    assert model.num_timesteps == 256


def test_envs_import_without_sb3_and_the_adapter_says_what_to_install():
    code = (
        "import sys\n"
        "sys.modules['stable_baselines3'] = None  # as if not installed\n"
        "import envs\n"
        "try:\n"
        "    import envs.sb3\n"
        "except ImportError as error:\n"
        "    print(error)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert "pip install 'warpcut[sb3]'" in done.stdout, done.stdout + done.stderr


def test_the_batched_adapter_puts_torch_on_one_thread_beside_a_cpu_simulator():
    """The simulator's threads use the cores: torch's spinning beside them made SB3 about ten times slower
    on 2 cores, so make_sb3_env sets one torch thread on the CPU (and leaves torch alone when told)."""
    import torch

    from envs.sb3 import make_sb3_env

    before = torch.get_num_threads()
    try:
        torch.set_num_threads(2)
        make_sb3_env(2, torch_threads=None, **SMALL)
        assert torch.get_num_threads() == 2
        make_sb3_env(2, **SMALL)
        assert torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)
