"""Training on rsl-rl (agents.training) with PPO: the categorical distribution, run directories, learning,
resume, Ctrl-C, export."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from dummy_env import FINAL_ERROR_KEY, ReachEnv
from onnx.reference import ReferenceEvaluator
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from tensordict import TensorDict

from agents.checkpoints import BEST_CHECKPOINT, policy_checkpoint
from agents.config import TrainConfig
from agents.export import export_policy
from agents.policies import load_policy
from agents.ppo.config import PpoConfig
from agents.ppo.distributions import Categorical
from agents.runner import FINAL_ERROR_KEY as TRAIN_FINAL_ERROR_KEY
from agents.runner import Runner
from agents.training import train

NUM_ENVS = 32


def tiny_config(stay_prior: float = 0.0, **overrides) -> TrainConfig:
    """Small PPO settings for the dummy env, from a uniform initial policy (``stay_prior=0``: the dummy
    env's action 0 is not "stay")."""
    ppo = PpoConfig(num_steps_per_env=24, stay_prior=stay_prior)
    defaults = {"algo": "ppo", "num_envs": NUM_ENVS, "iterations": 3, "ppo": ppo}
    return TrainConfig(**{**defaults, **overrides})


def mean_final_error(env: ReachEnv, policy, episodes: int = 4) -> float:
    """Mean final error of ``policy(obs) -> actions`` over ``episodes`` episodes of every env."""
    errors = []
    obs = env.get_observations()
    with torch.inference_mode():
        while len(errors) < episodes:
            obs, _, _, extras = env.step(policy(obs))
            if FINAL_ERROR_KEY in extras["log"]:
                errors.append(extras["log"][FINAL_ERROR_KEY].mean().item())
    return float(np.mean(errors))


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory) -> str:
    """A discrete policy trained until it reaches the target (about 2 s)."""
    run_dir = tmp_path_factory.mktemp("trained")
    train(ReachEnv(NUM_ENVS), tiny_config(iterations=20), run_dir, progress=False)
    return str(run_dir)


def test_categorical_matches_torch_and_starts_uniform():
    dist = Categorical(output_dim=2, num_choices=3)
    logits = torch.randn(5, 2, 3)
    dist.update(logits)
    actions = dist.sample()
    reference = torch.distributions.Categorical(logits=logits)
    assert actions.shape == (5, 2) and actions.dtype == torch.float32
    assert torch.allclose(dist.log_prob(actions), reference.log_prob(actions.long()).sum(-1))
    assert torch.allclose(dist.entropy, reference.entropy().sum(-1))
    assert torch.equal(dist.deterministic_output(logits), logits.argmax(-1).float())
    assert torch.allclose(dist.kl_divergence(dist.params, dist.params), torch.zeros(5), atol=1e-6)
    probs = reference.probs
    assert torch.allclose(dist.probs, probs)
    assert torch.allclose(dist.mean, (probs * torch.arange(3.0)).sum(-1))
    other = torch.randn(5, 2, 3)
    expected = torch.distributions.kl_divergence(reference, torch.distributions.Categorical(logits=other))
    dist_other = Categorical(output_dim=2, num_choices=3)
    dist_other.update(other)
    assert torch.allclose(dist.kl_divergence(dist.params, dist_other.params), expected.sum(-1), atol=1e-6)
    # A choice the new policy cannot take costs infinity; one the old could not take costs nothing.
    impossible = torch.tensor([[[0.0, -torch.inf, 0.0]]])
    assert dist.kl_divergence((impossible.log_softmax(-1),), (torch.zeros(1, 1, 3),)).isfinite().all()
    assert dist.kl_divergence((torch.zeros(1, 1, 3),), (impossible.log_softmax(-1),)).isinf().all()

    # Samples follow the probabilities: 20,000 draws of each of 5 x 2 distributions, within 4 sigma.
    torch.manual_seed(0)
    dist.update(logits.expand(20_000, 5, 2, 3))
    draws = dist.sample().long()
    frequencies = torch.nn.functional.one_hot(draws, 3).float().mean(0)
    sigma = (probs * (1 - probs) / 20_000).sqrt()
    assert torch.all((frequencies - probs).abs() < 4 * sigma + 1e-4)

    env = ReachEnv(num_envs=4)
    cfg = tiny_config(num_envs=4).to_rsl_rl(env.num_action_choices)
    actor = Runner(env, cfg, log_dir=None).alg.get_policy()
    actor(env.get_observations(), stochastic_output=True)
    assert torch.allclose(actor.output_entropy, torch.full((4,), float(np.log(3))), atol=1e-3)


def test_stay_prior_starts_at_choice_zero():
    env = ReachEnv(num_envs=4)
    cfg = tiny_config(num_envs=4, stay_prior=0.8).to_rsl_rl(env.num_action_choices)
    actor = Runner(env, cfg, log_dir=None).alg.get_policy()
    obs = env.get_observations()
    actor(obs, stochastic_output=True)
    probs = actor.distribution.probs
    assert torch.allclose(probs, torch.tensor([0.8, 0.1, 0.1]).expand_as(probs), atol=1e-2)
    assert torch.equal(actor(obs), torch.zeros(4, 1))
    for kwargs, match in (
        ({"init_choice": 3, "init_choice_prob": 0.8}, "init_choice"),
        ({"init_choice": 0, "init_choice_prob": 1.0}, "init_choice_prob"),
        ({"init_choice": 0, "init_choice_prob": 0.2}, "init_choice_prob"),
    ):
        with pytest.raises(ValueError, match=match):
            Categorical(output_dim=1, num_choices=3, **kwargs)


class ScriptedValidation:
    """Returns the scripted errors in turn and remembers the actor's weights at each call."""

    def __init__(self, errors: list[float]) -> None:
        self.errors, self.calls, self.weights = list(errors), 0, []

    def __call__(self, actor):
        assert not actor.training
        self.weights.append({k: v.clone() for k, v in actor.state_dict().items()})
        self.calls += 1
        return self.errors[self.calls - 1]


def test_validation_keeps_the_best_policy(tmp_path):
    validate = ScriptedValidation([5.0, 3.0, 4.0, 9.0])
    summary = train(
        ReachEnv(NUM_ENVS),
        tiny_config(iterations=6, validation_interval=2),
        tmp_path,
        progress=False,
        validate=validate,
    )
    assert [v["iterations"] for v in summary["validation"]] == [0, 2, 4, 6]
    assert [v["error"] for v in summary["validation"]] == [5.0, 3.0, 4.0, 9.0]
    assert summary["best"] == {"iterations": 2, "validation_error": 3.0, "validation_score": 3.0}
    best = torch.load(tmp_path / BEST_CHECKPOINT, weights_only=True)
    assert best["infos"]["iterations_done"] == 2
    assert policy_checkpoint(tmp_path) == tmp_path / BEST_CHECKPOINT
    policy = load_policy(tmp_path).state_dict()
    for name, value in validate.weights[1].items():
        assert torch.equal(policy[name], value), name
    assert [event.step for event in _scalars(tmp_path, "Validation/error")] == [2, 4, 6]

    # Resuming keeps the best so far: a later, worse policy does not replace it.
    summary = train(
        ReachEnv(NUM_ENVS),
        tiny_config(iterations=8, validation_interval=2),
        tmp_path,
        resume=tmp_path,
        progress=False,
        validate=ScriptedValidation([3.5]),
    )
    assert [v["iterations"] for v in summary["validation"]] == [0, 2, 4, 6, 8]
    assert summary["best"] == {"iterations": 2, "validation_error": 3.0, "validation_score": 3.0}
    assert torch.load(tmp_path / BEST_CHECKPOINT, weights_only=True)["infos"]["iterations_done"] == 2


@pytest.mark.parametrize("margin, kept", [(0.0, 6), (1.0, 4)])
def test_selection_needs_a_paired_gain_beyond_validation_noise(tmp_path, margin, kept):
    still = [5.0, 5.0, 5.0, 5.0]  # the initial policy's error on each of 4 validation episodes
    steady = [4.0, 4.2, 3.8, 4.0]  # 1 vertex better on every episode
    lucky = [0.5, 8.0, 0.5, 6.0]  # a lower mean (3.75), but worse than still on half the episodes
    validate = ScriptedValidation([np.array(e) for e in (still, [2.0, 8.0, 2.0, 8.0], steady, lucky)])
    cfg = tiny_config(iterations=6, validation_interval=2, selection_margin=margin)
    summary = train(ReachEnv(NUM_ENVS), cfg, tmp_path, progress=False, validate=validate)
    assert [v["error"] for v in summary["validation"]] == [5.0, 5.0, 4.0, 3.75]
    assert summary["best"]["iterations"] == kept
    se = np.std(np.subtract(lucky, still), ddof=1) / 2
    assert summary["validation"][3]["score"] == pytest.approx(3.75 + margin * se)
    assert torch.load(tmp_path / BEST_CHECKPOINT, weights_only=True)["infos"]["iterations_done"] == kept

    # Resuming scores against the same baseline: the initial policy's episodes, kept in the checkpoint.
    validate = ScriptedValidation([np.array([3.9, 4.1, 3.7, 3.9])])
    cfg = tiny_config(iterations=8, validation_interval=2, selection_margin=margin)
    summary = train(ReachEnv(NUM_ENVS), cfg, tmp_path, resume=tmp_path, progress=False, validate=validate)
    assert summary["best"]["iterations"] == (6 if margin == 0 else 8)
    with pytest.raises(ValueError, match="same episodes"):
        train(
            ReachEnv(NUM_ENVS), tiny_config(iterations=10, validation_interval=2), tmp_path,
            resume=tmp_path, progress=False, validate=ScriptedValidation([np.ones(3)]),
        )  # fmt: skip
    with pytest.raises(ValueError, match="selection_margin"):
        train(ReachEnv(NUM_ENVS), tiny_config(selection_margin=-1.0), tmp_path / "bad", progress=False)


def test_without_validation_the_latest_checkpoint_is_the_policy(trained_run):
    assert policy_checkpoint(trained_run).name == "latest.pt"


@pytest.mark.parametrize("discrete", [True, False], ids=["discrete", "continuous"])
def test_smoke_run_writes_run_directory(tmp_path, discrete):
    summary = train(ReachEnv(NUM_ENVS, discrete=discrete), tiny_config(), tmp_path, progress=True)

    assert summary == json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["iterations"] == 3 and summary["algo"] == "ppo"
    assert summary["env_steps"] == 3 * 24 * NUM_ENVS
    assert summary["checkpoint"] == "model_2.pt" and summary["final_error"] is not None
    assert [h["iteration"] for h in summary["history"]] == [1, 2, 3]
    assert summary["history"][-1]["final_error"] == summary["final_error"]
    checkpoint = torch.load(tmp_path / "latest.pt", weights_only=True)
    assert checkpoint["iter"] == 2 and checkpoint["infos"]["iterations_done"] == 3
    # Every checkpoint names its learner and describes its policy (what load_policy rebuilds it from).
    assert checkpoint["algo"] == "ppo"
    policy = checkpoint["policy"]
    assert policy["obs_shapes"] == {"policy": [2]} and policy["num_actions"] == 1
    assert policy["num_action_choices"] == (3 if discrete else None)
    assert policy["actor"] == tiny_config().to_rsl_rl(3 if discrete else None)["actor"]
    assert {"model_0.pt", "model_2.pt"} <= {p.name for p in tmp_path.glob("model_*.pt")}

    assert TRAIN_FINAL_ERROR_KEY == FINAL_ERROR_KEY
    for tag in (FINAL_ERROR_KEY, "Train/mean_reward", "Perf/total_fps", "Loss/surrogate"):
        assert [event.step for event in _scalars(tmp_path, tag)] == [0, 1, 2]


def test_same_seed_same_weights(tmp_path):
    for run in ("a", "b"):
        train(ReachEnv(NUM_ENVS), tiny_config(iterations=2), tmp_path / run, progress=False)
    a, b = (torch.load(tmp_path / run / "latest.pt", weights_only=True) for run in ("a", "b"))
    for key, value in a["actor_state_dict"].items():
        assert torch.equal(value, b["actor_state_dict"][key]), key


def test_trained_policy_beats_random(trained_run):
    env = ReachEnv(NUM_ENVS, seed=123)
    random_error = mean_final_error(env, lambda obs: torch.randint(0, 3, (NUM_ENVS, 1)).float())
    actor = load_policy(trained_run)
    trained_error = mean_final_error(ReachEnv(NUM_ENVS, seed=123), actor)
    assert random_error > 1.5
    assert trained_error < 0.25 * random_error


def test_resume_continues_from_checkpoint(tmp_path):
    first = train(ReachEnv(NUM_ENVS), tiny_config(), tmp_path, progress=False)
    saved = torch.load(tmp_path / "latest.pt", weights_only=True)
    assert first["earlier_wall_time_s"] == 0 and first["wall_time_s"] == first["run_wall_time_s"] > 0
    assert 0 < saved["infos"]["wall_time_s"] <= first["wall_time_s"]

    # Ctrl-C on the first step of the resumed run saves the state it started from.
    env = ReachEnv(NUM_ENVS)
    env.interrupt_after = 1
    with pytest.raises(KeyboardInterrupt):
        train(env, tiny_config(iterations=5), tmp_path / "resumed", resume=tmp_path, progress=False)
    restored = torch.load(tmp_path / "resumed" / "latest.pt", weights_only=True)
    assert restored["infos"]["iterations_done"] == 3
    for key in ("actor_state_dict", "critic_state_dict"):
        for name, value in saved[key].items():
            assert torch.equal(value, restored[key][name]), name
    assert (
        restored["optimizer_state_dict"]["state"][0]["step"]
        == saved["optimizer_state_dict"]["state"][0]["step"]
    )

    summary = train(ReachEnv(NUM_ENVS), tiny_config(iterations=5), tmp_path, resume=tmp_path, progress=False)
    assert summary["iterations"] == 5 and summary["env_steps"] == 5 * 24 * NUM_ENVS
    assert [h["iteration"] for h in summary["history"]] == [1, 2, 3, 4, 5]  # carried over the resume
    assert summary["checkpoint"] == "model_4.pt"
    assert torch.load(tmp_path / "model_4.pt", weights_only=True)["infos"]["iterations_done"] == 5
    # The time counts the run before the resume, up to the checkpoint it resumed.
    assert summary["earlier_wall_time_s"] == saved["infos"]["wall_time_s"]
    assert summary["wall_time_s"] == pytest.approx(
        summary["earlier_wall_time_s"] + summary["run_wall_time_s"]
    )
    # A checkpoint from before the field: the earlier time is unknown, said as None, not counted as 0.
    old = torch.load(tmp_path / "latest.pt", weights_only=True)
    del old["infos"]["wall_time_s"]
    torch.save(old, tmp_path / "old.pt")
    summary = train(
        ReachEnv(NUM_ENVS),
        tiny_config(iterations=6),
        tmp_path / "old",
        resume=tmp_path / "old.pt",
        progress=False,
    )
    assert summary["earlier_wall_time_s"] is None and summary["wall_time_s"] == summary["run_wall_time_s"]
    assert torch.load(tmp_path / "old" / "latest.pt", weights_only=True)["infos"]["wall_time_s"] is None
    steps = [event.step for event in _scalars(tmp_path, "Loss/surrogate")]
    assert sorted(steps) == [0, 1, 2, 3, 4]


def test_ctrl_c_leaves_a_checkpoint(tmp_path):
    env = ReachEnv(NUM_ENVS)
    env.interrupt_after = 2 * 24 + 10  # in the third iteration's rollout
    with pytest.raises(KeyboardInterrupt):
        train(env, tiny_config(iterations=10), tmp_path, progress=False)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["iterations"] == 2
    assert summary["checkpoint"] == "model_1.pt"
    checkpoint = torch.load(tmp_path / "latest.pt", weights_only=True)
    assert checkpoint["iter"] == 1 and checkpoint["infos"]["iterations_done"] == 2
    assert not list(tmp_path.glob(".*.tmp"))


@pytest.mark.filterwarnings("ignore:.*torch.jit.load.* is deprecated:DeprecationWarning")
@pytest.mark.parametrize("discrete", [True, False], ids=["discrete", "continuous"])
def test_exported_policies_match_live_policy(tmp_path, trained_run, discrete):
    run_dir = trained_run
    if not discrete:
        run_dir = tmp_path / "run"
        train(ReachEnv(NUM_ENVS, discrete=False), tiny_config(), run_dir, progress=False)
    paths = export_policy(run_dir, tmp_path / "exported")
    obs = torch.randn(64, 2) * 2.0

    live = load_policy(run_dir)(TensorDict({"policy": obs}, batch_size=[64]))
    torchscript = torch.jit.load(paths["torchscript"])(obs)
    onnx = torch.from_numpy(ReferenceEvaluator(str(paths["onnx"])).run(None, {"obs": obs.numpy()})[0])
    assert live.shape == torchscript.shape == onnx.shape == (64, 1)
    if discrete:
        assert torch.equal(torchscript, live) and torch.equal(onnx, live)
        assert set(live.unique().tolist()) <= {0.0, 1.0, 2.0}
    else:
        assert torch.allclose(torchscript, live, atol=1e-6) and torch.allclose(onnx, live, atol=1e-5)


def _scalars(log_dir, tag: str) -> list:
    events = EventAccumulator(str(log_dir))
    events.Reload()
    return events.Scalars(tag)


def test_the_run_logs_its_hyperparameters_for_tensorboard(tmp_path):
    train(ReachEnv(NUM_ENVS), tiny_config(iterations=2), tmp_path, progress=False, validate=lambda actor: 2.5)
    events = EventAccumulator(str(tmp_path))
    events.Reload()
    assert events.PluginTagToContent("hparams")  # what the HPARAMS tab shows
    assert [e.value for e in events.Scalars("hparam/validation_error")] == [2.5]


@pytest.mark.parametrize("algo", ["ppo", "es"])
def test_collection_runs_on_one_torch_thread_and_the_update_on_all(tmp_path, monkeypatch, algo):
    """On a CPU, rsl-rl's collection shares the cores with the simulator's threads, so it runs torch on one
    thread; the learner's update (PPO's, es's) gets every thread torch had; both are restored afterwards
    (docs/performance.md §6)."""
    from agents.es.algorithm import ES
    from agents.es.config import EsConfig

    seen = {"step": set(), "update": set()}
    env = ReachEnv(NUM_ENVS, discrete=algo == "ppo")
    step = env.step

    def counting_step(actions):
        seen["step"].add(torch.get_num_threads())
        return step(actions)

    monkeypatch.setattr(env, "step", counting_step)
    from rsl_rl.algorithms import PPO

    learner = PPO if algo == "ppo" else ES
    update = learner.update

    def counting_update(self, *args, **kwargs):
        seen["update"].add(torch.get_num_threads())
        return update(self, *args, **kwargs)

    monkeypatch.setattr(learner, "update", counting_update)
    cfg = tiny_config(iterations=2)
    if algo == "es":
        cfg = TrainConfig(
            algo="es", num_envs=NUM_ENVS, iterations=2, es=EsConfig(population=4, feedback=False)
        )
    torch.set_num_threads(2)
    try:
        train(env, cfg, tmp_path, progress=False)
        assert seen == {"step": {1}, "update": {2}}
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(1)  # the module's fixture's setting


def test_the_runner_installs_the_ppo_speed_ups():
    from agents.ppo.algorithm import PPO, mini_batches

    env = ReachEnv(num_envs=4)
    alg = Runner(env, tiny_config(num_envs=4).to_rsl_rl(env.num_action_choices), log_dir=None).alg
    assert type(alg) is PPO
    assert alg.storage.mini_batch_generator.__func__ is mini_batches
    assert alg.optimizer.defaults["fused"] is True
