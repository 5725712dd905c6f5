"""Gymnasium envs, the natively batched vector env and the rsl-rl adapter (small sheets, short cuts)."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode
from rsl_rl.runners import OnPolicyRunner

import envs
from envs import ENV_ID, PatternCutEnv, PatternCutVecEnv
from envs.observations import Fiducials
from envs.rsl import FINAL_ERROR_KEY, PatternCutRslEnv
from warpcut.contours import load_contour
from warpcut.sim.config import SheetGrid, SimConfig

SMALL = {"contour": "circle-small", "resolution": 9}
"""A 9 x 9 sheet and a 94 mm contour: 48 steps per episode."""
PAPER = {"action_type": "discrete", "contour_features": False, "allow_z": False, "dense_reward": False}
"""The paper's env (the defaults are the default learner's): x-y moves of 1 mm, fiducials only, the final
reward alone."""
OBS_DIM = 4 + 3 * 12
"""The paper's observation: the clock, the last move and 12 fiducials."""
CONTOUR_FEATURES = 7
"""What ``contour_features`` adds: the scissor tip, its cutting flag and the tracking error."""


@pytest.mark.parametrize(
    "options",
    [PAPER, {}],
    ids=["paper", "defaults"],
)
def test_check_env_passes_without_warnings(options):
    env = gym.make(ENV_ID, device="cpu", noise_std=0.05, **SMALL, **options)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=True)


def test_make_and_make_vec_build_the_registered_envs():
    """The defaults are the default learner's: contour features observed, continuous x-y-z moves; the
    vector env restarts as Gymnasium's own vector envs do (NEXT_STEP)."""
    env = gym.make(ENV_ID, device="cpu", **SMALL)
    assert isinstance(env.unwrapped, PatternCutEnv) and env.spec.id == ENV_ID
    assert env.observation_space.shape == (OBS_DIM + CONTOUR_FEATURES,)
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
    vec = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point", device="cpu", **SMALL)
    assert isinstance(vec, PatternCutVecEnv) and vec.num_envs == 3 and vec.task.num_envs == 3
    assert vec.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP is vec.autoreset_mode
    assert vec.action_space == gym.spaces.Box(-1.0, 1.0, (3, 3), np.float32)
    paper = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point", device="cpu", **SMALL,
                         **PAPER)  # fmt: skip
    assert paper.action_space == gym.spaces.MultiDiscrete([5, 5, 5])
    assert paper.single_observation_space.shape == (OBS_DIM,)
    assert isinstance(envs.make(num_envs=2, device="cpu", **SMALL), PatternCutVecEnv)
    with pytest.raises(TypeError, match="unknown option"):
        gym.make(ENV_ID, contuor="fls-circle")


def test_a_generated_contour_is_made_by_its_name():
    """``gym.make`` takes every way a contour is named, a generated one's name too: the env cuts the same
    contour the generator draws on its sheet, and stores it whole."""
    from warpcut.planning import generate_contours

    env = gym.make(ENV_ID, device="cpu", contour="gen-test-0-0003-open", resolution=13)
    env.reset(seed=0)
    (drawn,) = [
        c for c in generate_contours(4, "test", 0, SimConfig(resolution=13)) if c.name.endswith("open")
    ]
    cut = env.unwrapped.task.contours[0]
    assert cut.name == "gen-test-0-0003-open" and np.array_equal(cut.points, drawn.points)
    assert env.unwrapped.options.to_dict()["contour"]["name"] == "gen-test-0-0003-open"
    with pytest.raises(ValueError, match="names 2 contours; give one"):
        gym.make(ENV_ID, device="cpu", contour="gen-test-0:2", resolution=13)


STEP_INFO = ["cut_deviation_mm", "running_path_error_mm2"]


def test_vector_env_shapes_dtypes_and_discrete_moves(device):
    vec = PatternCutVecEnv(
        4,
        device=device,
        action_type="discrete",
        contour_features=True,
        allow_z=True,
        dense_reward=False,
        **SMALL,
    )
    obs, info = vec.reset(seed=0)
    assert (
        obs.shape == (4, OBS_DIM + CONTOUR_FEATURES)
        and obs.dtype == np.float32
        and obs in vec.observation_space
    )
    assert info["pinch_feasible"].all() and info["_pinch_feasible"].all() and "pinch_problem" not in info
    assert vec.single_action_space == gym.spaces.Discrete(7)
    obs, rewards, terminated, truncated, info = vec.step(np.array([1, 2, 3, 6]))
    assert (
        obs.shape == (4, OBS_DIM + CONTOUR_FEATURES)
        and obs.dtype == np.float32
        and obs in vec.observation_space
    )
    assert rewards.shape == (4,) and rewards.dtype == np.float64 and np.all(rewards == 0.0)
    assert terminated.dtype == bool and truncated.dtype == bool and not (terminated.any() or truncated.any())
    assert sorted(info) == sorted(STEP_INFO + [f"_{k}" for k in STEP_INFO])
    assert info["cut_deviation_mm"].shape == (4,) and info["_cut_deviation_mm"].all()
    deviation = np.nan_to_num(info["cut_deviation_mm"])
    np.testing.assert_allclose(
        info["running_path_error_mm2"], deviation * 2 * vec.task.config.trajectory_spacing_mm
    )
    moves = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, 0, -1]]
    np.testing.assert_allclose(vec.task.sim.displacements(), moves, atol=1e-6)
    np.testing.assert_allclose(obs[:, 0], 1 / vec.task.num_steps)
    np.testing.assert_allclose(obs[:, 1:4], np.array(moves) / 10.0, atol=1e-6)


def test_seeded_resets_repeat_and_fiducials_differ_between_envs():
    vec = PatternCutVecEnv(2, device="cpu", **SMALL, **PAPER)
    first, _ = vec.reset(seed=1)
    again, _ = vec.reset(seed=1)
    other, _ = vec.reset(seed=2)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first[:, 4:], other[:, 4:])
    assert not np.array_equal(first[0, 4:], first[1, 4:])
    np.testing.assert_array_equal(vec.reset(seed=[1, 2])[0], first)  # SyncVectorEnv's list for seed=1


def test_vector_autoreset_is_same_step_with_final_obs_and_score():
    vec = PatternCutVecEnv(
        2, device="cpu", contour=["circle-small", "edge-bite"], resolution=9, damping=[0.99, 0.98],
        autoreset_mode="same_step", **PAPER,
    )  # fmt: skip
    start, _ = vec.reset(seed=3)
    num_steps = vec.task.num_steps
    for _ in range(num_steps - 1):
        obs, rewards, terminated, truncated, info = vec.step(np.array([1, 3]))
        assert not terminated.any() and not truncated.any() and np.all(rewards == 0.0)
        assert "final_info" not in info and set(STEP_INFO) <= set(info)
    obs, rewards, terminated, truncated, info = vec.step(np.array([1, 3]))
    assert terminated.all() and not truncated.any()
    assert info["_final_obs"].all() and info["_final_info"].all() and info["final_obs"].dtype == object
    final = np.stack(info["final_obs"])
    assert final.shape == (2, OBS_DIM) and np.all(final[:, 0] == 1.0)
    score = info["final_info"]
    assert score["_error_mm2"].all()
    for key in ("path_error_vertices", "separated_error_vertices", "separated", "dropped_fraction"):
        assert score[key].shape == (2,)
    np.testing.assert_allclose(score["error_mm2"], score["path_error_mm2"])  # the default score
    areas = [load_contour(name).area_mm2 for name in ("circle-small", "edge-bite")]
    np.testing.assert_allclose(rewards, -score["error_mm2"] / areas)
    np.testing.assert_allclose(score["relative_error"], -rewards)
    # The returned observation already starts the next episode: same fiducials, settled sheet, no grasp move.
    np.testing.assert_array_equal(obs, start)
    assert vec.scene.step_index == 0
    obs, rewards, terminated, *_ = vec.step(np.array([2, 0]))
    assert obs[0, 0] == np.float32(1 / num_steps) and not terminated.any()
    np.testing.assert_allclose(vec.task.sim.displacements()[0], [-1, 0, 0], atol=1e-6)


def test_truncated_episodes_have_no_score_and_reset_in_the_same_step():
    vec = PatternCutVecEnv(
        2,
        device="cpu",
        max_episode_steps=3,
        resample_fiducials=True,
        autoreset_mode="same_step",
        **SMALL,
        **PAPER,
    )
    start, _ = vec.reset(seed=0)
    for _ in range(3):
        obs, rewards, terminated, truncated, info = vec.step(np.array([0, 0]))
    assert truncated.all() and not terminated.any() and np.all(rewards == 0.0)
    assert "error_mm2" not in info["final_info"] and info["_final_info"].all()
    assert set(STEP_INFO) <= set(info["final_info"])
    assert obs[0, 0] == 0.0 and not np.array_equal(obs[:, 4:], start[:, 4:])  # resampled fiducials


def test_fiducials_hidden_under_the_shaft_or_cut_away_keep_their_last_visible_position():
    grid = SheetGrid(11, 11, 100.0, 100.0)
    flat = np.column_stack([grid.material, np.zeros(grid.num_vertices)])[None]
    fiducials = Fiducials(grid, shaft_radius_mm=5.0)
    # 0: right of the tip, 2 mm off the shaft's axis; 1: left of the tip; 2: away from both.
    fiducials.material = np.array([[[70.0, 52.0], [30.0, 52.0], [55.0, 25.0]]])
    fiducials.reset(flat)
    alive = np.ones((1, grid.num_vertices), dtype=bool)
    tip = np.array([[50.0, 50.0, 0.0, 1.0]])
    seen = fiducials.track(flat + [0.0, 0.0, -3.0], alive, tip)
    assert fiducials.visible.tolist() == [[False, True, True]]
    np.testing.assert_allclose(seen[0], [[70.0, 52.0, 0.0], [30.0, 52.0, -3.0], [55.0, 25.0, -3.0]])
    alive[0, 2 * 11 + 5] = False  # the vertex at (50, 20), a corner of fiducial 2's cell
    tip_far = np.array([[0.0, 0.0, 50.0, 1.0]])
    seen = fiducials.track(flat + [0.0, 0.0, -6.0], alive, tip_far)
    assert fiducials.visible.tolist() == [[True, True, False]]
    np.testing.assert_allclose(seen[0], [[70.0, 52.0, -6.0], [30.0, 52.0, -6.0], [55.0, 25.0, -3.0]])


def test_a_fiducial_on_the_contour_is_cut_away_and_stays_put():
    vec = PatternCutVecEnv(1, device="cpu", num_fiducials=2, **SMALL, **PAPER)
    vec.reset(seed=0)
    contour = vec.task.contours[0]
    start = contour.points[np.argmax(contour.points[:, 0])]  # where the scissors enter
    fiducials = vec.scene.fiducials
    fiducials.material = np.array([[start, [85.0, 15.0]]])
    fiducials.reset(vec.task.sim.positions())
    first = vec.scene.observe()[0, 4:10]
    for _ in range(20):
        obs, *_ = vec.step(np.array([1]))  # pull +x: the whole sheet moves
        assert not fiducials.visible[0, 0] and fiducials.visible[0, 1]
        np.testing.assert_array_equal(obs[0, 4:7], first[:3])
    assert not np.allclose(obs[0, 7:10], first[3:])


@pytest.mark.parametrize(
    "field, value, message",
    [
        ("dense_reward", "no", r"dense_reward: True or False \(got 'no'\)"),  # a truthy string, not a flag
        ("allow_z", "false", "allow_z: True or False"),
        ("num_fiducials", True, r"num_fiducials: an integer >= 0 \(got True\)"),
        ("max_episode_steps", 2.5, "max_episode_steps: an integer >= 1, or None for the whole cut"),
        ("max_episode_steps", "3", "max_episode_steps: an integer >= 1"),
        ("shaft_radius_mm", "5", "shaft_radius_mm: a number >= 0 mm"),
        ("noise_std", "0.1", r"noise_std: a number in \[0, 1\] mm, or a list of one per env"),
        ("gravity", [1.0, "x"], "gravity: a number in .*, or a list of one per env"),
        ("noise_std", -1.0, r"noise_std: a number in \[0, 1\]"),
        ("contour", 123, "contour: a built-in name, a .json or .svg contour file"),
        ("pinch_point", [1, 2, 3], r"pinch_point: a finite point \[x_mm, y_mm\]"),
        ("sim_config", 5, "sim_config: a SimConfig, or a dict of its fields"),
    ],
)
def test_options_of_the_wrong_type_are_refused_by_name(field, value, message):
    for make in (PatternCutEnv, lambda **kw: PatternCutVecEnv(2, **kw)):
        with pytest.raises(ValueError, match=f"^PatternCutOptions.{message}"):
            make(device="cpu", **{**SMALL, field: value})
    with pytest.raises(
        ValueError, match="options: expected PatternCutOptions .* PatternCutOptions.from_dict"
    ):
        PatternCutEnv(options={"dense_reward": True})
    for num_envs in (0, -1, 2.0, True, "2"):
        with pytest.raises(ValueError, match=r"^PatternCutVecEnv\.num_envs: an integer >= 1"):
            PatternCutVecEnv(num_envs, device="cpu", **SMALL)


def test_stepping_before_the_first_reset_is_refused_and_info_keeps_its_types():
    env = PatternCutEnv(device="cpu", **SMALL, **PAPER)
    with pytest.raises(RuntimeError, match="step: call reset\\(\\) first"):
        env.step(0)
    assert env.scene.step_index == 0  # nothing was simulated
    env.reset(seed=0)
    terminated = False
    while not terminated:
        _, _, terminated, _, info = env.step(0)
    assert isinstance(info["separated"], bool) and isinstance(info["error_vertices"], int | float)
    assert isinstance(info["cut_deviation_mm"], float)


def test_invalid_actions_raise_and_continuous_actions_are_clipped():
    env = PatternCutEnv(device="cpu", **SMALL, **PAPER)
    env.reset(seed=0)
    for bad in (np.nan, 5, 1.5, -1):
        with pytest.raises(ValueError, match="action"):
            env.step(bad)
    vec = PatternCutVecEnv(2, device="cpu", action_type="continuous", allow_z=True, **SMALL)
    vec.reset(seed=0)
    with pytest.raises(ValueError, match=r"action: .*not finite \(env 1\)"):
        vec.step(np.array([[0.0, 0.0, 0.0], [0.0, np.nan, 0.0]]))
    obs, *_ = vec.step(np.array([[5.0, -0.5, 0.0], [-3.0, 0.0, 2.0]]))
    np.testing.assert_allclose(vec.task.sim.displacements(), [[1.0, -0.5, 0.0], [-1.0, 0.0, 1.0]], atol=1e-6)
    np.testing.assert_allclose(obs[:, 1:4], [[0.1, -0.05, 0.0], [-0.1, 0.0, 0.1]], atol=1e-6)


def test_sparse_reward_is_zero_until_the_last_step_then_minus_the_relative_error():
    env = gym.make(ENV_ID, device="cpu", **SMALL, **PAPER)
    env.reset(seed=0)
    rewards, terminated, info = [], False, {}
    while not terminated:
        _, reward, terminated, truncated, info = env.step(0)
        rewards.append(reward)
        assert not truncated
    task = env.unwrapped.task
    assert len(rewards) == task.num_steps and all(r == 0.0 for r in rewards[:-1])
    assert info["error_mm2"] == task.score().error_mm2[0] > 0
    assert rewards[-1] == pytest.approx(-info["error_mm2"] / task.contours[0].area_mm2)
    assert set(info) == {
        "error_vertices",
        "pinch_feasible",
        "error_mm2",
        "path_error_vertices",
        "path_error_mm2",
        "separated_error_vertices",
        "separated_error_mm2",
        "separated",
        "dropped_fraction",
        "missed_vertices",
        "excess_vertices",
        "relative_error",
        *STEP_INFO,
    }
    # The running path error (deviation x advance) approximates the path score's charge along the cut.
    assert info["running_path_error_mm2"] > 0


def test_separated_score_drives_the_reward_when_chosen():
    env = gym.make(ENV_ID, device="cpu", sim_config=SimConfig(score="separated"), **SMALL, **PAPER)
    env.reset(seed=0)
    terminated = False
    while not terminated:
        _, reward, terminated, _, info = env.step(0)
    assert info["error_mm2"] == info["separated_error_mm2"] != info["path_error_mm2"]
    assert reward == pytest.approx(-info["separated_error_mm2"] / env.unwrapped.task.contours[0].area_mm2)


def test_dense_reward_penalises_the_cut_deviation_every_step():
    env = PatternCutEnv(device="cpu", **SMALL, **{**PAPER, "dense_reward": True})
    env.reset(seed=0)
    steps = [env.step(1) for _ in range(20)]  # pulling +x drags the contour off the scissors' path
    rewards = [s[1] for s in steps]
    assert all(r <= 0.0 for r in rewards) and min(rewards) < 0.0
    scale = env.scene.config.max_displacement_mm * env.task.num_steps
    for _, reward, _, _, info in steps:
        assert reward == pytest.approx(-np.nan_to_num(info["cut_deviation_mm"]) / scale)


def test_rsl_adapter_steps_logs_and_resets_itself():
    env = PatternCutRslEnv(
        PatternCutVecEnv(3, device="cpu", autoreset_mode="same_step", **SMALL, **PAPER), seed=0
    )
    obs = env.get_observations()
    assert list(obs.keys()) == ["policy"] and obs["policy"].shape == (3, OBS_DIM)
    assert obs["policy"].dtype == torch.float32 and obs.batch_size == torch.Size([3])
    assert env.num_actions == 1 and env.num_action_choices == 5
    assert env.max_episode_length == env.env.task.num_steps
    for k in range(env.max_episode_length):
        actions = torch.randint(0, 5, (3, 1)).float() if k % 2 else torch.randint(0, 5, (3,))
        obs, rewards, dones, extras = env.step(actions)
        assert obs["policy"].shape == (3, OBS_DIM) and rewards.shape == (3,) and dones.shape == (3,)
        assert rewards.dtype == torch.float32 and dones.dtype == torch.long
        assert extras["time_outs"].dtype == torch.bool and extras["time_outs"].shape == (3,)
        if k < env.max_episode_length - 1:
            assert not dones.any() and "log" not in extras and env.episode_length_buf.tolist() == [k + 1] * 3
    assert dones.all() and not extras["time_outs"].any()  # a completed cut is terminal, not a time-out
    torch.testing.assert_close(rewards, -extras["log"][FINAL_ERROR_KEY])
    assert extras["log"]["Cut/error_mm2"].shape == (3,)
    assert env.episode_length_buf.tolist() == [0, 0, 0] and torch.all(obs["policy"][:, 0] == 0.0)
    with pytest.raises(ValueError, match="action"):
        env.step(torch.full((3, 1), 0.5))


def test_rsl_adapter_reports_time_outs_for_truncated_episodes():
    vec = PatternCutVecEnv(2, device="cpu", max_episode_steps=2, autoreset_mode="same_step", **SMALL,
                           **{**PAPER, "action_type": "continuous"})  # fmt: skip
    env = PatternCutRslEnv(vec)
    assert env.num_actions == 2 and env.num_action_choices is None and env.max_episode_length == 2
    for _ in range(2):
        _, _, dones, extras = env.step(torch.randn(2, 2))
    assert dones.tolist() == [1, 1] and extras["time_outs"].all() and "log" not in extras
    assert env.episode_length_buf.tolist() == [0, 0]
    with pytest.raises(ValueError, match="init_at_random_ep_len"):
        env.episode_length_buf = torch.zeros(2, dtype=torch.long)


def test_rsl_rl_ppo_runs_on_the_adapter():
    env = PatternCutRslEnv(PatternCutVecEnv(2, device="cpu", autoreset_mode="same_step", **SMALL))
    model = {"class_name": "rsl_rl.models:MLPModel", "hidden_dims": [8]}
    cfg = {
        "num_steps_per_env": 8,
        "save_interval": 100,
        "obs_groups": {"actor": ["policy"], "critic": ["policy"]},
        "actor": {**model, "distribution_cfg": {"class_name": "rsl_rl.modules:GaussianDistribution"}},
        "critic": model,
        "algorithm": {"class_name": "rsl_rl.algorithms:PPO", "num_learning_epochs": 1, "num_mini_batches": 1},
    }
    runner = OnPolicyRunner(env, cfg, log_dir=None, device="cpu")
    runner.learn(num_learning_iterations=7)  # 56 steps: across the end of a 48-step episode
    assert env.episode_length_buf.tolist() == [8, 8]


def test_segments_one_path_for_all_or_one_per_env():
    contour = load_contour("circle-small")
    right, left = contour.points[contour.points[:, 0] >= 36.0], contour.points[contour.points[:, 0] <= 36.0]
    shared = PatternCutVecEnv(2, contour="circle-small", resolution=9, segments=[right])
    assert shared.task.num_steps > 0
    per_env = PatternCutVecEnv(2, contour="circle-small", resolution=9, segments=[[right], [left[::-1]]])
    assert per_env.task.num_steps > 0
    with pytest.raises(ValueError, match="got 3 paths for 2 envs"):
        PatternCutVecEnv(2, contour="circle-small", resolution=9, segments=[[right]] * 3)
    with pytest.raises(ValueError, match=r"segments\[1\]: give a list of polylines"):
        PatternCutVecEnv(2, contour="circle-small", resolution=9, segments=[[right], [[[1.0, 2.0]]]])


def test_training_builds_its_rsl_env_with_same_step_autoreset_not_the_gym_default():
    """The vector env restarts as Gymnasium's do (NEXT_STEP, its default); rsl-rl resets inside ``step``,
    so the env a learner trains in is built with SAME_STEP, and the adapter refuses any other."""
    from agents.config import TrainConfig
    from agents.training import training_env
    from envs.options import PatternCutOptions
    from envs.rsl import EPISODE_COST_KEY

    options = PatternCutOptions(device="cpu", **SMALL)
    assert PatternCutVecEnv(2, options).autoreset_mode is AutoresetMode.NEXT_STEP
    with pytest.raises(ValueError, match="rsl-rl resets envs inside step.*SAME_STEP"):
        PatternCutRslEnv(PatternCutVecEnv(2, options))
    env = training_env(options, TrainConfig(num_envs=2))
    assert env.env.autoreset_mode is AutoresetMode.SAME_STEP and env.num_actions == 3
    for _ in range(env.max_episode_length):
        obs, _, dones, extras = env.step(torch.zeros(2, 3))
    assert dones.tolist() == [1, 1] and extras[EPISODE_COST_KEY].shape == (2,)
    assert torch.all(obs["policy"][:, 0] == 0.0)  # already the next episode's first observation
