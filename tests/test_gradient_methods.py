"""Gradient-based tensioning: the open-loop plan optimiser (agents.gradient) and APG training (agents.apg)."""

import json

import numpy as np
import pytest

from agents.config import GradConfig, TrainConfig
from agents.gradient import PlanPolicy, PlanResult, optimize_plan
from warpcut import CuttingTask, load_contour
from warpcut.sim.config import SimConfig

pytestmark = pytest.mark.usefixtures("one_torch_thread")

SMALL = SimConfig(resolution=13, noise_std=0.03)
PINCH = np.array([68.8, 38.9])  # circle-small's planned pinch on the 13 x 13 sheet


def test_plan_policy_plays_each_contours_plan_to_its_trials():
    plans = [np.ones((3, 3)), -np.ones((5, 3))]
    policy = PlanPolicy(plans, trials=2)
    task = CuttingTask(SMALL, [load_contour("circle-small")] * 4, seed=0)
    moves = policy(task)
    assert moves.shape == (4, 3)
    np.testing.assert_array_equal(moves[:, 0], [1, 1, -1, -1])
    task.update_index = 4 * SMALL.updates_per_step  # past the first plan's end: it holds still
    np.testing.assert_array_equal(policy(task)[:, 0], [0, 0, -1, -1])
    with pytest.raises(ValueError, match="plans: 2 plan"):
        PlanPolicy(plans, trials=1)(task)


def test_optimize_plan_lowers_the_surrogate_within_the_move_limits():
    contour = load_contour("circle-small")
    settings = GradConfig(iterations=4, trials=2, learning_rate=0.2, window=None)  # the whole gradient
    result = optimize_plan(contour, PINCH, config=SMALL, settings=settings)
    surrogate = [h["surrogate"] for h in result.history]
    held_out = [h["validation_error_vertices"] for h in result.history]
    assert len(result.history) == settings.iterations + 1
    assert min(surrogate[1:]) < 0.8 * surrogate[0]  # descent on what it differentiates
    assert result.best_iteration == int(np.argmin(held_out))  # selected on the held-out episodes
    assert np.abs(result.plan).max() <= SMALL.max_step_mm
    assert result.best_iteration == 0 or np.abs(result.plan).max() > 0
    assert result.env_steps == (settings.iterations + 1) * settings.trials * len(result.plan)
    again = PlanResult.from_json(json.loads(json.dumps(result.to_json())))
    np.testing.assert_array_equal(again.plan, result.plan)  # bit for bit: a read-back plan plays the same


def test_an_interrupted_optimisation_continues_from_its_state(tmp_path, monkeypatch):
    from warpcut.gradients import DifferentiableRollout

    contour = load_contour("circle-small")
    settings = GradConfig(iterations=3, trials=2, learning_rate=0.2)
    whole = optimize_plan(contour, PINCH, config=SMALL, settings=settings)

    state = tmp_path / "state.json"
    backward = DifferentiableRollout.backward
    calls = []

    def interrupted(self, rollout, window=None):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return backward(self, rollout, window)

    monkeypatch.setattr(DifferentiableRollout, "backward", interrupted)
    with pytest.raises(KeyboardInterrupt):
        optimize_plan(contour, PINCH, config=SMALL, settings=settings, state_file=state)
    assert json.loads(state.read_text())["iteration"] == 1
    monkeypatch.setattr(DifferentiableRollout, "backward", backward)
    resumed = optimize_plan(contour, PINCH, config=SMALL, settings=settings, state_file=state)
    np.testing.assert_array_equal(resumed.plan, whole.plan)
    assert [h["error_vertices"] for h in resumed.history] == [h["error_vertices"] for h in whole.history]
    with pytest.raises(ValueError, match="other settings"):
        optimize_plan(
            contour, PINCH, config=SMALL, settings=GradConfig(iterations=5, trials=2), state_file=state
        )


def test_grad_config_names_a_bad_field():
    with pytest.raises(ValueError, match="iterations"):
        GradConfig(iterations=0).validated()
    with pytest.raises(ValueError, match="learning_rate"):
        GradConfig(learning_rate=float("nan")).validated()


def _apg_env(num_envs: int):
    from agents.rl import training_env
    from envs.options import PatternCutOptions

    options = PatternCutOptions(
        contour="circle-small", sim_config=SMALL, action_type="continuous", contour_features=True
    )
    cfg = TrainConfig(num_envs=num_envs, iterations=2, algorithm="apg", discrete=False, save_interval=1)
    return training_env(options, cfg), cfg


def test_apg_trains_saves_and_resumes(tmp_path):
    from agents.train import train

    env, cfg = _apg_env(2)
    summary = train(env, cfg, tmp_path, progress=False)
    assert summary["status"] == "completed" and summary["iterations"] == 2
    steps = env.env.scene.task.num_steps
    assert summary["env_steps"] == 2 * 2 * steps  # one whole episode per env and iteration
    history = summary["history"]
    assert all(np.isfinite(h["final_error"]) and h["grad_norm"] > 0 for h in history)
    assert (tmp_path / "latest.pt").is_file()
    env, _ = _apg_env(2)
    more = train(
        env, TrainConfig(**{**cfg.__dict__, "iterations": 3}), tmp_path, resume=tmp_path, progress=False
    )
    assert more["iterations"] == 3 and len(more["history"]) == 3


def test_apg_accept_replays_the_same_episodes_and_keeps_only_steps_that_help(monkeypatch):
    """``apg_accept``: the step is judged on the iteration's own episodes run again (the same noise and
    fiducials: weights left as they were replay the same error to the bit, so that step is not kept), and a
    rejected step leaves the weights and Adam's state as they were and halves the step size."""
    import copy

    import torch

    from agents.apg import ApgRunner

    env, cfg = _apg_env(3)
    cfg = TrainConfig(**{**cfg.__dict__, "apg_accept": True, "learning_rate": 0.05})
    runner = ApgRunner(env, cfg.to_rsl_rl(None), None)
    errors = []
    forward = runner.engine.forward

    def recorded(*args, **kwargs):
        rollout = forward(*args, **kwargs)
        errors.append(float(np.nanmean(rollout.score.error_vertices)))
        return rollout

    runner.engine.forward = recorded
    with monkeypatch.context() as patch:
        patch.setattr(runner.apg_optimizer, "step", lambda: None)  # a step that changes nothing
        metrics = runner._iteration()
    assert errors[0] == errors[1] and metrics["accepted"] == 0.0
    assert metrics["step_size"] == pytest.approx(0.025)
    for _ in range(4):  # real steps: kept exactly when the replay cut better
        errors.clear()
        before = [p.detach().clone() for p in runner.alg.actor.parameters()]
        adam = copy.deepcopy(runner.apg_optimizer.state_dict()["state"])
        metrics = runner._iteration()
        after = list(runner.alg.actor.parameters())
        same = all(torch.equal(p, q) for p, q in zip(before, after, strict=True))
        assert metrics["accepted"] == float(errors[1] < errors[0]) == float(not same)
        if same:
            kept = runner.apg_optimizer.state_dict()["state"]
            assert all(torch.equal(adam[k]["exp_avg"], kept[k]["exp_avg"]) for k in adam)


def test_apg_refuses_discrete_actions():
    from agents.train import train

    env, _ = _apg_env(2)
    with pytest.raises(ValueError, match="algorithm: apg"):
        train(env, TrainConfig(num_envs=2, algorithm="apg", discrete=True), "unused", progress=False)
    with pytest.raises(ValueError, match="algorithm: choose one of"):
        train(env, TrainConfig(num_envs=2, algorithm="sac", discrete=False), "unused", progress=False)


def test_optimize_pinch_moves_the_pinch_point_and_keeps_it_feasible():
    from warpcut.planning.feasibility import pinch_feasible

    contour = load_contour("circle-small")
    settings = GradConfig(iterations=3, trials=2, optimize_pinch=True, pinch_learning_rate=2.0)
    result = optimize_plan(contour, PINCH, config=SMALL, settings=settings)
    pinches = np.array([h["pinch"] for h in result.history])
    assert np.linalg.norm(pinches[-1] - PINCH) > 0.5  # it moved along its gradient
    assert pinch_feasible(pinches, contour, SMALL).all()
    np.testing.assert_allclose(result.pinch, pinches[result.best_iteration])
