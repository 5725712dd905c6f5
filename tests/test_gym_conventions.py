"""Gymnasium's conventions on the envs: the vector env's autoreset modes (and the vector wrappers that need
NEXT_STEP), Gymnasium's reset forms (seed lists, ``reset_mask``), and the registration's entry points."""

import subprocess
import sys
import textwrap
from importlib.metadata import entry_points

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from gymnasium.wrappers import vector as vector_wrappers

import envs
from envs import ENV_ID, PatternCutVecEnv

PAPER = {"action_type": "discrete", "contour_features": False, "allow_z": False, "dense_reward": False}
"""The paper's env: x-y moves of 1 mm (``Discrete(5)``), 12 fiducials observed (40 values), the final reward
alone."""
SMALL = {"contour": "circle-small", "resolution": 9, "device": "cpu", **PAPER}
"""A 9 x 9 sheet and a 94 mm contour: 48 steps per episode."""
STEPS = 48


def test_next_step_autoreset_ends_with_the_score_and_restarts_on_the_next_step():
    vec = PatternCutVecEnv(2, autoreset_mode="next_step", **SMALL)
    assert vec.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    start, _ = vec.reset(seed=3)
    for _ in range(STEPS - 1):
        obs, rewards, terminated, truncated, info = vec.step(np.array([1, 3]))
        assert not terminated.any() and "error_mm2" not in info
    obs, rewards, terminated, truncated, info = vec.step(np.array([1, 3]))
    assert terminated.all() and not truncated.any() and np.all(obs[:, 0] == 1.0)  # the final observations
    assert "final_obs" not in info and info["_error_mm2"].all() and info["_cut_deviation_mm"].all()
    np.testing.assert_allclose(rewards, -info["relative_error"])
    obs, rewards, terminated, truncated, info = vec.step(np.array([2, 2]))  # ignored: the reset step
    np.testing.assert_array_equal(obs, start)
    assert info == {} and np.all(rewards == 0.0) and not (terminated.any() or truncated.any())
    assert vec.scene.step_index == 0 and np.all(vec.task.sim.displacements() == 0.0)
    obs, *_ = vec.step(np.array([2, 0]))
    np.testing.assert_allclose(vec.task.sim.displacements()[0], [-1, 0, 0], atol=1e-6)


@pytest.mark.usefixtures("unbounded_noise")
def test_a_diverged_env_under_next_step_reports_once_then_idles_to_the_batch_end():
    vec = PatternCutVecEnv(3, autoreset_mode=AutoresetMode.NEXT_STEP, noise_std=[0.03, 1e30, 0.03], **SMALL)
    vec.reset(seed=0)
    obs, rewards, terminated, truncated, info = vec.step(np.ones(3, dtype=int))
    assert terminated.tolist() == [False, True, False] and "final_obs" not in info and np.all(obs[1] == 0)
    # its episode ended: a partial reset_mask naming it resets nothing (it restarts with the batch)
    same, _ = vec.reset(options={"reset_mask": np.array([False, True, False])})
    np.testing.assert_array_equal(same, obs)
    for _ in range(STEPS - 1):
        obs, rewards, terminated, truncated, info = vec.step(np.ones(3, dtype=int))
    assert terminated.all() and info["_error_mm2"].tolist() == [True, False, True]
    obs, rewards, terminated, *_ = vec.step(np.ones(3, dtype=int))
    assert not terminated.any() and np.isfinite(obs).all() and not vec.scene.diverged.any()


@pytest.mark.usefixtures("unbounded_noise")
@pytest.mark.parametrize("mode", ["same_step", "next_step"])
def test_an_env_that_diverged_is_terminated_at_a_truncated_batch_end_not_truncated(mode):
    """Diverging before the batch's episode is cut short, or on the step that cuts it short, ends that env
    (terminated: nothing to bootstrap); the envs still running are truncated."""
    import torch

    from envs.rsl import PatternCutRslEnv

    for first in ([0.03, 1e30, 0.03], [0.03, 0.03, 0.03]):  # diverging at step 1, or (set below) at step 3
        vec = PatternCutVecEnv(3, autoreset_mode=mode, noise_std=first, max_episode_steps=3, **SMALL)
        vec.reset(seed=0)
        for step in range(3):
            if step == 2 and not vec.scene.diverged.any():
                vec.task.sim.set_params(noise_std=np.array([0.03, 1e30, 0.03]))  # env 1 blows up at the end
            obs, rewards, terminated, truncated, info = vec.step(np.ones(3, dtype=int))
        assert terminated.tolist() == [False, True, False] and truncated.tolist() == [True, False, True]
        assert info["diverged"].tolist() == [False, True, False]
    rsl = PatternCutRslEnv(
        PatternCutVecEnv(
            3, autoreset_mode="same_step", noise_std=[0.03, 1e30, 0.03], max_episode_steps=3, **SMALL
        )
    )
    for _ in range(3):
        _, _, dones, extras = rsl.step(torch.ones(3, dtype=torch.long))
    assert dones.tolist() == [1, 1, 1] and extras["time_outs"].tolist() == [True, False, True]


def test_the_rsl_adapter_refuses_envs_that_do_not_reset_inside_step():
    from envs.rsl import PatternCutRslEnv

    for mode in ("next_step", "disabled"):
        with pytest.raises(ValueError, match="rsl-rl resets envs inside step.*SAME_STEP"):
            PatternCutRslEnv(PatternCutVecEnv(2, autoreset_mode=mode, **SMALL))
    with pytest.raises(ValueError, match="rsl-rl resets envs inside step.*SAME_STEP"):
        PatternCutRslEnv(PatternCutVecEnv(2, **SMALL))  # the default, Gymnasium's: NEXT_STEP
    with pytest.raises(ValueError, match="env: expected an envs.PatternCutVecEnv"):
        PatternCutRslEnv(gym.make(ENV_ID, **SMALL))


def test_disabled_autoreset_waits_for_reset():
    vec = PatternCutVecEnv(2, autoreset_mode="Disabled", max_episode_steps=3, **SMALL)
    vec.reset(seed=0)
    for _ in range(3):
        obs, rewards, terminated, truncated, info = vec.step(np.zeros(2, dtype=int))
    assert truncated.all() and not terminated.any() and "error_mm2" not in info
    with pytest.raises(RuntimeError, match="DISABLED; call reset"):
        vec.step(np.zeros(2, dtype=int))
    obs, _ = vec.reset(options={"reset_mask": np.array([True, True])})
    assert np.all(obs[:, 0] == 0.0) and vec.step(np.zeros(2, dtype=int))[0][0, 0] > 0


@pytest.mark.parametrize("bad", ["sometimes", 3])
def test_an_unknown_autoreset_mode_is_refused(bad):
    with pytest.raises(ValueError, match="autoreset_mode: choose one of AutoresetMode.NEXT_STEP"):
        PatternCutVecEnv(2, autoreset_mode=bad, **SMALL)


WRAPPERS = {
    "NormalizeObservation": vector_wrappers.NormalizeObservation,
    "TransformObservation": lambda env: vector_wrappers.TransformObservation(env, lambda obs: 2.0 * obs),
    "DtypeObservation": lambda env: vector_wrappers.DtypeObservation(env, np.float64),
    "FlattenObservation": vector_wrappers.FlattenObservation,
}


def test_gymnasium_vector_observation_wrappers_run_across_episodes():
    """The wrappers need NEXT_STEP (or DISABLED): the vector env's default, so ``gym.make_vec`` as is."""
    same_step = PatternCutVecEnv(2, autoreset_mode="same_step", **SMALL)
    for wrap in WRAPPERS.values():  # Gymnasium's own check: these wrappers refuse same-step autoreset
        with pytest.raises(ValueError, match="NEXT_STEP or DISABLED"):
            wrap(same_step)
    env = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", **SMALL)
    assert env.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    for wrap in WRAPPERS.values():
        env = wrap(env)
    env = vector_wrappers.RecordEpisodeStatistics(env)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (2, 40) and obs.dtype == np.float64
    returns = []
    for _ in range(STEPS + 2):
        obs, rewards, terminated, truncated, info = env.step(np.zeros(2, dtype=int))
        assert obs.shape == (2, 40) and obs.dtype == np.float64 and np.isfinite(obs).all()
        if "episode" in info:
            returns.append(info["episode"]["r"])
            assert info["episode"]["l"].tolist() == [STEPS, STEPS]
    assert len(returns) == 1 and np.all(returns[0] < 0.0)


def test_reset_takes_gymnasium_seed_lists():
    vec = PatternCutVecEnv(2, **SMALL)
    by_int, _ = vec.reset(seed=7)
    by_list, _ = vec.reset(seed=[7, 8])  # what SyncVectorEnv makes of seed=7
    np.testing.assert_array_equal(by_list, by_int)
    other, _ = vec.reset(seed=[7, 7])
    again, _ = vec.reset(seed=np.array([7, 7]))
    np.testing.assert_array_equal(other, again)
    assert not np.array_equal(other, by_int)
    vec.reset(seed=[None, None])
    for bad, message in [
        ([1, 2, 3], "3 seeds for 2 envs"),
        ([1, None], "an int for every env"),
        ([1, -2], "an int for every env"),
        ("7", "seed must be an int"),
        (1.5, "seed must be an int"),
    ]:
        with pytest.raises(ValueError, match=message):
            vec.reset(seed=bad)


def test_reset_masks_reset_all_or_nothing():
    vec = PatternCutVecEnv(3, **SMALL)
    with pytest.raises(ValueError, match="first reset resets every env"):
        vec.reset(options={"reset_mask": np.zeros(3, dtype=bool)})
    first, _ = vec.reset(seed=0, options={"reset_mask": np.ones(3, dtype=bool)})
    np.testing.assert_array_equal(first, PatternCutVecEnv(3, **SMALL).reset(seed=0)[0])
    obs, *_ = vec.step(np.array([1, 1, 1]))
    kept, info = vec.reset(options={"reset_mask": np.zeros(3, dtype=bool)})
    np.testing.assert_array_equal(kept, obs)
    assert info == {} and vec.scene.step_index == 1
    with pytest.raises(ValueError, match="resets no env here, so the seed would be dropped"):
        vec.reset(seed=5, options={"reset_mask": np.zeros(3, dtype=bool)})
    with pytest.raises(ValueError, match="share one episode clock"):
        vec.reset(options={"reset_mask": np.array([True, False, False])})
    with pytest.raises(ValueError, match=r"\(3,\) bool array"):
        vec.reset(options={"reset_mask": [1, 0, 1]})
    with pytest.raises(ValueError, match="unknown options \\['pinch'\\]; it takes only 'reset_mask'"):
        vec.reset(options={"pinch": 1})


def test_next_step_does_the_same_simulation_work_as_same_step(monkeypatch):
    """NEXT_STEP spends one extra ``step`` call per episode on the reset that SAME_STEP does inside its
    last step: per episode both simulate the same steps and reset once (measured: the same seconds per
    episode of a 64-env fls-circle batch, within the noise)."""
    counts = {}
    for mode in ("same_step", "next_step"):
        vec = PatternCutVecEnv(2, autoreset_mode=mode, **SMALL)
        calls = {"step": 0, "reset": 0}
        for name in calls:
            method = getattr(vec.scene, name)

            def counted(*args, _method=method, _name=name, _calls=calls, **kwargs):
                _calls[_name] += 1
                return _method(*args, **kwargs)

            monkeypatch.setattr(vec.scene, name, counted)
        vec.reset(seed=0)
        episodes, step_calls = 0, 0
        while episodes < 2:
            _, _, terminated, truncated, _ = vec.step(np.zeros(2, dtype=int))
            step_calls += 1
            episodes += bool(terminated.all() or truncated.all())
        counts[mode] = (calls["step"], calls["reset"], step_calls)
    assert counts["same_step"] == (2 * STEPS, 3, 2 * STEPS)  # the first reset, then one per episode
    assert counts["next_step"] == (2 * STEPS, 2, 2 * STEPS + 1)  # the second episode's reset is pending


# ---------------------------------------------------------------------- registration
def run_python(code: str, *path: str) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter with ``path`` first on ``sys.path`` (as a user's script dir)."""
    prelude = f"import sys; sys.path[:0] = {list(path)!r}\n"
    return subprocess.run(
        [sys.executable, "-c", prelude + textwrap.dedent(code)], capture_output=True, text=True, timeout=120
    )


def test_the_registration_is_an_entry_point_with_fully_qualified_entry_points():
    import warpcut.gym

    (entry,) = [e for e in entry_points(group="gymnasium.envs") if e.name == "warpcut"]
    assert entry.value == "warpcut.gym:register_envs" and entry.load() is warpcut.gym.register_envs
    assert warpcut.gym.env_package() is envs  # the name envs is ours here: no second copy
    spec = gym.spec(ENV_ID)
    assert spec.entry_point == "envs.pattern_cut:PatternCutEnv"
    assert spec.vector_entry_point == "envs.vector:PatternCutVecEnv"
    done = run_python(
        """
        from importlib.metadata import entry_points
        import gymnasium as gym
        for entry in entry_points(group="gymnasium.envs"):  # what a plugin loader does
            entry.load()()
        env = gym.make("warpcut/PatternCut-v0", contour="circle-small", resolution=9, device="cpu")
        print(type(env.unwrapped).__module__)
        """
    )
    assert done.returncode == 0 and done.stdout.strip() == "envs.pattern_cut", done.stderr


def test_a_users_own_agents_package_does_not_shadow_the_env(tmp_path):
    (tmp_path / "agents").mkdir()
    (tmp_path / "agents" / "__init__.py").write_text("MINE = True\n")
    done = run_python(
        """
        import gymnasium as gym
        import agents
        assert agents.MINE
        env = gym.make("envs:warpcut/PatternCut-v0", contour="circle-small", resolution=9, device="cpu")
        vec = gym.make_vec("warpcut/PatternCut-v0", num_envs=2, vectorization_mode="vector_entry_point",
                           contour="circle-small", resolution=9, device="cpu")
        print(env.reset(seed=0)[0].shape, vec.reset(seed=0)[0].shape)
        """,
        str(tmp_path),
    )
    assert done.returncode == 0 and done.stdout.strip() == "(47,) (2, 47)", done.stderr  # the defaults


@pytest.mark.parametrize(
    "how",
    [
        "entry",  # what a plugin loader does
        "import",  # import warpcut.gym
        "id",  # gym.make("warpcut.gym:warpcut/PatternCut-v0")
    ],
)
def test_a_users_own_envs_package_does_not_hide_the_env(tmp_path, how):
    """A script's own top-level ``envs`` package, first on ``sys.path``, keeps the name ``envs``;
    :mod:`warpcut.gym` registers warpcut's from its location; ``gym.make`` and ``gym.make_vec`` build it."""
    (tmp_path / "envs").mkdir()
    (tmp_path / "envs" / "__init__.py").write_text("MINE = True\n")
    load = {
        "entry": "from importlib.metadata import entry_points\n"
        "for entry in entry_points(group='gymnasium.envs'):\n    entry.load()()",
        "import": "import warpcut.gym",
        "id": "",
    }[how]
    env_id = "warpcut.gym:warpcut/PatternCut-v0" if how == "id" else "warpcut/PatternCut-v0"
    done = run_python(
        f"""
import sys
import gymnasium as gym
import envs
assert envs.MINE
{load}
env = gym.make("{env_id}", contour="circle-small", resolution=9, device="cpu")
vec = gym.make_vec("warpcut/PatternCut-v0", num_envs=2, vectorization_mode="vector_entry_point",
                   contour="circle-small", resolution=9, device="cpu")
print(type(env.unwrapped).__module__, env.reset(seed=0)[0].shape, vec.reset(seed=0)[0].shape)
assert sys.modules["envs"].MINE
""",
        str(tmp_path),
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "_warpcut_envs.pattern_cut (47,) (2, 47)", done.stdout
