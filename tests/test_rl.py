"""Learned tensioners on the real pattern-cutting env: run directories and their evaluation."""

import json

import numpy as np
import pytest
import torch

from agents.rl import (
    RECIPE,
    Scenario,
    chosen_candidate,
    evaluate_run,
    load_scenario,
    rollout_errors,
    train_contour,
)
from agents.train import TrainConfig
from warpcut.contours import load_contour
from warpcut.planning import feasible_centroid


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    torch.set_num_threads(1)
    run = tmp_path_factory.mktemp("rl") / "fls-circle"
    scenario = Scenario(
        contour="fls-circle", sim={"resolution": 13}, dense_reward=True, contour_features=True
    )
    train_contour(
        scenario,
        run,
        TrainConfig(num_envs=8, iterations=2, num_steps_per_env=8),
        eval_trials=3,
        progress=False,
    )
    return run


def test_run_directory_records_the_scenario(run_dir):
    scenario = load_scenario(run_dir)
    assert scenario.contour == "fls-circle" and scenario.dense_reward and scenario.contour_features
    # The default pinch: the feasible point nearest the centroid (the disc lies under the cutting arm).
    contour = load_contour("fls-circle")
    assert scenario.pinch == pytest.approx(list(feasible_centroid(contour, scenario.sim_config())), abs=1e-3)
    evaluation = json.loads((run_dir / "evaluation.json").read_text())
    assert evaluation["trials"] == 3 and evaluation["none_error_vertices"] > 0


def test_evaluation_is_reproducible_from_the_run_directory(run_dir):
    first = json.loads((run_dir / "evaluation.json").read_text())
    again = evaluate_run(run_dir, trials=3, seed=1)
    assert again["rl_error_vertices"] == first["rl_error_vertices"]
    errors = rollout_errors(run_dir, trials=2, seed=5)
    assert errors["error_vertices"].shape == (2,) and np.all(np.isfinite(errors["error_mm2"]))


def test_mismatched_action_type_is_reported(tmp_path):
    with pytest.raises(ValueError, match="does not match the scenario's continuous actions"):
        train_contour(
            Scenario(contour="fls-circle", action_type="continuous"), tmp_path, TrainConfig(num_envs=2)
        )
    with pytest.raises(FileNotFoundError, match="no scenario.json"):
        load_scenario(tmp_path / "nothing")


CANDIDATES = [{"pinch": [50.0, 42.5], "segments": None}, {"pinch": [30.0, 40.0], "segments": None}]


def test_shared_policy_observes_its_pinch_and_picks_the_best_candidate(tmp_path):
    """One policy over two pinch candidates: env i pinches candidate i % 2 and observes that point; the run
    chooses the candidate whose validation error is lowest and evaluates there."""
    torch.set_num_threads(1)
    scenario = Scenario(contour="fls-circle", sim={"resolution": 13}, candidates=CANDIDATES, **RECIPE)
    assert scenario.observe_pinch
    env = scenario.vec_env(4)
    obs, _ = env.reset(seed=0)
    pinches = np.array([CANDIDATES[i % 2]["pinch"] for i in range(4)])
    assert env.task.pinch_points == pytest.approx(pinches)
    assert obs[:, -2:] == pytest.approx((pinches - 50.0) / 50.0)  # normalised material x, y
    result = train_contour(
        scenario,
        tmp_path,
        TrainConfig(num_envs=4, iterations=2, num_steps_per_env=4, stay_prior=0.9),
        eval_trials=2,
        progress=False,
        validation_trials=4,
    )
    selection = json.loads((tmp_path / "candidates.json").read_text())
    errors = selection["validation_error_vertices"]
    assert len(errors) == 2 and selection["chosen"] == int(np.argmin(errors)) == chosen_candidate(tmp_path)
    assert selection["validation_episodes_per_candidate"] == 4  # at least CANDIDATE_VALIDATION_MIN each
    assert result["evaluation"]["pinch"] == pytest.approx(CANDIDATES[selection["chosen"]]["pinch"])
    assert load_scenario(tmp_path).candidates == CANDIDATES


def test_shared_scenario_rejects_a_single_pinch():
    with pytest.raises(ValueError, match="leave pinch and segments None"):
        Scenario(contour="fls-circle", pinch=[50.0, 50.0], candidates=CANDIDATES)
    with pytest.raises(ValueError, match="candidates: give a non-empty list"):
        Scenario(contour="fls-circle", candidates=[])
    with pytest.raises(ValueError, match="several; use at_candidate"):
        Scenario(contour="fls-circle", candidates=CANDIDATES).pinch_point()
    with pytest.raises(ValueError, match="candidate: 2 is not in 0..1"):
        Scenario(contour="fls-circle", candidates=CANDIDATES).at_candidate(2)


@pytest.mark.slow
def test_ppo_learns_to_lift_the_parabola(tmp_path):
    """A seeded learning test on the real env (~30 s): on ``parabola`` with the grasp at the centroid, the
    open-loop scissors pass over a sheet that sags out of their reach, so no tension and holding still both
    leave ~250 vertices of error; lifting the sheet (+z) is what helps (``scripts/constant_moves.py``).
    From a uniform start (its argmax policy cuts as badly as no tension), PPO must find it. Measured with
    seeds 0, 1, 2: 16, 17 and 84 vertices after 30 iterations, against 252 with no tension. The setting
    is the one before the path score: an 8 mm cut-height limit, scored by separated material, no process
    noise, the grasp at the centroid (inside the piece: a short arm footprint)."""
    torch.set_num_threads(1)
    old_protocol = {"cut_height_mm": 8.0, "score": "separated", "noise_std": 0.0}
    centroid = [float(v) for v in load_contour("parabola").centroid]
    scenario = Scenario(contour="parabola", pinch=centroid, sim=old_protocol, **RECIPE)
    result = train_contour(
        scenario,
        tmp_path,
        TrainConfig(num_envs=64, iterations=30, stay_prior=0.0, save_interval=10**6),
        eval_trials=4,
        progress=False,
    )
    initial = result["summary"]["validation"][0]
    assert initial["iterations"] == 0
    evaluation = result["evaluation"]
    assert evaluation["none_error_vertices"] > 200
    assert initial["error"] > 0.8 * evaluation["none_error_vertices"]  # the untrained policy does not help
    assert evaluation["rl_error_vertices"] < 0.5 * evaluation["none_error_vertices"]
    assert result["summary"]["best"]["iterations"] > 0


def test_a_still_policy_with_paired_noise_cuts_exactly_as_fixed_tension():
    """Paired trials: a policy that always chooses "stay", rolled out with the noise of the baselines'
    batch, reproduces fixed tension at its pinch bit for bit, trial by trial, for a contour that is not the
    first of the batch too; with its env's own noise it does not."""
    from agents.evaluation import MethodSpec, run_method
    from agents.rl import Scenario, policy_errors
    from warpcut import SimConfig

    class Stay(torch.nn.Module):
        def forward(self, obs):
            return torch.zeros(obs.batch_size[0], 1)

    scenario = Scenario(contour="circle-small", sim={"resolution": 13, "noise_std": 0.05})
    contour, pinch = scenario.load_contour(), scenario.pinch_point()
    trials, seed = 3, 4
    fixed = run_method(
        [load_contour("fls-circle"), contour],
        MethodSpec([pinch, pinch], None),
        trials,
        SimConfig(resolution=13, noise_std=0.05),
        "cpu",
        seed,
    ).errors[1]
    paired = policy_errors(Stay(), scenario.vec_env(trials, "cpu"), scenario, 9, paired_noise=(seed, trials))
    np.testing.assert_array_equal(paired["error_vertices"], fixed)
    own = policy_errors(Stay(), scenario.vec_env(trials, "cpu"), scenario, 9)
    assert not np.array_equal(own["error_vertices"], fixed)
