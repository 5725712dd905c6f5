"""Evolution strategies on the policy's weights (agents.es, the default learner): an rsl-rl algorithm that
rsl-rl's ``OnPolicyRunner`` drives, one whole cut per env an iteration, ranked by the path score."""

from __future__ import annotations

import dataclasses
import functools
import shutil

import numpy as np
import pytest
import torch
from dummy_env import EPISODE_COST_KEY, FINAL_ERROR_KEY, ReachEnv
from tensordict import TensorDict

from agents.algorithms import ALGORITHMS
from agents.checkpoints import read_checkpoint
from agents.config import TrainConfig
from agents.es.algorithm import ES
from agents.es.config import EsConfig
from agents.models import feedback_inputs
from agents.ppo.config import PpoConfig
from agents.runner import Runner
from agents.training import train, training_env
from envs.options import PatternCutOptions
from warpcut import load_contour
from warpcut.sim.config import SimConfig

pytestmark = pytest.mark.usefixtures("one_torch_thread")

SMALL = SimConfig(resolution=13, noise_std=0.03)


def es_config(num_envs: int = 8, population: int = 4, iterations: int = 2, **es) -> TrainConfig:
    """es on a small batch: ``population`` perturbed policies, ``num_envs / population`` cuts each."""
    return TrainConfig(
        algo="es", num_envs=num_envs, iterations=iterations, save_interval=1, validation_trials=0,
        es=EsConfig(population=population, **es),
    )  # fmt: skip


def es_env(cfg: TrainConfig, seed: int = 0, **options):
    """warpcut's rsl-rl env on circle-small (13 x 13 sheet) for ``cfg``'s batch."""
    return training_env(PatternCutOptions(contour="circle-small", sim_config=SMALL, **options), cfg, seed)


def es_runner(cfg: TrainConfig, env) -> Runner:
    """warpcut's rsl-rl runner for ``cfg`` on ``env``, as :func:`agents.training.train` builds it."""
    feedback = feedback_inputs(env) if cfg.feedback else None
    return Runner(env, cfg.to_rsl_rl(None, feedback, int(env.max_episode_length)), None)


def weights(path) -> dict[str, torch.Tensor]:
    return read_checkpoint(path)["actor_state_dict"]


def assert_same_weights(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        assert torch.equal(a[key], b[key]), key


def test_rsl_rls_runner_drives_es_one_whole_cut_an_iteration(tmp_path, monkeypatch):
    """es is an rsl-rl algorithm: the registry's runner is warpcut's rsl-rl runner, whose learning loop is
    rsl-rl's ``OnPolicyRunner.learn`` with ``ES`` as its algorithm; every iteration plays one whole cut in
    every env, and the checkpoints record the learner."""
    from rsl_rl.runners import OnPolicyRunner
    from rsl_rl.utils import resolve_callable

    assert resolve_callable(ALGORITHMS["es"].runner) is Runner
    assert ALGORITHMS["es"].runner == ALGORITHMS["ppo"].runner
    assert TrainConfig().algo == "gps" and TrainConfig(algo="es").learner == EsConfig()
    assert es_config().to_rsl_rl(None, (0, 3), 40)["algorithm"]["class_name"] == "agents.es.algorithm:ES"
    loops = []
    learn = OnPolicyRunner.learn

    def rsl_rl_learn(self, num_learning_iterations, init_at_random_ep_len=False):
        loops.append((type(self), type(self.alg), num_learning_iterations))
        return learn(self, num_learning_iterations, init_at_random_ep_len)

    monkeypatch.setattr(OnPolicyRunner, "learn", rsl_rl_learn)
    cfg = es_config(iterations=3)
    env = es_env(cfg)
    steps = int(env.max_episode_length)
    ended = []  # the step calls on which the batch's cut ended
    step = env.step

    def counting_step(actions):
        out = step(actions)
        ended.append(EPISODE_COST_KEY in out[3])
        return out

    monkeypatch.setattr(env, "step", counting_step)
    summary = train(env, cfg, tmp_path, progress=False)
    assert loops == [(Runner, ES, 3)]
    assert steps == env.env.scene.task.num_steps > 10
    assert len(ended) == 3 * steps
    assert [k + 1 for k, end in enumerate(ended) if end] == [steps, 2 * steps, 3 * steps]
    assert summary["status"] == "completed" and summary["algo"] == "es" and summary["iterations"] == 3
    assert summary["env_steps"] == 3 * cfg.batch_size * steps
    history = summary["history"]
    assert all(np.isfinite(h["final_error"]) and np.isfinite(h["population_cost"]) for h in history)
    assert "step_norm" not in history[0] and all(h["step_norm"] > 0 for h in history[1:])
    checkpoint = read_checkpoint(tmp_path / "latest.pt")
    assert checkpoint["algo"] == "es" and checkpoint["iter"] == 2
    assert checkpoint["policy"]["actor"]["class_name"] == "agents.models:FeedbackMLPModel"


@pytest.mark.parametrize("whole", [False, True], ids=["shorter", "longer"])
def test_es_refuses_an_iteration_that_is_not_one_cut(whole):
    """rsl-rl's loop must step exactly one episode an iteration: shorter, the iteration ends before the cut
    has a cost; longer, a second cut would end within it. Both are refused by name."""
    env = ReachEnv(4, discrete=False, horizon=6)
    cfg = es_config(num_envs=4, population=2, feedback=False)
    rsl = cfg.to_rsl_rl(None, None, 6)
    rsl["num_steps_per_env"] = 12 if whole else 5
    runner = Runner(env, rsl, None)
    match = "must be whole iterations" if whole else "the iteration ended before the cut did"
    with pytest.raises(ValueError, match=match):
        runner.learn(1)


@pytest.mark.parametrize("feedback", [False, True], ids=["mlp", "feedback"])
def test_each_env_plays_its_own_perturbed_policy(feedback):
    """The batched forward gives env ``e`` the actor with the weights of policy ``e // trials``: the same
    actions as the actor itself, loaded with those weights (its deterministic output, clipped to 1), the
    feedback path included; the untrained actor holds still."""
    cfg = es_config(num_envs=4, population=2, feedback=feedback)
    env = es_env(cfg)
    alg = es_runner(cfg, env).alg
    actor = alg.actor
    assert isinstance(alg, ES) and alg.trials == 2
    assert (alg.feedback_layer is not None) == feedback
    if feedback:
        gains = 3 * env.num_actions  # the tracking error's three entries to each move axis
        assert alg.layers[-1] is actor.mlp.feedback and np.all(alg._theta()[-gains:] == 0)
    rng = np.random.default_rng(0)
    obs = TensorDict(
        {"policy": torch.as_tensor(rng.standard_normal((4, actor.obs_dim)), dtype=torch.float32)}, [4]
    )
    with torch.inference_mode():
        assert torch.equal(actor(obs), torch.zeros(4, env.num_actions))  # starts still
    thetas = alg._theta() + rng.standard_normal((2, alg.num_params))
    alg._batch = alg._unpack(thetas)
    with torch.inference_mode():
        moves = torch.clamp(alg._forward(actor.get_latent(obs)), -1.0, 1.0)
    assert moves.shape == (4, env.num_actions) and moves.abs().max() <= 1.0
    for p in range(2):
        alg._set_theta(thetas[p])
        with torch.inference_mode():
            mine = torch.clamp(actor(obs[2 * p : 2 * p + 2]), -1.0, 1.0)
        torch.testing.assert_close(moves[2 * p : 2 * p + 2], mine, atol=1e-5, rtol=0)
    np.testing.assert_array_equal(alg._theta(), thetas[1].astype(np.float32))


def _scripted_es(seed: int = 0, population: int = 256) -> tuple[ES, TensorDict]:
    """es on the reach env with a tiny actor (17 weights) and one episode per perturbed policy, past its
    warm-up iteration."""
    torch.manual_seed(seed)
    env = ReachEnv(population, discrete=False)
    cfg = dataclasses.replace(
        es_config(num_envs=population, population=population, feedback=False, sigma=0.1, learning_rate=0.01),
        actor_hidden_dims=[4],
    )
    alg = Runner(env, cfg.to_rsl_rl(None, None, env.max_episode_length), None).alg
    obs = env.get_observations()
    alg.act(obs)  # the warm-up: no perturbations, the normaliser learns
    alg.process_env_step(
        obs, torch.zeros(population), torch.ones(population), {EPISODE_COST_KEY: torch.zeros(population)}
    )
    alg.update()
    return alg, obs


def _scripted_step(alg: ES, obs: TensorDict, cost, rewards=None) -> tuple[np.ndarray, dict]:
    """One es iteration whose cut costs ``cost(eps)`` per perturbed policy; the step it takes."""
    before = alg._theta()
    alg.act(obs)
    costs = torch.as_tensor(np.repeat(cost(alg._eps), alg.trials))
    rewards = torch.zeros(len(costs)) if rewards is None else rewards(costs)
    alg.process_env_step(obs, rewards.float(), torch.ones(len(costs)), {EPISODE_COST_KEY: costs})
    losses = alg.update()
    return alg._theta() - before, losses


def test_es_steps_against_the_path_cost_not_the_reward():
    """es ranks its population by the cut's cost (``extras["episode_cost"]``, the path error), not by the
    reward: with costs that grow along a direction of weight space (and rewards that would say the opposite),
    its step goes against that direction; with the costs reversed, along it."""
    direction = np.random.default_rng(5).standard_normal(17)
    alg, obs = _scripted_es()
    assert alg.num_params == 17 and alg._eps is None
    step, losses = _scripted_step(alg, obs, lambda eps: eps @ direction, rewards=lambda costs: costs)
    cosine = step @ direction / np.linalg.norm(step) / np.linalg.norm(direction)
    assert cosine < -0.5, cosine
    assert losses["best_cost"] < losses["population_cost"]
    assert losses["step_norm"] == pytest.approx(np.linalg.norm(step))
    alg, obs = _scripted_es()
    reverse, _ = _scripted_step(alg, obs, lambda eps: -(eps @ direction))
    # the same perturbations, ranked the other way
    np.testing.assert_allclose(reverse, -step, rtol=0, atol=1e-6)


def test_a_diverged_cut_ranks_its_policy_last():
    """A NaN cost (the env diverged) ranks its policy below every finite one: the step is the one a huge
    cost gives; the population's mean cost leaves it out."""

    def cost(eps, diverged):
        values = eps[:, 0].copy()
        values[np.argmin(values)] = diverged  # the best policy diverged
        return values

    alg, obs = _scripted_es()
    nan_step, losses = _scripted_step(alg, obs, lambda eps: cost(eps, np.nan))
    alg, obs = _scripted_es()
    huge_step, _ = _scripted_step(alg, obs, lambda eps: cost(eps, 1e9))
    np.testing.assert_array_equal(nan_step, huge_step)
    assert np.isfinite(losses["population_cost"])


def test_es_learns_to_reach_on_the_dummy_env(tmp_path):
    """A learning test that can fail: es from "hold still" (final error ~2.2 on the reach task) on rsl-rl's
    loop, ranking by ``extras["episode_cost"]``, ends near the target."""
    cfg = dataclasses.replace(
        es_config(num_envs=64, population=32, iterations=60, feedback=False, sigma=0.05, learning_rate=0.02),
        save_interval=10**6,
    )
    summary = train(ReachEnv(64, discrete=False), cfg, tmp_path, progress=False)
    first, last = summary["history"][0], summary["history"][-1]
    assert first["final_error"] > 1.5
    assert last["final_error"] < 0.4 * first["final_error"], [h["final_error"] for h in summary["history"]]


def test_the_first_iteration_only_teaches_the_normaliser():
    """A fresh run's first iteration plays the initial policy in every env: the weights stay, the
    observation normaliser learns from every step of the cut, so the first population is perturbed on the
    scale the later ones are; the next iteration steps the weights. A run that loads a checkpoint whose
    normaliser has learned plays its population at once."""
    cfg = es_config(num_envs=8, population=4)
    env = es_env(cfg)
    runner = es_runner(cfg, env)
    alg, normaliser = runner.alg, runner.alg.actor.obs_normalizer
    steps = int(env.max_episode_length)
    played = []
    unpack = alg._unpack
    alg._unpack = lambda thetas: played.append(np.array(thetas)) or unpack(thetas)
    before = alg._theta()
    assert int(normaliser.count) == 0
    runner.learn(1)
    np.testing.assert_array_equal(alg._theta(), before)
    np.testing.assert_array_equal(played[0], np.repeat(before[None], 4, axis=0))  # the initial policy
    assert int(normaliser.count) == 8 * steps
    assert not torch.allclose(normaliser.std, torch.ones_like(normaliser.std))
    runner.learn(1)
    assert not np.array_equal(alg._theta(), before) and int(normaliser.count) == 2 * 8 * steps
    assert not np.allclose(played[1], before)  # perturbed

    state = runner.alg.save()
    fresh = es_runner(cfg, es_env(cfg))
    fresh.alg.load(state, None, True)
    fresh_unpack = fresh.alg._unpack
    fresh.alg._unpack = lambda thetas: played.append(np.array(thetas)) or fresh_unpack(thetas)
    fresh.learn(1)
    assert not np.allclose(played[2], alg._theta())  # no warm-up after a load


def test_es_perturbs_and_steps_the_feedback_gains_on_their_own_scale():
    """The feedback gains get ``es.feedback_sigma`` and ``es.feedback_learning_rate``, the MLP's weights
    ``es.sigma`` and ``es.learning_rate``: the perturbations and the first Adam step (|step| = its learning
    rate wherever the gradient estimate is not zero) are on each one's scale."""
    scales = {"sigma": 1e-3, "learning_rate": 1e-4, "feedback_sigma": 1.0, "feedback_learning_rate": 0.5}
    cfg = es_config(num_envs=4, population=2, **scales)
    env = es_env(cfg)
    runner = es_runner(cfg, env)
    alg = runner.alg
    gains = alg.feedback_layer.weight.numel()
    played, unpack = [], alg._unpack
    alg._unpack = lambda thetas: played.append(np.array(thetas)) or unpack(thetas)
    before = alg._theta()
    runner.learn(2)  # the warm-up, then the first population
    offsets = np.abs(played[-1] - before)
    assert offsets[:, :-gains].max() < 1e-2 and offsets[:, -gains:].max() > 0.3
    step = np.abs(alg._theta() - before)
    assert step[:-gains].max() <= 1.01e-4 and step[-gains:].max() > 0.4


@pytest.mark.parametrize("randomize", [(), ("gravity",)], ids=["nominal", "gravity"])
def test_a_resumed_es_run_ends_with_the_weights_of_an_uninterrupted_one(tmp_path, randomize):
    """Three iterations, then two more on resume, end with exactly the weights of five in one go: the
    perturbations' stream, Adam's state, the normaliser and the episodes' stream (the randomised sheets
    included) are in the checkpoint."""
    cfg = es_config(iterations=3)
    five = dataclasses.replace(cfg, iterations=5)
    first = train(es_env(cfg, 3, randomize=randomize), cfg, tmp_path / "a", seed=3, progress=False)
    assert first["iterations"] == 3
    resumed = train(
        es_env(cfg, 3, randomize=randomize),
        five,
        tmp_path / "a",
        seed=3,
        resume=tmp_path / "a",
        progress=False,
    )
    straight = train(es_env(cfg, 3, randomize=randomize), five, tmp_path / "b", seed=3, progress=False)
    assert resumed["iterations"] == straight["iterations"] == 5
    assert_same_weights(weights(tmp_path / "a" / "latest.pt"), weights(tmp_path / "b" / "latest.pt"))
    assert [h["population_cost"] for h in resumed["history"]] == [
        h["population_cost"] for h in straight["history"]
    ]
    # ... and not by chance: another seed ends elsewhere.
    train(es_env(cfg, 4, randomize=randomize), five, tmp_path / "c", seed=4, progress=False)
    other = weights(tmp_path / "c" / "latest.pt")
    assert not torch.equal(
        other["mlp.feedback.weight"], weights(tmp_path / "b" / "latest.pt")["mlp.feedback.weight"]
    )


def test_an_es_run_stopped_mid_cut_resumes_as_if_never_stopped(tmp_path, monkeypatch):
    """Ctrl-C in the middle of an iteration's cut (the warm-up's, then a population's) saves the state of the
    last completed iteration; resuming from it ends with exactly the weights of a run never stopped."""
    cfg = es_config(iterations=3)
    straight = train(es_env(cfg, 1), cfg, tmp_path / "straight", seed=1, progress=False)
    steps = straight["env_steps"] // (3 * cfg.batch_size)
    run = tmp_path / "stopped"
    for stop_at in (steps // 2, 2 * steps + steps // 2):  # in iteration 1 (the warm-up), then in iteration 3
        env = es_env(cfg, 1)
        calls = {"n": 0}
        step = env.step

        def interrupting_step(actions, stop_at=stop_at, calls=calls, step=step):
            calls["n"] += 1
            if calls["n"] > stop_at:
                raise KeyboardInterrupt
            return step(actions)

        monkeypatch.setattr(env, "step", interrupting_step)
        with pytest.raises(KeyboardInterrupt):
            train(env, cfg, run, seed=1, resume=run if (run / "latest.pt").exists() else None, progress=False)
        monkeypatch.undo()
    assert read_checkpoint(run / "latest.pt")["infos"]["iterations_done"] == 2
    summary = train(es_env(cfg, 1), cfg, run, seed=1, resume=run, progress=False)
    assert summary["iterations"] == 3
    assert_same_weights(weights(run / "latest.pt"), weights(tmp_path / "straight" / "latest.pt"))


def test_es_refuses_what_it_cannot_train(tmp_path):
    cfg = es_config(num_envs=4, population=2)
    env = es_env(cfg)
    discrete = es_env(cfg, action_type="discrete")
    with pytest.raises(ValueError, match="algo: es plays continuous moves; set env.action_type=continuous"):
        train(discrete, cfg, tmp_path / "x", progress=False)
    bad = {
        "population": (3, r"es.population: must be an even integer >= 2, antithetic pairs \(got 3\)"),
        "sigma": (-1.0, r"es.sigma: must be a finite number > 0"),
        "feedback_sigma": (0.0, r"es.feedback_sigma: must be a finite number > 0"),
        "feedback_learning_rate": (float("nan"), r"es.feedback_learning_rate: must be a finite number > 0"),
    }
    for name, (value, match) in bad.items():
        with pytest.raises(ValueError, match=match):
            es = EsConfig(**{"population": 2, name: value})
            train(env, dataclasses.replace(cfg, es=es), tmp_path / "x", progress=False)
    divide = (
        r"es.population: 8 must divide num_envs \(4\), each perturbed policy .*; e.g. train.es.population=4"
    )
    with pytest.raises(ValueError, match=divide):
        train(env, dataclasses.replace(cfg, es=EsConfig(population=8)), tmp_path / "x", progress=False)
    with pytest.raises(ValueError, match=r"num_envs: the env has 4 envs but the config asks for 8"):
        train(env, es_config(num_envs=8), tmp_path / "x", progress=False)
    truncated = es_env(cfg, max_episode_steps=5)
    with pytest.raises(ValueError, match=r"env.max_episode_steps: es plays whole cuts \(\d+ steps\), not 5"):
        train(truncated, cfg, tmp_path / "x", progress=False)
    blind = es_env(cfg, contour_features=False)
    with pytest.raises(
        ValueError, match=r"feedback: the policy observes no tracking error \(env.contour_features=false\)"
    ):
        train(blind, cfg, tmp_path / "x", progress=False)
    assert not (tmp_path / "x" / "latest.pt").exists()
    assert ALGORITHMS["es"].num_envs % EsConfig().population == 0  # the defaults fit together
    # another learner's checkpoint is not resumed as es's
    ppo = dataclasses.replace(cfg, algo="ppo", iterations=1, ppo=PpoConfig(num_steps_per_env=4))
    train(es_env(cfg), ppo, tmp_path / "ppo", progress=False)
    with pytest.raises(
        ValueError, match=r"latest.pt: a checkpoint of 'ppo', not of 'es'; resume it with its own algo"
    ):
        train(es_env(cfg), cfg, tmp_path / "ppo", resume=tmp_path / "ppo", progress=False)


def test_es_trains_on_randomised_sheets_weighing_each_cut_by_its_sheet():
    """Unlike APG, es trains over randomised sheets: each cut's cost is its path error weighed by the env's
    reward scale (the nominal sheet's no-tension error over its own sheet's), as the relative reward weighs
    it; and its perturbed policies cut the same sheets (common random numbers)."""
    cfg = es_config(num_envs=8, population=2, iterations=1)
    env = es_env(cfg, randomize=("gravity",), relative_reward=True)
    runner = es_runner(cfg, env)
    assert env.common_sheets == 2
    env.seed(0)  # the next reset draws the common sheets
    scales, ends = [], []
    step = env.step

    def recording_step(actions):
        scales.append(np.array(env.env.scene.reward_scale, dtype=np.float64))
        out = step(actions)
        if EPISODE_COST_KEY in out[3]:
            ends.append(out[3])
        return out

    env.step = recording_step
    runner.learn(1)
    (extras,) = ends
    scale = scales[-1]
    costs = extras[EPISODE_COST_KEY].numpy()
    assert not np.allclose(scale, 1.0) and len(set(scale[:4])) > 1
    np.testing.assert_array_equal(scale[4:], scale[:4])  # both policies cut the same four sheets
    np.testing.assert_allclose(costs, extras["log"][FINAL_ERROR_KEY].double().numpy() * scale, rtol=1e-6)
    assert runner.history[0]["population_cost"] == pytest.approx(costs.mean())


def test_es_trains_as_many_whole_cuts_as_ppos_env_steps_unless_told(tmp_path, monkeypatch):
    """Without iterations es plays PPO's default run's env steps in whole cuts: a contour's iterations
    follow its episode's length (41 to 380 steps on the suite)."""
    import agents.algorithms as es_settings

    ppo = ALGORITHMS["ppo"]
    assert es_settings.ENV_STEPS == ppo.iterations * ppo.num_envs * PpoConfig().num_steps_per_env
    iterations = functools.partial(es_settings.default_iterations, "es")
    assert iterations(256, 48) == 100 and iterations(256, 380) == 13
    assert iterations(256, 10**5) == es_settings.MIN_ITERATIONS
    assert es_settings.default_iterations("gps", 256, 48) == 50  # half of es's env steps
    assert ALGORITHMS["es"].iterations is None and TrainConfig(algo="es").total_iterations(48) == 100
    cfg = dataclasses.replace(es_config(), iterations=None)
    env = es_env(cfg)
    steps = int(env.max_episode_length)
    monkeypatch.setattr(es_settings, "ENV_STEPS", 3 * 8 * steps)
    monkeypatch.setattr(es_settings, "MIN_ITERATIONS", 1)
    summary = train(env, cfg, tmp_path, progress=False)
    assert summary["iterations"] == 3 and summary["env_steps"] == 3 * 8 * steps


def test_the_feedback_path_adds_a_gain_matrix_on_the_tracking_error():
    """``es.feedback`` (the default): the actor's output is its MLP's plus ``K`` times the normalised
    tracking error, ``K`` zero at the start; it sits where the observation names put the tracking error,
    and a policy that observes none is refused by name."""
    from agents.models import FeedbackMLPModel
    from envs.observations import TRACKING_ERROR, observation_names

    cfg = es_config(num_envs=4, population=2)
    env = es_env(cfg)
    names = observation_names(env.cfg.num_fiducials, True)
    start, size = feedback_inputs(env)
    assert names[start : start + size] == list(TRACKING_ERROR) and TrainConfig().feedback
    assert not TrainConfig(algo="ppo").feedback and not TrainConfig(algo="apg").feedback
    obs = TensorDict({"policy": torch.randn(8, len(names))}, batch_size=[8])
    rsl = cfg.to_rsl_rl(None, (start, size), 40)
    assert rsl["actor"]["class_name"] == "agents.models:FeedbackMLPModel"
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
    with pytest.raises(ValueError, match="feedback: the actor's feedback path needs the tracking error"):
        cfg.to_rsl_rl(None, None, 40)
    blind = PatternCutOptions(contour="circle-small", sim_config=SMALL, contour_features=False)
    with pytest.raises(ValueError, match="feedback: the policy observes no tracking error"):
        feedback_inputs(type("Env", (), {"cfg": blind})())
    with pytest.raises(ValueError, match="feedback: the actor's feedback path needs warpcut's env"):
        feedback_inputs(object())


def test_scaling_an_actors_moves_scales_its_output_exactly():
    """:func:`agents.models.scale_moves_` (fine-tuning's ``init_gain``): the last layer and the feedback
    gains, static and scheduled, scaled; the output scales with them, and 1 changes nothing."""
    from agents.models import FeedbackMLP, scale_moves_

    torch.manual_seed(0)
    for body, scheduled in (
        (torch.nn.Sequential(torch.nn.Linear(10, 16), torch.nn.Tanh(), torch.nn.Linear(16, 3)), True),
        (torch.nn.Sequential(torch.nn.Linear(10, 16), torch.nn.Tanh(), torch.nn.Linear(16, 3)), False),
    ):
        mlp = FeedbackMLP(body, 4, 3, scheduled)
        with torch.no_grad():
            mlp.feedback.weight.normal_()
        x = torch.randn(5, 10)
        before = mlp(x).detach()
        scale_moves_(mlp, 1.0)
        assert torch.equal(mlp(x).detach(), before)
        scale_moves_(mlp, 0.5)
        torch.testing.assert_close(mlp(x).detach(), 0.5 * before)
    plain = torch.nn.Sequential(torch.nn.Linear(10, 16), torch.nn.Tanh(), torch.nn.Linear(16, 3))
    x, hidden = torch.randn(5, 10), plain[0].weight.detach().clone()
    before = plain(x).detach()
    scale_moves_(plain, 1.5)
    torch.testing.assert_close(plain(x).detach(), 1.5 * before)
    assert torch.equal(plain[0].weight, hidden)  # the hidden layer as it was


@pytest.mark.filterwarnings("ignore:.*torch.jit.load.* is deprecated:DeprecationWarning")
def test_es_trains_the_feedback_path_and_its_exports_play_it(tmp_path):
    """Training moves the feedback gains off zero; the checkpoint describes the actor with its feedback
    path, so the policy loads from the file alone, and the TorchScript and ONNX exports give the live
    actor's actions, the feedback included."""
    from onnx.reference import ReferenceEvaluator

    from agents.checkpoints import policy_layout
    from agents.export import export_policy
    from agents.policies import load_policy

    cfg = es_config(num_envs=4, population=2, iterations=3)
    env = es_env(cfg)
    train(env, cfg, tmp_path / "run", progress=False)
    state = read_checkpoint(tmp_path / "run" / "latest.pt")
    assert state["actor_state_dict"]["mlp.feedback.weight"].abs().max() > 0
    assert policy_layout(state["actor_state_dict"]) == (
        env.get_observations()["policy"].shape[1],
        env.num_actions,
    )
    alone = tmp_path / "elsewhere" / "policy.pt"
    alone.parent.mkdir()
    shutil.copy(tmp_path / "run" / "latest.pt", alone)
    live_actor = load_policy(alone)
    assert_same_weights(live_actor.state_dict(), state["actor_state_dict"])
    paths = export_policy(alone, tmp_path / "exported")
    x = torch.randn(64, live_actor.obs_dim) * 2.0
    live = live_actor(TensorDict({"policy": x}, batch_size=[64]))
    body = live_actor.mlp.body(live_actor.obs_normalizer(x))
    assert (live - body).abs().max() > 1e-3  # the feedback path is in play
    torchscript = torch.jit.load(paths["torchscript"])(x)
    onnx = torch.from_numpy(ReferenceEvaluator(str(paths["onnx"])).run(None, {"obs": x.numpy()})[0])
    assert torch.allclose(torchscript, live, atol=1e-6) and torch.allclose(onnx, live, atol=1e-5)


@pytest.mark.parametrize("discrete", [True, False], ids=["discrete", "continuous"])
def test_ppo_trains_the_feedback_path_too(tmp_path, discrete):
    """``ppo.feedback`` gives PPO's actor the same path: its gradient reaches the gains (logits for
    discrete moves, the Gaussian's mean for continuous ones)."""
    cfg = TrainConfig(algo="ppo", num_envs=4, iterations=1, ppo=PpoConfig(num_steps_per_env=8, feedback=True))
    env = es_env(cfg, action_type="discrete" if discrete else "continuous")
    train(env, cfg, tmp_path, progress=False)
    state = read_checkpoint(tmp_path / "latest.pt")["actor_state_dict"]
    assert state["mlp.feedback.weight"].abs().max() > 0


def test_es_learns_a_neural_policy_that_beats_a_still_grasp(tmp_path):
    """A learning test that can fail: the 2 x 32 actor with its feedback path, trained by es from "hold
    still" (its output layer zeroed: the untrained policy is the still grasp, trial for trial), cuts
    edge-bite (13 x 13 sheet; holding still barely helps there) better than fixed tension at the same pinch
    by more than both CIs, and model selection keeps a trained iteration (~5 s)."""
    from agents.jobs import EvaluateJob
    from agents.pipelines import evaluate_table
    from warpcut.planning import plan_cut

    plan = plan_cut(load_contour("edge-bite"), SMALL.replace(noise_std=0.0), num_candidates=8, seed=0)
    job = EvaluateJob(
        contours=["edge-bite"], methods=["fixed", "rl"], trials=10, sim=SMALL,
        train=TrainConfig(algo="es", num_envs=64, iterations=20, es=EsConfig(population=16)),
    )  # fmt: skip
    report = evaluate_table(job, tmp_path / "table", plans=[plan])
    row = report.table["rows"][0]
    assert row["rl_policy_iteration"] > 0
    assert row["rl_improvement_pct"] - row["rl_ci95"] > row["fixed_improvement_pct"] + row["fixed_ci95"], row
