"""Property-based tests of the physical parameters: whatever a user sets, a cut either runs to
finite scores, or its diverged envs are flagged with NaN scores, or it fails with a one-line ``ValueError``
naming what to change; never another exception, never a NaN score without ``diverged``, never a NaN
observation (any value of any type for every config field: tests/test_validation.py). Examples per test:
the hypothesis profile's (tests/conftest.py: "ci" by default, "long" for a real fuzzing run); the sheets
are small so each example takes milliseconds."""

import math

import numpy as np
from hypothesis import event, given, settings
from hypothesis import strategies as st

from envs import PatternCutVecEnv
from warpcut import SimConfig
from warpcut.contours import load_contour
from warpcut.task import CuttingTask

CONTOUR = load_contour("circle-small")
NUM_ENVS = 2
SHORT = SimConfig(resolution=9, settle_updates=30, trajectory_spacing_mm=3.0)
"""A small sheet and a 17-step episode of circle-small (the env test)."""


def floats(low: float, high: float) -> st.SearchStrategy:
    """Ordinary values in [low, high], with the edges and a few huge ones (noise that overflows)."""
    return st.one_of(st.floats(low, high), st.sampled_from([low, high]))


def anything(low: float, high: float) -> st.SearchStrategy:
    """:func:`floats`, and the values nobody should give."""
    return st.one_of(
        floats(low, high),
        st.floats(allow_nan=True, allow_infinity=True),
        st.sampled_from([math.nan, math.inf, -math.inf, -1.0, 0.0, 1e30, 1e300]),
    )


def per_env(values: st.SearchStrategy, wrong_lengths: bool = False) -> st.SearchStrategy:
    """One value, or a list of them: one per env (or of any length, with ``wrong_lengths``)."""
    sizes = (
        {"min_size": 0, "max_size": NUM_ENVS + 1}
        if wrong_lengths
        else {"min_size": NUM_ENVS, "max_size": NUM_ENVS}
    )
    return st.one_of(values, st.lists(values, **sizes))


SANE = {
    "noise_std": per_env(st.one_of(floats(0.0, 3.0), st.sampled_from([30.0, 1e6, 1e30, 3e38]))),
    "gravity": per_env(floats(0.0, 1e5)),
    "dt": per_env(floats(1e-4, 1.0)),
    "damping": per_env(floats(0.0, 1.0)),
    "elasticity": per_env(floats(0.01, 1.99)),
    "sweeps": st.integers(1, 40),
    "chebyshev_rho": st.sampled_from([0.0, 0.5, 0.9, SimConfig.chebyshev_rho]),
    "updates_per_step": st.integers(1, 4),
    "first_order_z": st.booleans(),
    "fixture": st.sampled_from(["corners", "rows"]),
}
"""Every parameter within its documented range (some combinations still diverge, or do not settle)."""

ANY = {
    "noise_std": per_env(anything(0.0, 1e3), wrong_lengths=True),
    "gravity": per_env(anything(0.0, 1e5), wrong_lengths=True),
    "dt": per_env(anything(1e-4, 1.0), wrong_lengths=True),
    "damping": per_env(anything(0.0, 1.0), wrong_lengths=True),
    "elasticity": per_env(anything(0.01, 1.99), wrong_lengths=True),
    "sweeps": st.one_of(st.integers(-2, 60), st.sampled_from([0, 200, 201, 2.5, True])),
    "chebyshev_rho": anything(0.0, 0.99),
    "updates_per_step": st.integers(-1, 4),
    "fixture": st.sampled_from(["corners", "rows", "clamps"]),
}
"""Anything, out of range and malformed values included."""


def run(physics: dict) -> None:
    """Cut with ``physics``: finite scores, flagged divergence, or a one-line ValueError."""
    try:  # a config checks each field as it is made
        config = SimConfig(resolution=5, settle_updates=30, **physics)
        task = CuttingTask(config, CONTOUR, num_envs=NUM_ENVS, device="cpu", seed=1)
        score = task.run(None)
    except ValueError as error:  # ConfigError, SimulationDiverged (a ValueError) or another bad input
        assert_one_line(error)
        event(f"refused: {type(error).__name__} {str(error).split(':')[0][:30]}")
        return
    event(f"ran, {int(task.diverged().sum())} of {NUM_ENVS} diverged")
    assert task.horizon_updates < 4 * CONTOUR.length  # episodes never explode
    diverged = task.diverged()
    np.testing.assert_array_equal(score.diverged, diverged)
    for values in (score.error_vertices, score.error_mm2, score.separated_error_mm2):
        assert np.isfinite(values[~diverged]).all()
        assert np.isnan(values[diverged]).all()


def assert_one_line(error: ValueError) -> None:
    message = str(error)
    assert message and "\n" not in message, repr(message)


@settings(deadline=None)
@given(**SANE)
def test_physics_in_range_runs_to_finite_scores_or_flags_divergence(**physics):
    run(physics)


@settings(deadline=None)
@given(**ANY)
def test_any_physics_runs_or_fails_in_one_line(**physics):
    run(physics)


@settings(deadline=None, max_examples=10)
@given(noise_std=SANE["noise_std"], gravity=anything(0.0, 1e5), dt=floats(1e-4, 1.0))
def test_env_observations_and_rewards_are_never_nan(**physics):
    try:
        vec = PatternCutVecEnv(
            NUM_ENVS, contour="circle-small", sim_config=SHORT, device="cpu", contour_features=True,
            action_type="discrete", autoreset_mode="same_step", **physics,
        )  # fmt: skip
    except ValueError as error:
        assert_one_line(error)
        event(f"refused: {type(error).__name__} {str(error).split(':')[0][:30]}")
        return
    obs, _ = vec.reset(seed=0)
    seen = np.zeros(NUM_ENVS, dtype=bool)
    for _ in range(vec.scene.episode_steps):
        assert obs in vec.observation_space and not np.isnan(obs).any()
        obs, rewards, terminated, truncated, info = vec.step(np.ones(NUM_ENVS, dtype=np.int64))
        assert np.isfinite(rewards).all() and not np.isnan(obs).any()
        seen |= info.get("diverged", seen)
        if "final_info" in info and "error_mm2" in info["final_info"]:
            final = info["final_info"]
            diverged = final.get("diverged", np.zeros(NUM_ENVS, dtype=bool))
            assert np.isfinite(final["error_mm2"][~diverged]).all()
            assert np.isnan(final["error_mm2"][diverged]).all()
        if terminated.all() or truncated.all():
            break
    event(f"ran, {int(seen.sum())} of {NUM_ENVS} diverged")
