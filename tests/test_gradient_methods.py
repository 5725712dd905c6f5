"""Gradient-based tensioning: the plan optimiser (agents.plan_optimizer) and APG training (agents.apg)."""

import dataclasses
import json
import types

import numpy as np
import pytest

from agents.config import TrainConfig
from agents.plan_optimizer.config import GRAD_CONFIGS, GradConfig, grad_config
from agents.plan_optimizer.estimators import SmoothedGradient, Tether, path_distance
from agents.plan_optimizer.optimizer import cached_plan, grad_result, optimize_plan
from agents.plan_optimizer.plan import PlanPolicy, PlanResult
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
    settings = GradConfig(
        estimator="tape", iterations=4, trials=2, learning_rate=0.2, window=None
    )  # the whole gradient
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


def _interrupt_and_resume(
    monkeypatch, owner, name: str, call: int, settings, state, **anchored
) -> PlanResult:
    """Optimise circle-small's plan with ``owner.name`` interrupted (Ctrl-C) at its ``call``-th call, check
    the state file holds the iterations done, and continue from it; returns the continued result."""
    method, calls = getattr(owner, name), []

    def interrupted(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == call:
            raise KeyboardInterrupt
        return method(self, *args, **kwargs)

    contour = load_contour("circle-small")
    monkeypatch.setattr(owner, name, interrupted)
    with pytest.raises(KeyboardInterrupt):
        optimize_plan(contour, PINCH, config=SMALL, settings=settings, state_file=state, **anchored)
    assert json.loads(state.read_text())["iteration"] == call - 1
    monkeypatch.setattr(owner, name, method)
    return optimize_plan(contour, PINCH, config=SMALL, settings=settings, state_file=state, **anchored)


def test_an_interrupted_optimisation_continues_from_its_state(tmp_path, monkeypatch):
    from warpcut.gradients import DifferentiableRollout

    contour = load_contour("circle-small")
    settings = GradConfig(estimator="tape", iterations=3, trials=2, learning_rate=0.2)
    whole = optimize_plan(contour, PINCH, config=SMALL, settings=settings)

    state = tmp_path / "state.json"
    resumed = _interrupt_and_resume(monkeypatch, DifferentiableRollout, "backward", 2, settings, state)
    np.testing.assert_array_equal(resumed.plan, whole.plan)
    assert [h["error_vertices"] for h in resumed.history] == [h["error_vertices"] for h in whole.history]
    with pytest.raises(ValueError, match="other settings"):
        optimize_plan(
            contour,
            PINCH,
            config=SMALL,
            settings=GradConfig(estimator="tape", iterations=5, trials=2),
            state_file=state,
        )


def test_grad_config_names_a_bad_field():
    with pytest.raises(ValueError, match="iterations"):
        GradConfig(estimator="tape", iterations=0).validated()
    with pytest.raises(ValueError, match="learning_rate"):
        GradConfig(learning_rate=float("nan")).validated()
    with pytest.raises(ValueError, match="estimator: must be one of es, tape"):
        GradConfig(estimator="cma").validated()
    with pytest.raises(ValueError, match="es_population: must be even"):
        GradConfig(estimator="es", es_population=5).validated()
    with pytest.raises(ValueError, match="optimize_pinch: .* only with estimator 'tape'"):
        GradConfig(estimator="es", optimize_pinch=True).validated()
    with pytest.raises(ValueError, match="validation_trials: estimator 'es'"):
        GradConfig(estimator="es", validation_trials=0).validated()
    with pytest.raises(ValueError, match="es_sigma_mm"):
        GradConfig(estimator="es", es_sigma_mm=0.0).validated()
    with pytest.raises(ValueError, match="estimator: must be one of"):
        grad_config("cma")


def test_grad_config_takes_the_estimators_defaults_and_the_given_fields():
    assert grad_config() == GRAD_CONFIGS["es"] == GradConfig()  # es is the default estimator
    es = grad_config("es", iterations=None, learning_rate=None, es_population=8)
    assert es == dataclasses.replace(GRAD_CONFIGS["es"], es_population=8)
    tape = grad_config("tape", iterations=None, learning_rate=None, trials=2)
    assert tape == dataclasses.replace(GRAD_CONFIGS["tape"], trials=2)
    assert es.learning_rate != tape.learning_rate  # each estimator's own step


class _QuadraticTask:
    """Stands in for a CuttingTask: a plan's "error" is its squared distance from ``target`` (the same for
    every trial), NaN (diverged) for plans whose first move exceeds ``diverge_above``."""

    num_steps = 3

    def __init__(self, target: np.ndarray, diverge_above: float = np.inf):
        self.target, self.diverge_above, self.played = target, diverge_above, []

    def run(self, policy: PlanPolicy):
        plans = np.asarray(policy.plans)
        self.played.append(plans)
        errors = ((plans - self.target) ** 2).sum(axis=(1, 2))
        errors[plans[:, 0, 0] > self.diverge_above] = np.nan
        return types.SimpleNamespace(error_vertices=np.repeat(errors, policy.trials))


def test_the_es_estimator_points_uphill_from_antithetic_ranked_pairs():
    settings = GradConfig(estimator="es", es_population=64, es_trials=2, es_sigma_mm=0.1)
    target = np.random.default_rng(1).uniform(-0.5, 0.5, (3, 3))
    task = _QuadraticTask(target)
    plan = np.zeros((3, 3), np.float32)
    mean, grad, no_gains = SmoothedGradient(task, settings, max_step=1.0, seed=4)(plan)
    (played,) = task.played
    assert played.shape == (64, 3, 3) and no_gains is None
    np.testing.assert_allclose(played[:32] - plan, -(played[32:] - plan), atol=1e-6)  # antithetic pairs
    assert mean == pytest.approx(((played - target) ** 2).sum(axis=(1, 2)).mean())
    true = 2 * (plan - target)  # the error's gradient
    cosine = (grad * true).sum() / np.linalg.norm(grad) / np.linalg.norm(true)
    assert cosine > 0.7, cosine
    again = SmoothedGradient(_QuadraticTask(target), settings, max_step=1.0, seed=4)(plan)[1]
    np.testing.assert_array_equal(again, grad)  # seeded
    other = SmoothedGradient(_QuadraticTask(target), settings, max_step=1.0, seed=5)(plan)[1]
    assert not np.array_equal(other, grad)
    # A diverged plan ranks last (as the worst error), and the mean leaves it out
    nan_task = _QuadraticTask(target, diverge_above=0.15)
    mean, grad, _ = SmoothedGradient(nan_task, settings, max_step=1.0, seed=4)(plan)
    assert np.isfinite(mean) and np.isfinite(grad).all()
    # Perturbed plans stay within the move limit
    big = SmoothedGradient(_QuadraticTask(target), dataclasses.replace(settings, es_sigma_mm=5.0), 1.0, 4)
    big(plan)
    assert np.abs(big.task.played[0]).max() <= 1.0


def test_the_tether_costs_the_mean_squared_distance_between_grasp_paths():
    """A plan's path is its moves added up (each clipped as the simulator clips it): a first move 1 mm off
    the anchor's leaves the whole path 1 mm off; a move undone by the next one costs only its own step."""
    anchor = np.zeros((4, 3), np.float32)
    assert path_distance(anchor, anchor, 1.0) == 0.0
    shifted = anchor.copy()
    shifted[0, 0] = 1.0
    assert path_distance(shifted, anchor, 1.0) == pytest.approx(1.0)
    jitter = anchor.copy()
    jitter[1, 1], jitter[2, 1] = 1.0, -1.0
    assert path_distance(jitter, anchor, 1.0) == pytest.approx(0.25)
    clipped = shifted * 3.0  # 3 mm asked, 1 mm moved
    assert path_distance(np.stack([clipped, anchor]), anchor, 1.0) == pytest.approx([1.0, 0.0])


def test_a_tethered_es_estimator_is_pulled_back_towards_its_anchor():
    """The tether's cost joins each perturbed plan's error before the ranking: far from the anchor, with a
    heavy tether, the estimate points away from it (uphill: the optimiser steps against it); the mean error it
    reports is the error alone."""
    settings = GradConfig(estimator="es", es_population=64, es_trials=2, es_sigma_mm=0.1)
    target = np.full((3, 3), 0.5, np.float32)
    plan = np.full((3, 3), -0.5, np.float32)  # the error pulls up, towards the target
    free = SmoothedGradient(_QuadraticTask(target), settings, 1.0, seed=4)(plan)
    assert (free[1] < 0).mean() > 0.8
    anchor = np.full((3, 3), -1.0, np.float32)
    held = SmoothedGradient(_QuadraticTask(target), settings, 1.0, 4, Tether(anchor, 100.0))(plan)
    assert (held[1] > 0).mean() > 0.8  # the tether outweighs the error: back down, towards the anchor
    assert held[0] == pytest.approx(free[0])


def test_an_anchored_optimisation_starts_from_the_anchor_and_a_heavy_tether_keeps_it():
    """With an anchor the first iterate is the anchor's moves (padded to the cut), iteration 0 records the
    still grasp's validation too, and a tether far heavier than any gain leaves the anchor the plan kept; a
    tether needs an anchor."""
    contour = load_contour("circle-small")
    settings = GradConfig(iterations=3, es_population=8, es_trials=1, validation_trials=2)
    free = optimize_plan(contour, PINCH, config=SMALL, settings=settings)
    anchor = np.asarray(free.plan[:-5] + 0.2, np.float32)  # shorter than the cut: padded with still steps
    held = optimize_plan(contour, PINCH, config=SMALL, settings=settings, anchor=anchor, tether=1e6)
    first = held.history[0]
    assert first["tether_vertices"] == 0.0 and "still_error_vertices" in first
    assert first["validation_error_vertices"] != first["still_error_vertices"]
    assert held.best_iteration == 0
    np.testing.assert_array_equal(held.plan[: len(anchor)], np.clip(anchor, -1.0, 1.0))
    assert not held.plan[len(anchor) :].any()
    with pytest.raises(ValueError, match="tether: needs an anchor"):
        optimize_plan(contour, PINCH, config=SMALL, settings=settings, tether=0.1)


def test_an_anchored_tethered_optimisation_resumes_bit_for_bit(tmp_path, monkeypatch):
    contour = load_contour("circle-small")
    settings = GradConfig(iterations=3, es_population=8, es_trials=1, validation_trials=2)
    anchored = {"anchor": np.full((10, 3), 0.1, np.float32), "tether": 0.05}
    whole = optimize_plan(contour, PINCH, config=SMALL, settings=settings, **anchored)
    resumed = _interrupt_and_resume(
        monkeypatch, SmoothedGradient, "__call__", 2, settings, tmp_path / "s.json", **anchored
    )
    np.testing.assert_array_equal(resumed.plan, whole.plan)
    assert [h["tether_vertices"] for h in resumed.history] == [h["tether_vertices"] for h in whole.history]


def test_es_optimises_the_path_score_and_resumes_bit_for_bit(tmp_path, monkeypatch):
    contour = load_contour("circle-small")
    settings = GradConfig(
        estimator="es", iterations=4, learning_rate=0.2, es_population=8, es_trials=1, validation_trials=2
    )
    whole = optimize_plan(contour, PINCH, config=SMALL, settings=settings)
    held_out = [h["validation_error_vertices"] for h in whole.history]
    assert len(whole.history) == settings.iterations + 1 and whole.history[0]["surrogate"] is None
    assert whole.best_iteration == int(np.argmin(held_out))
    assert np.abs(whole.plan).max() <= SMALL.max_step_mm
    assert whole.env_steps == settings.iterations * 8 * len(whole.plan)

    resumed = _interrupt_and_resume(
        monkeypatch, SmoothedGradient, "__call__", 3, settings, tmp_path / "s.json"
    )
    np.testing.assert_array_equal(resumed.plan, whole.plan)  # the perturbations' stream resumed too
    assert [h["error_vertices"] for h in resumed.history] == [h["error_vertices"] for h in whole.history]


def test_the_grad_column_passes_its_evaluation_batch_to_the_step_callback(tmp_path):
    """The regions plot and recordings see the grad column's cuts (``on_step``) like the other methods'."""
    from warpcut.viz.plots import FinalCuts

    contour = load_contour("circle-small")
    cuts = FinalCuts()
    settings = GradConfig(estimator="tape", iterations=1, trials=2, validation_trials=2)
    method, _ = grad_result(
        [contour], [PINCH], [None], 2, SMALL, settings, folder=tmp_path, on_step=cuts.step_callback("grad")
    )
    (cut,) = cuts.of("circle-small", ["grad"]).values()
    assert cut.trials == 2 and cut.score.error_vertices[0] == method.error_vertices[0, 0]


def test_a_kept_plan_of_other_settings_is_refused(tmp_path):
    contour = load_contour("circle-small")
    settings = GradConfig(estimator="tape", iterations=1, trials=2, validation_trials=2)
    first = cached_plan(contour, PINCH, None, SMALL, settings, folder=tmp_path)
    again = cached_plan(contour, PINCH, None, SMALL, settings, folder=tmp_path)  # read back, not rerun
    np.testing.assert_array_equal(again.plan, first.plan)
    other = dataclasses.replace(settings, estimator="es", es_population=2, es_trials=1)
    with pytest.raises(ValueError, match="circle-small.json: a plan optimised with other settings"):
        cached_plan(contour, PINCH, None, SMALL, other, folder=tmp_path)
    kept = tmp_path / "circle-small.json"  # written before es_feedback_sag existed: read at its default
    data = json.loads(kept.read_text())
    del data["settings"]["es_feedback_sag"]
    kept.write_text(json.dumps(data))
    np.testing.assert_array_equal(
        cached_plan(contour, PINCH, None, SMALL, settings, folder=tmp_path).plan, first.plan
    )
    with pytest.raises(ValueError, match="a plan optimised with other settings"):
        cached_plan(contour, PINCH, None, SMALL, dataclasses.replace(settings, trials=3), folder=tmp_path)


def _apg_env(num_envs: int, action_type: str = "continuous"):
    from agents.training import training_env
    from envs.options import PatternCutOptions

    options = PatternCutOptions(
        contour="circle-small", sim_config=SMALL, action_type=action_type, contour_features=True
    )
    cfg = TrainConfig(algo="apg", num_envs=num_envs, iterations=2, save_interval=1)
    return training_env(options, cfg), cfg


def test_apg_trains_saves_and_resumes(tmp_path):
    from agents.training import train

    env, cfg = _apg_env(2)
    summary = train(env, cfg, tmp_path, progress=False)
    assert summary["status"] == "completed" and summary["iterations"] == 2
    steps = env.env.scene.task.num_steps
    assert summary["env_steps"] == 2 * 2 * steps  # one whole episode per env and iteration
    history = summary["history"]
    assert all(np.isfinite(h["final_error"]) and h["grad_norm"] > 0 for h in history)
    assert (tmp_path / "latest.pt").is_file()
    env, _ = _apg_env(2)
    more = train(env, dataclasses.replace(cfg, iterations=3), tmp_path, resume=tmp_path, progress=False)
    assert more["iterations"] == 3 and len(more["history"]) == 3


def test_apg_accept_replays_the_same_episodes_and_keeps_only_steps_that_help(monkeypatch):
    """``apg_accept``: the step is judged on the iteration's own episodes run again (the same noise and
    fiducials: weights left as they were replay the same error to the bit, so that step is not kept), and a
    rejected step leaves the weights and Adam's state as they were and halves the step size."""
    import copy

    import torch

    from agents.apg.config import ApgConfig
    from agents.apg.runner import ApgRunner

    env, cfg = _apg_env(3)
    cfg = dataclasses.replace(cfg, apg=ApgConfig(accept=True, learning_rate=0.05))
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
    from agents.training import train

    env, cfg = _apg_env(2, action_type="discrete")
    with pytest.raises(ValueError, match="algo: apg plays continuous moves"):
        train(env, cfg, "unused", progress=False)
    with pytest.raises(ValueError, match="algo: choose one of"):
        train(env, dataclasses.replace(cfg, algo="sac"), "unused", progress=False)


def test_optimize_pinch_moves_the_pinch_point_and_keeps_it_feasible():
    from warpcut.planning.feasibility import pinch_feasible

    contour = load_contour("circle-small")
    settings = GradConfig(
        estimator="tape", iterations=3, trials=2, optimize_pinch=True, pinch_learning_rate=2.0
    )
    result = optimize_plan(contour, PINCH, config=SMALL, settings=settings)
    pinches = np.array([h["pinch"] for h in result.history])
    assert np.linalg.norm(pinches[-1] - PINCH) > 0.5  # it moved along its gradient
    assert pinch_feasible(pinches, contour, SMALL).all()
    np.testing.assert_allclose(result.pinch, pinches[result.best_iteration])


def test_a_plan_with_gains_adds_its_phase_gains_times_the_tracking_error():
    task = CuttingTask(SMALL, [load_contour("circle-small")] * 2, pinch_points=[PINCH] * 2, seed=0)
    plan = np.full((6, 3), 0.1, np.float32)
    gains = np.stack([np.full((3, 2), 0.2), np.full((3, 2), -0.3)]).astype(np.float32)  # two phases
    closed, still = PlanPolicy([plan], 2, [gains]), PlanPolicy([plan], 2, [None])
    assert still.gains is None  # no gains: open loop, as before
    task.reset()
    seen = []
    while not task.done:
        t, error = task.step_index, np.nan_to_num(task.tracking_error()[:, :2], nan=0.0)
        phase = gains[min(t * 2 // len(plan), 1)]
        base = plan[t] if t < len(plan) else np.zeros(3, np.float32)
        expected = np.clip(base + error @ phase.T, -SMALL.max_step_mm, SMALL.max_step_mm)
        move = closed(task)
        np.testing.assert_allclose(move, expected, atol=1e-6)
        seen.append(np.abs(error).max())
        task.step(move)
    assert max(seen) > 0.05, "the sheet moved: the feedback had something to act on"
    with pytest.raises(ValueError, match="gains: 1 for 2 plan"):
        PlanPolicy([plan, plan], 1, [gains])


def test_gains_scheduled_on_the_sag_act_on_the_error_and_on_it_times_the_sag():
    """``es_feedback_sag``: 3 x 4 matrices on ``[e, s e]``, ``s`` the settled sheet's mean depth over
    SAG_SCALE_MM (0 without gravity); a 3 x 2 plan beside a 3 x 4 one gets zero sag gains; the JSON keeps
    the width, and another width is refused by name."""
    from agents.plan_optimizer.plan import SAG_SCALE_MM, feedback_features, sheet_sag

    task = CuttingTask(SMALL, [load_contour("circle-small")] * 2, pinch_points=[PINCH] * 2, seed=0)
    task.sim.set_params(gravity=np.array([0.0, SMALL.gravity], np.float32))
    task.reset()
    sag = sheet_sag(task)
    assert sag[0] == 0.0 and 0.5 < sag[1] * SAG_SCALE_MM / 10.0 < 2.0  # flat, and the default's ~1.2
    plan = np.zeros((6, 3), np.float32)
    scheduled = np.zeros((1, 3, 4), np.float32)
    scheduled[0, :, 2:] = 0.5  # acts only through the sag: a flat sheet is held still
    plain = np.full((1, 3, 2), 0.2, np.float32)
    policy = PlanPolicy([plan, plan], 1, [scheduled, plain])
    assert [g.shape for g in policy.gains] == [(1, 3, 4), (1, 3, 4)]
    moved = 0.0
    while not task.done:
        error = np.nan_to_num(task.tracking_error()[:, :2], nan=0.0)
        features = feedback_features(task, scheduled=True)
        np.testing.assert_array_equal(features[:, :2], error)
        np.testing.assert_allclose(features[:, 2:], error * sag[:, None], rtol=1e-6)
        move = policy(task)
        expected = np.clip(np.stack([features[0] @ scheduled[0].T, error[1] @ plain[0].T]), -1.0, 1.0)
        np.testing.assert_allclose(move, expected, atol=1e-6)
        assert not move[0].any()  # env 0 hangs flat
        moved = max(moved, np.abs(move[1]).max())
        task.step(move)
    assert moved > 0.01
    result = PlanResult("circle-small", list(PINCH), plan, 1, gains=scheduled)
    assert PlanResult.from_json(json.loads(json.dumps(result.to_json()))).gains.shape == (1, 3, 4)
    with pytest.raises(ValueError, match="gains: expected 3 x 2 or 3 x 4 matrices"):
        PlanResult.from_json({**result.to_json(), "gains": np.zeros((1, 3, 3)).tolist()})
    with pytest.raises(ValueError, match="es_feedback_sag: there are no gains"):
        GradConfig(estimator="es", es_feedback_sag=True).validated()


def test_es_optimises_gains_scheduled_on_the_sag():
    settings = GradConfig(
        estimator="es", iterations=2, learning_rate=0.2, es_population=4, es_trials=1, validation_trials=2,
        es_feedback_phases=2, es_feedback_only=True, es_feedback_sag=True, es_randomize="gravity",
    )  # fmt: skip
    result = optimize_plan(load_contour("circle-small"), PINCH, config=SMALL, settings=settings)
    assert result.gains.shape == (2, 3, 4) and not result.plan.any()


class _QuadraticGainsTask(_QuadraticTask):
    """:class:`_QuadraticTask` whose error also counts the gains' squared distance from ``gains_target``."""

    def __init__(self, target: np.ndarray, gains_target: np.ndarray):
        super().__init__(target)
        self.gains_target, self.gains_played = gains_target, []

    def run(self, policy: PlanPolicy):
        result = super().run(policy)
        gains = np.asarray(policy.gains)
        self.gains_played.append(gains)
        extra = ((gains - self.gains_target) ** 2).sum(axis=(1, 2, 3))
        result.error_vertices = result.error_vertices + np.repeat(extra, policy.trials)
        return result


def test_the_es_estimator_moves_the_gains_downhill_with_the_plan():
    settings = GradConfig(
        estimator="es", es_population=512, es_trials=1, es_sigma_mm=0.1, es_feedback_phases=2
    )
    rng = np.random.default_rng(2)
    target, gains_target = rng.uniform(-0.5, 0.5, (3, 3)), rng.uniform(-0.5, 0.5, (2, 3, 2))
    task = _QuadraticGainsTask(target, gains_target)
    plan, gains = np.zeros((3, 3), np.float32), np.zeros((2, 3, 2), np.float32)
    _, grad, gains_grad = SmoothedGradient(task, settings, max_step=1.0, seed=4)(plan, gains)
    (played,) = task.gains_played
    assert played.shape == (512, 2, 3, 2) and gains_grad.shape == gains.shape
    np.testing.assert_allclose(played[:256], -played[256:], atol=1e-6)  # antithetic, around zero gains
    for estimate, true in ((grad, 2 * (plan - target)), (gains_grad, 2 * (gains - gains_target))):
        cosine = (estimate * true).sum() / np.linalg.norm(estimate) / np.linalg.norm(true)
        assert cosine > 0.6, cosine


def test_es_with_feedback_under_randomisation_keeps_its_gains_and_resumes_bit_for_bit(tmp_path, monkeypatch):
    settings = GradConfig(
        estimator="es", iterations=3, learning_rate=0.2, es_population=4, es_trials=2, validation_trials=3,
        es_feedback_phases=2, es_randomize="gravity",
    )  # fmt: skip
    contour = load_contour("circle-small")
    whole = optimize_plan(contour, PINCH, config=SMALL, settings=settings)
    assert whole.gains.shape == (2, 3, 2)
    if whole.best_iteration:  # the gains moved from zero with the plan
        assert np.abs(whole.gains).max() > 0
    restored = PlanResult.from_json(json.loads(json.dumps(whole.to_json())))
    np.testing.assert_array_equal(restored.gains, whole.gains)
    assert PlanResult.from_json({**whole.to_json(), "gains": None}).gains is None  # an open-loop plan
    resumed = _interrupt_and_resume(
        monkeypatch, SmoothedGradient, "__call__", 3, settings, tmp_path / "s.json"
    )
    np.testing.assert_array_equal(resumed.plan, whole.plan)
    np.testing.assert_array_equal(resumed.gains, whole.gains)
    assert [h["validation_error_vertices"] for h in resumed.history] == [
        h["validation_error_vertices"] for h in whole.history
    ]


def test_randomised_episodes_are_weighed_by_their_sheets_no_tension_error():
    """Under es_randomize each episode's error is weighed by the nominal sheet's no-tension error over its
    own sheet's: 1 on the nominal sheet, more on a flatter one; held-out episodes draw their sheets once."""
    from agents.plan_optimizer.estimators import HeldOut, RelativeWeights

    contour = load_contour("circle-small")
    task = CuttingTask(SMALL, [contour] * 2, pinch_points=[PINCH] * 2, seed=0)
    task.set_params(gravity=[SMALL.gravity, SMALL.gravity / 2])
    weights = RelativeWeights(SMALL)(task)
    assert weights[0] == pytest.approx(1.0) and weights[1] > 1.0
    held_out = CuttingTask(SMALL, [contour] * 6, pinch_points=[PINCH] * 6, seed=1)
    settings = GradConfig(estimator="es", es_randomize="gravity")
    HeldOut(held_out, settings, seed=3)
    assert len(set(np.asarray(held_out.config.gravity).tolist())) > 1  # drawn per episode
    plan = np.zeros((held_out.num_steps, 3), np.float32)
    first = HeldOut(held_out, settings, seed=3)(plan, None)
    assert HeldOut(held_out, settings, seed=3)(plan, None) == first  # the same draws every time
    # A range of its own (es_randomize_ranges) is where the draws come from, for validation and es alike.
    narrow = grad_config("es", es_randomize="gravity,noise", es_randomize_ranges={"noise": (0.2, 0.27)})
    assert narrow.es_randomize_ranges == {"noise_std": [0.2, 0.27]}  # one spelling, saved runs compare equal
    HeldOut(held_out, narrow, seed=3)
    noise = np.asarray(held_out.config.noise_std)
    assert noise.min() >= 0.2 and noise.max() <= 0.27 and len(set(noise.tolist())) > 1
    with pytest.raises(ValueError, match="es_randomize_ranges: noise not randomised"):
        grad_config("es", es_randomize="gravity", es_randomize_ranges={"noise": (0.0, 0.27)})


def test_a_kept_plan_must_match_its_pinch_and_closed_loop_settings_need_es(tmp_path):
    contour = load_contour("circle-small")
    tape = GradConfig(estimator="tape", iterations=1, trials=2, validation_trials=2)
    cached_plan(contour, PINCH, None, SMALL, tape, folder=tmp_path)
    with pytest.raises(ValueError, match="a plan optimised at the pinch point"):
        cached_plan(contour, PINCH + 1.0, None, SMALL, tape, folder=tmp_path)
    with pytest.raises(ValueError, match="es_feedback_phases: only estimator 'es'"):
        GradConfig(estimator="tape", es_feedback_phases=1).validated()
    with pytest.raises(ValueError, match="es_randomize: unknown parameter 'gravty'"):
        GradConfig(estimator="es", es_randomize="gravty").validated()


def test_feedback_only_leaves_the_plan_at_zero_and_moves_the_gains():
    settings = GradConfig(
        estimator="es", iterations=2, learning_rate=0.2, es_population=4, es_trials=1, validation_trials=2,
        es_feedback_phases=1, es_feedback_only=True,
    )  # fmt: skip
    result = optimize_plan(load_contour("circle-small"), PINCH, config=SMALL, settings=settings)
    assert not result.plan.any()
    task = _QuadraticGainsTask(np.ones((3, 3)), np.ones((1, 3, 2)))
    plan, gains = np.zeros((3, 3), np.float32), np.zeros((1, 3, 2), np.float32)
    _, grad, gains_grad = SmoothedGradient(task, settings, max_step=1.0, seed=0)(plan, gains)
    assert not grad.any() and gains_grad.any() and not np.asarray(task.played).any()
    with pytest.raises(ValueError, match="es_feedback_only: there are no gains"):
        GradConfig(estimator="es", es_feedback_only=True).validated()


def test_es_learns_feedback_gains_that_beat_a_still_grasp():
    """A learning test that can fail: six feedback gains learnt by es from a still grasp (their initial
    policy: zero gains hold still) cut wave-1 better than the still grasp at the same pinch on evaluation
    trials the optimiser never saw, by more than both CIs (the paired difference's too)."""
    from warpcut import plan_cut
    from warpcut.stats import paired_improvement

    contour = load_contour("wave-1")
    planned = plan_cut(contour, SMALL.replace(noise_std=0.0), num_candidates=8)
    pinch, segments = planned.chosen["pinch"], planned.ordered_segments()
    settings = GradConfig(
        estimator="es", iterations=15, learning_rate=0.2, es_population=16, es_trials=2, validation_trials=4,
        es_feedback_phases=1, es_feedback_only=True,
    )  # fmt: skip
    result = optimize_plan(contour, pinch, segments, SMALL, settings)
    assert result.best_iteration > 0 and np.abs(result.gains).max() > 0.1

    def errors(policy, point):
        points = None if point is None else [point] * 10
        task = CuttingTask(SMALL, [contour] * 10, pinch_points=points, segments=[segments] * 10, seed=7)
        return task.run(policy).error_vertices

    none = errors(None, None)
    still = paired_improvement(none, errors(None, pinch))
    learnt = paired_improvement(none, errors(PlanResult.policy([result], 10), pinch))

    def ci(values):
        return 1.96 * np.std(values, ddof=1) / np.sqrt(len(values))

    assert learnt.mean() - still.mean() > ci(learnt) + ci(still), (learnt.mean(), still.mean())
    assert (learnt - still).mean() - ci(learnt - still) > 0


def test_the_usage_guides_closed_loop_example_runs(capsys):
    """The usage guide's es block (feedback gains alone over randomised sheets) runs as written."""
    import re
    from pathlib import Path

    guide = (Path(__file__).resolve().parents[1] / "docs" / "usage.md").read_text()
    block = next(b for b in re.findall(r"```python\n(.*?)```", guide, re.S) if "es_feedback_only" in b)
    exec(compile(block, "docs/usage.md", "exec"), {})
    out = capsys.readouterr().out
    assert out.count("[") >= 3 and "nan" not in out.lower()
