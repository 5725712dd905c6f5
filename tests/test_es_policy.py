"""Evolution strategies on the neural policy's weights (agents.es, ``warpcut train --algo es``)."""

import numpy as np
import pytest
import torch

from agents.config import ES_PLAIN_NETWORK, RECIPES, Recipe, TrainConfig, algorithm_settings, batch_defaults
from warpcut import load_contour
from warpcut.sim.config import SimConfig

pytestmark = pytest.mark.usefixtures("one_torch_thread")

SMALL = SimConfig(resolution=13, noise_std=0.03)


def _es_env(num_envs: int, population: int = 2, **options):
    from agents.rl import training_env
    from envs.options import PatternCutOptions

    options = PatternCutOptions(
        contour="circle-small", sim_config=SMALL, action_type="continuous", contour_features=True, **options
    )
    cfg = TrainConfig(
        num_envs=num_envs, iterations=2, algorithm="es", discrete=False, save_interval=1,
        es_population=population, learning_rate=0.01,
    )  # fmt: skip
    return training_env(options, cfg), cfg


def test_each_env_plays_its_own_perturbed_policy():
    """The batched forward gives env ``e`` the actor with the weights of policy ``e // trials``: the same
    actions as the actor itself, loaded with those weights (its deterministic output, clipped to 1)."""
    from tensordict import TensorDict

    from agents.es import EsRunner

    env, cfg = _es_env(4)
    runner = EsRunner(env, cfg.to_rsl_rl(None), None)
    actor = runner.alg.actor
    assert np.all(runner._theta()[-runner.output_layer.bias.numel() :] == 0)  # starts still
    rng = np.random.default_rng(0)
    thetas = runner._theta() + rng.standard_normal((2, runner.num_params))
    obs = rng.standard_normal((4, actor.obs_dim)).astype(np.float32)
    moves = runner._moves(obs, runner._unpack(thetas))
    assert moves.shape == (4, env.num_actions) and np.abs(moves).max() <= 1.0
    for p in range(2):
        runner._set_theta(thetas[p])
        with torch.inference_mode():
            mine = actor(TensorDict({"policy": torch.as_tensor(obs[2 * p : 2 * p + 2])}, batch_size=[2]))
        np.testing.assert_allclose(moves[2 * p : 2 * p + 2], torch.clamp(mine, -1, 1).numpy(), atol=1e-5)
    np.testing.assert_array_equal(runner._theta(), thetas[1].astype(np.float32))


def test_es_trains_saves_and_resumes_where_it_stopped(tmp_path):
    """Two iterations then one more on resume move the weights exactly as three in one go (the episodes'
    and perturbations' stream and Adam's state are in the checkpoint)."""
    from agents.train import read_checkpoint, train

    env, cfg = _es_env(4)
    summary = train(env, cfg, tmp_path / "a", progress=False)
    assert summary["status"] == "completed" and summary["iterations"] == 2
    assert summary["env_steps"] == 2 * 4 * env.env.scene.task.num_steps  # one whole cut per env
    assert all(np.isfinite(h["final_error"]) and h["step_norm"] > 0 for h in summary["history"])
    three = TrainConfig(**{**cfg.__dict__, "iterations": 3})
    env, _ = _es_env(4)
    train(env, three, tmp_path / "a", resume=tmp_path / "a", progress=False)
    env, _ = _es_env(4)
    train(env, three, tmp_path / "b", progress=False)
    resumed = read_checkpoint(tmp_path / "a" / "latest.pt")["actor_state_dict"]
    straight = read_checkpoint(tmp_path / "b" / "latest.pt")["actor_state_dict"]
    assert resumed.keys() == straight.keys()
    for key in straight:
        torch.testing.assert_close(resumed[key], straight[key], rtol=0, atol=0)
    with pytest.raises(ValueError, match="not an ES run's checkpoint"):
        env, _ = _es_env(4)
        ppo = tmp_path / "c"
        train(
            env, TrainConfig(**{**three.__dict__, "iterations": 1, "algorithm": "ppo"}), ppo, progress=False
        )
        train(_es_env(4)[0], three, ppo, resume=ppo, progress=False)


def test_es_refuses_what_it_cannot_train(tmp_path):
    from agents.train import train

    env, cfg = _es_env(4)
    with pytest.raises(ValueError, match="algorithm: es plays continuous moves"):
        train(env, TrainConfig(**{**cfg.__dict__, "discrete": True}), "unused", progress=False)
    with pytest.raises(ValueError, match="es_population: 3 must be even .* --es-population 4"):
        train(env, TrainConfig(**{**cfg.__dict__, "es_population": 3}), tmp_path, progress=False)
    divide = r"es_population: 8 must be even \(antithetic pairs\) and divide num_envs \(4\)"
    with pytest.raises(ValueError, match=divide):
        train(env, TrainConfig(**{**cfg.__dict__, "es_population": 8}), tmp_path, progress=False)
    with pytest.raises(ValueError, match="es_sigma: must be a finite number > 0"):
        train(env, TrainConfig(**{**cfg.__dict__, "es_sigma": -1.0}), tmp_path, progress=False)
    with pytest.raises(ValueError, match="es_feedback_sigma: must be a finite number > 0"):
        train(env, TrainConfig(**{**cfg.__dict__, "es_feedback_sigma": 0.0}), tmp_path, progress=False)
    with pytest.raises(ValueError, match="es_feedback_learning_rate: must be a finite number > 0"):
        train(env, TrainConfig(**{**cfg.__dict__, "es_feedback_learning_rate": float("nan")}), tmp_path)
    assert batch_defaults("es")["num_envs"] % TrainConfig.es_population == 0
    assert algorithm_settings("es")["learning_rate"] == RECIPES["es"].train["learning_rate"]
    # an actor without the feedback path: the MLP learns alone, on the plain network's own scale
    plain = TrainConfig(**algorithm_settings("es", feedback=False))
    assert not plain.actor_feedback and plain.es_sigma == ES_PLAIN_NETWORK["es_sigma"] != TrainConfig.es_sigma
    assert plain.learning_rate == ES_PLAIN_NETWORK["learning_rate"]
    assert TrainConfig(**algorithm_settings("es")).es_sigma == TrainConfig.es_sigma


def test_es_trains_on_randomised_sheets_weighing_each_cut_by_its_sheet():
    """Unlike APG, es trains over randomised sheets: each cut's error weighed by the env's reward scale (the
    nominal sheet's no-tension error over its own), as the relative reward weighs it."""
    from agents.es import EsRunner

    env, cfg = _es_env(4, randomize=("gravity",), relative_reward=True)
    runner = EsRunner(env, cfg.to_rsl_rl(None), None)
    scene = runner.scene
    errors, _, _ = runner._episode(runner._unpack(np.tile(runner._theta(), (2, 1))))
    assert np.isfinite(errors).all() and not np.allclose(scene.reward_scale, 1.0)
    np.testing.assert_allclose(errors, scene.task.score().error_vertices * scene.reward_scale)


def test_es_learns_a_neural_policy_that_beats_a_still_grasp(tmp_path):
    """A learning test that can fail: the 2 x 32 actor trained by es from "hold still" (its output layer
    zeroed: the untrained policy is the still grasp, trial for trial) cuts edge-bite (13 x 13 sheet; holding
    still barely helps there) better than fixed tension at the same pinch by more than both CIs, and model
    selection keeps a trained iteration (~3 s of training)."""
    from agents.pipeline import evaluate_table
    from warpcut.planning import plan_cut

    contour = load_contour("edge-bite")
    plan = plan_cut(contour, SMALL.replace(noise_std=0.0), num_candidates=8, seed=0)
    recipe = Recipe(RECIPES["es"].options, {**RECIPES["es"].train, "es_population": 16})
    report = evaluate_table(
        "edge-bite", tmp_path, methods=["fixed", "rl"], trials=10, config=SMALL, plan=[plan], recipe=recipe,
        num_envs=64, iterations=20,
    )  # fmt: skip
    row = report.table["rows"][0]
    assert row["rl_policy_iteration"] > 0
    assert row["rl_improvement_pct"] - row["rl_ci95"] > row["fixed_improvement_pct"] + row["fixed_ci95"], row


def test_es_trains_as_many_whole_cuts_as_ppos_env_steps_unless_told(tmp_path, monkeypatch):
    """Without iterations es plays PPO's default run's env steps in whole cuts: a contour's iterations
    follow its episode's length (41 to 380 steps on the suite)."""
    import json

    import agents.config as config
    from agents.train import train

    assert (
        config.ES_ENV_STEPS == TrainConfig.iterations * TrainConfig.num_envs * TrainConfig.num_steps_per_env
    )
    assert config.es_iterations(256, 48) == 100 and config.es_iterations(256, 380) == 13
    assert config.es_iterations(256, 10**5) == config.ES_MIN_ITERATIONS
    assert batch_defaults("es")["iterations"] is None
    env, cfg = _es_env(4)
    steps = env.env.scene.task.num_steps
    monkeypatch.setattr(config, "ES_ENV_STEPS", 3 * 4 * steps)
    monkeypatch.setattr(config, "ES_MIN_ITERATIONS", 1)
    summary = train(env, TrainConfig(**{**cfg.__dict__, "iterations": None}), tmp_path, progress=False)
    assert summary["iterations"] == 3 and summary["env_steps"] == 3 * 4 * steps
    assert json.loads((tmp_path / "config.json").read_text())["train"]["iterations"] == 3


def test_the_feedback_path_adds_a_gain_matrix_on_the_tracking_error():
    """``actor_feedback`` (the es recipe's): the actor's output is its MLP's plus ``K`` times the normalised
    tracking error, ``K`` zero at the start; it sits where the observation names put the tracking error,
    and a policy that observes none is refused by name."""
    from tensordict import TensorDict

    from agents.models import FeedbackMLPModel, feedback_inputs
    from envs.observations import TRACKING_ERROR, observation_names
    from envs.options import PatternCutOptions

    env, cfg = _es_env(4)
    names = observation_names(env.cfg.num_fiducials, True)
    start, size = feedback_inputs(env)
    assert names[start : start + size] == list(TRACKING_ERROR) and RECIPES["es"].train["actor_feedback"]
    obs = TensorDict({"policy": torch.randn(8, len(names))}, batch_size=[8])
    rsl = TrainConfig(**{**cfg.__dict__, "actor_feedback": True}).to_rsl_rl(None, (start, size))
    model_cfg = {k: v for k, v in rsl["actor"].items() if k != "class_name"}
    actor = FeedbackMLPModel(obs, rsl["obs_groups"], "actor", 3, **model_cfg)
    assert torch.equal(actor.mlp.feedback.weight, torch.zeros(3, size))
    with torch.no_grad():
        actor.mlp.feedback.weight.normal_()
        latent = actor.get_latent(obs)
        expected = actor.mlp.body(latent) + latent[:, start : start + size] @ actor.mlp.feedback.weight.T
        torch.testing.assert_close(actor(obs), expected)
        assert (actor(obs) - actor.mlp.body(latent)).abs().max() > 0.1
    with pytest.raises(ValueError, match="feedback_inputs: \\(60, 3\\) is not a slice of the"):
        FeedbackMLPModel(obs, rsl["obs_groups"], "actor", 3, **{**model_cfg, "feedback_inputs": [60, 3]})
    blind = PatternCutOptions(contour="circle-small", sim_config=SMALL, contour_features=False)
    with pytest.raises(ValueError, match="actor_feedback: the policy observes no tracking error"):
        feedback_inputs(type("Env", (), {"cfg": blind})())
    with pytest.raises(ValueError, match="actor_feedback: needs warpcut's env"):
        feedback_inputs(object())


@pytest.mark.filterwarnings("ignore:.*torch.jit.load.* is deprecated:DeprecationWarning")
def test_es_trains_the_feedback_path_and_its_exports_play_it(tmp_path):
    """es perturbs the feedback gains with the MLP (the batched forward plays each env's own gains, as the
    actor does), training moves them off zero, a resume keeps the path, and the TorchScript and ONNX
    exports give the live actor's actions, the feedback included."""
    from onnx.reference import ReferenceEvaluator
    from tensordict import TensorDict

    from agents.es import EsRunner
    from agents.export import export_policy, load_policy
    from agents.rl import resume_settings
    from agents.train import policy_layout, read_checkpoint, train

    env, cfg = _es_env(4, population=2)
    cfg = TrainConfig(**{**cfg.__dict__, "actor_feedback": True})
    from agents.models import feedback_inputs

    runner = EsRunner(env, cfg.to_rsl_rl(None, feedback_inputs(env)), None)
    actor = runner.alg.actor
    gains = 3 * env.num_actions  # the tracking error's three entries to each move axis
    assert runner.layers[-1] is actor.mlp.feedback and np.all(runner._theta()[-gains:] == 0)
    rng = np.random.default_rng(1)
    thetas = runner._theta() + rng.standard_normal((2, runner.num_params))
    obs = rng.standard_normal((4, actor.obs_dim)).astype(np.float32)
    moves = runner._moves(obs, runner._unpack(thetas))
    for p in range(2):
        runner._set_theta(thetas[p])
        with torch.inference_mode():
            mine = actor(TensorDict({"policy": torch.as_tensor(obs[2 * p : 2 * p + 2])}, batch_size=[2]))
        np.testing.assert_allclose(moves[2 * p : 2 * p + 2], torch.clamp(mine, -1, 1).numpy(), atol=1e-5)

    env, _ = _es_env(4, population=2)
    train(env, cfg, tmp_path / "run", progress=False)
    state = read_checkpoint(tmp_path / "run" / "latest.pt")["actor_state_dict"]
    assert state["mlp.feedback.weight"].abs().max() > 0
    assert policy_layout(state) == (actor.obs_dim, env.num_actions)
    assert resume_settings(tmp_path / "run")["actor_feedback"] is True
    paths = export_policy(tmp_path / "run", tmp_path / "exported")
    live_actor = load_policy(tmp_path / "run")
    x = torch.randn(64, actor.obs_dim) * 2.0
    live = live_actor(TensorDict({"policy": x}, batch_size=[64]))
    body = live_actor.mlp.body(live_actor.obs_normalizer(x))
    assert (live - body).abs().max() > 1e-3  # the feedback path is in play
    torchscript = torch.jit.load(paths["torchscript"])(x)
    onnx = torch.from_numpy(ReferenceEvaluator(str(paths["onnx"])).run(None, {"obs": x.numpy()})[0])
    assert torch.allclose(torchscript, live, atol=1e-6) and torch.allclose(onnx, live, atol=1e-5)


def test_es_perturbs_and_steps_the_feedback_gains_on_their_own_scale():
    """The feedback gains get ``es_feedback_sigma`` and ``es_feedback_learning_rate``, the MLP's weights
    ``es_sigma`` and ``learning_rate``: the perturbations and the first Adam step (|step| = its learning
    rate wherever the gradient estimate is not zero) are on each one's scale."""
    from agents.es import EsRunner
    from agents.models import feedback_inputs

    env, cfg = _es_env(4, population=2)
    cfg = TrainConfig(**{
        **cfg.__dict__, "actor_feedback": True, "es_sigma": 1e-3, "learning_rate": 1e-4,
        "es_feedback_sigma": 1.0, "es_feedback_learning_rate": 0.5,
    })  # fmt: skip
    runner = EsRunner(env, cfg.to_rsl_rl(None, feedback_inputs(env)), None)
    gains = runner.feedback_layer.weight.numel()
    played, unpack = [], runner._unpack
    runner._unpack = lambda thetas: played.append(thetas) or unpack(thetas)
    before = runner._theta()
    runner._iteration()
    offsets = np.abs(played[-1] - before)  # the population (after the normaliser's first cut)
    assert offsets[:, :-gains].max() < 1e-2 and offsets[:, -gains:].max() > 0.3
    step = np.abs(runner._theta() - before)
    assert step[:-gains].max() <= 1.01e-4 and step[-gains:].max() > 0.4


def test_es_perturbs_its_first_population_on_normalised_observations():
    """A fresh run's normaliser learns from one cut of the initial policy before the first population plays,
    so every population sees observations on their own scale; a resumed run (a normaliser that has learned)
    plays its population at once."""
    from agents.es import EsRunner
    from agents.models import feedback_inputs

    env, cfg = _es_env(4, population=2)
    cfg = TrainConfig(**{**cfg.__dict__, "actor_feedback": True})
    runner = EsRunner(env, cfg.to_rsl_rl(None, feedback_inputs(env)), None)
    normaliser, episode = runner.alg.actor.obs_normalizer, runner._episode
    seen = []  # (the weights played, the normaliser's std when they played)
    runner._episode = lambda layers: seen.append((layers, normaliser.std.clone())) or episode(layers)
    before = runner._theta()
    runner._iteration()
    (warm, raw), (population, scaled) = seen
    assert torch.all(raw == 1.0) and not torch.allclose(scaled, raw)  # the population's scale is learned
    initial = runner._unpack(before[None])  # the warm-up cut: the initial policy in every env
    assert all(torch.equal(w, w0.expand_as(w)) for (w, _), (w0, _) in zip(warm, initial, strict=True))
    assert not torch.equal(population[-1][0], initial[-1][0].expand_as(population[-1][0]))  # then perturbed
    runner._iteration()
    assert len(seen) == 3  # one cut an iteration once the normaliser has learned


@pytest.mark.parametrize("discrete", [True, False], ids=["discrete", "continuous"])
def test_ppo_trains_the_feedback_path_too(tmp_path, discrete):
    """``actor_feedback`` is the actor's, not es's: PPO's gradient reaches the gains (logits for
    discrete moves, the Gaussian's mean for continuous ones)."""
    from agents.rl import training_env
    from agents.train import read_checkpoint, train
    from envs.options import PatternCutOptions

    options = PatternCutOptions(
        contour="circle-small", sim_config=SMALL, contour_features=True,
        action_type="discrete" if discrete else "continuous",
    )  # fmt: skip
    cfg = TrainConfig(num_envs=4, iterations=1, num_steps_per_env=8, discrete=discrete, actor_feedback=True)
    train(training_env(options, cfg), cfg, tmp_path, progress=False)
    state = read_checkpoint(tmp_path / "latest.pt")["actor_state_dict"]
    assert state["mlp.feedback.weight"].abs().max() > 0
