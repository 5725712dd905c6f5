"""gps: a closed-loop policy trained from the contour's optimised plan (agents.gps): the teacher's plan as
the student's feed-forward, es on the correction, model selection over the still grasp, the plan and the
student, exact resume, exports that carry the plan; and the learner registry as the one place a learner is
added."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from agents.checkpoints import read_checkpoint
from agents.config import TrainConfig
from agents.es.config import EsConfig
from agents.gps.config import GpsConfig
from agents.gps.model import NominalLookup, PlanLookup
from agents.policies import load_policy
from agents.training import train, training_env
from envs.options import PatternCutOptions
from warpcut.sim.config import SimConfig

pytestmark = pytest.mark.usefixtures("one_torch_thread")

SMALL = SimConfig(resolution=13, noise_std=0.03)


def gps_config(iterations: int = 2, **train) -> TrainConfig:
    """gps on a small batch, with a teacher of 2 optimiser steps."""
    gps = GpsConfig(teacher_iterations=2, refine=EsConfig(population=4))
    return TrainConfig(
        algo="gps", num_envs=8, iterations=iterations, save_interval=1, validation_trials=4, gps=gps, **train
    )  # fmt: skip


def gps_env(cfg: TrainConfig, seed: int = 0):
    return training_env(PatternCutOptions(contour="circle-small", sim_config=SMALL), cfg, seed)


def validation(cfg: TrainConfig, seed: int = 0):
    """A validation of 4 held-out episodes, as :func:`agents.training.train_contour` builds it."""
    from agents.policies import policy_errors
    from envs.vector import PatternCutVecEnv

    env = PatternCutVecEnv(cfg.validation_trials, PatternCutOptions(contour="circle-small", sim_config=SMALL))
    return lambda actor: policy_errors(actor, env, seed + 99)["error_vertices"]


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A gps run of 2 iterations on circle-small."""
    out = tmp_path_factory.mktemp("gps")
    cfg = gps_config()
    summary = train(gps_env(cfg), cfg, out, seed=0, progress=False, validate=validation(cfg))
    return out, summary


def test_the_plan_lookup_plays_the_move_of_the_step_the_time_index_names():
    lookup = PlanLookup(4, 3)
    lookup.plan.copy_(torch.arange(12, dtype=torch.float32).reshape(4, 3))
    time = torch.tensor([0.0, 0.25, 0.5 + 1e-6, 0.75, 1.0, -0.25])
    moves = lookup(time)
    assert torch.equal(moves[:4], lookup.plan)
    assert torch.equal(moves[4:], torch.zeros(2, 3))  # past the plan's end: hold still


def test_the_nominal_lookup_records_the_mean_observation_of_each_step():
    """Each step's mean over the cuts that met it; a step no cut met keeps the step before's."""
    nominal = NominalLookup(4, 2)
    assert float(nominal.centred) == 0.0
    seen = [torch.tensor([[0.0, 1.0], [0.0, 3.0]]), torch.tensor([[0.25, 5.0], [0.25, 7.0]])]
    seen.append(torch.tensor([[0.75, 9.0], [0.75, 11.0]]))
    nominal.record(seen, time_index=0)
    assert float(nominal.centred) == 1.0
    assert nominal.obs[:, 1].tolist() == [2.0, 6.0, 6.0, 10.0]
    assert nominal(torch.tensor([0.25, 0.75]))[:, 1].tolist() == [6.0, 10.0]


def test_gps_trains_from_its_teacher_and_selects_among_still_plan_and_student(trained):
    """The teacher is optimised into the run's teacher/ folder and becomes the actor's feed-forward; the
    first validation scores the plan (the student as it starts) and the still grasp on the same episodes,
    later ones the student; the kept policy is the best of them."""
    out, summary = trained
    teacher = json.loads((out / "teacher" / "circle-small.json").read_text())
    plan = np.asarray(teacher["plan"], dtype=np.float32)
    assert plan.shape[1] == 3 and np.abs(plan).max() > 0  # the optimiser moved
    assert summary["teacher"]["best_iteration"] == teacher["best_iteration"]
    labels = [(v["iterations"], v["policy"]) for v in summary["validation"]]
    assert labels[:2] == [(0, "plan"), (0, "still")] and {p for _, p in labels[2:]} == {"student"}
    best = min(summary["validation"], key=lambda v: v["score"])
    assert summary["kept"] == best["policy"] and summary["best"]["validation_score"] == best["score"]
    kept = read_checkpoint(out / "best.pt")["actor_state_dict"]["lookup.plan"]
    if summary["kept"] == "still":
        assert torch.count_nonzero(kept) == 0
    else:  # max_step_mm is 1 mm: the actor's plan is the teacher's in mm
        assert torch.equal(kept, torch.as_tensor(plan)[: len(kept)])


def test_the_student_starts_as_its_teacher_and_stays_closed_loop(trained):
    """Before any correction the student's move is the plan's move at the observed step; the trained one
    adds a correction that depends on what it observes (the tracking error)."""
    out, _ = trained
    actor = load_policy(out / "latest.pt")
    steps = actor.lookup.plan.shape[0]
    obs = torch.zeros(steps, actor.obs_dim)
    obs[:, 0] = torch.arange(steps) / steps
    with torch.no_grad():
        correction = actor(TensorDict({"policy": obs}, batch_size=[steps])) - actor.lookup.plan
        start, size = actor.mlp.start, actor.mlp.size
        seen = obs.clone()
        seen[:, start : start + size] = 0.5
        moved = actor(TensorDict({"policy": seen}, batch_size=[steps])) - actor.lookup.plan
    assert not torch.allclose(correction, moved)  # the move depends on the observed tracking error
    assert torch.count_nonzero(actor.mlp.feedback.weight) > 0


def test_the_correction_is_centred_on_the_plans_own_trajectory(trained):
    """The first iteration records the observations the plan meets; where the sheet does what the plan
    expects the trained student plays the plan exactly, elsewhere it corrects."""
    out, _ = trained
    actor = load_policy(out / "latest.pt")
    assert float(actor.nominal.centred) == 1.0
    steps = actor.lookup.plan.shape[0]
    nominal = actor.nominal.obs.clone()
    assert torch.allclose(nominal[:, 0], torch.arange(steps) / steps)  # the time index of each step
    with torch.no_grad():
        at_nominal = actor(TensorDict({"policy": nominal}, batch_size=[steps]))
        off = nominal.clone()
        off[:, actor.mlp.start : actor.mlp.start + actor.mlp.size] += 0.5
        corrected = actor(TensorDict({"policy": off}, batch_size=[steps]))
    torch.testing.assert_close(at_nominal, actor.lookup.plan, rtol=0, atol=1e-6)
    assert not torch.allclose(corrected, actor.lookup.plan)


def test_a_resumed_gps_run_ends_as_an_uninterrupted_one(tmp_path):
    """One iteration, then one more on resume (the teacher read back from the run's folder, the plan from
    the checkpoint), ends with exactly the weights of two in one go."""
    cfg = gps_config(iterations=1)
    two = dataclasses.replace(cfg, iterations=2)
    train(gps_env(cfg, 2), cfg, tmp_path / "a", seed=2, progress=False, validate=validation(cfg, 2))
    resumed = train(
        gps_env(cfg, 2), two, tmp_path / "a", seed=2, resume=tmp_path / "a", progress=False,
        validate=validation(cfg, 2),
    )  # fmt: skip
    straight = train(
        gps_env(cfg, 2), two, tmp_path / "b", seed=2, progress=False, validate=validation(cfg, 2)
    )
    a = read_checkpoint(tmp_path / "a" / "latest.pt")["actor_state_dict"]
    b = read_checkpoint(tmp_path / "b" / "latest.pt")["actor_state_dict"]
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    same = ("best_iteration", "validation_error", "env_steps")
    assert [resumed["teacher"][k] for k in same] == [straight["teacher"][k] for k in same]
    assert resumed["kept"] == straight["kept"]
    assert resumed["validation"][-1]["error"] == straight["validation"][-1]["error"]


def test_the_exports_carry_the_plan(trained, tmp_path):
    """TorchScript and ONNX play what the actor plays, the plan's feed-forward included."""
    ort = pytest.importorskip("onnxruntime")
    from agents.export import export_policy

    out, _ = trained
    paths = export_policy(out / "latest.pt", tmp_path / "x")
    actor = load_policy(out / "latest.pt")
    steps = actor.lookup.plan.shape[0]
    obs = torch.rand(steps, actor.obs_dim) * 0.2
    obs[:, 0] = torch.arange(steps) / steps
    with torch.no_grad():
        expected = actor(TensorDict({"policy": obs}, batch_size=[steps])).numpy()
    assert np.abs(actor.lookup.plan.numpy()).max() > 0 and float(actor.nominal.centred) == 1.0
    scripted = torch.jit.load(str(paths["torchscript"]))(obs).detach().numpy()
    session = ort.InferenceSession(str(paths["onnx"]))
    onnx = session.run(None, {"obs": obs.numpy()})[0]
    np.testing.assert_allclose(scripted, expected, atol=1e-5)
    np.testing.assert_allclose(onnx, expected, atol=1e-5)


def test_gps_settings_are_checked_where_they_are_given():
    with pytest.raises(ValueError, match="train.gps.teacher_iterations"):
        GpsConfig(teacher_iterations=0)
    with pytest.raises(ValueError, match="train.gps.randomize: unknown parameter 'gravty'"):
        GpsConfig(randomize=["gravty"])
    with pytest.raises(ValueError, match="train.gps.refine.feedback"):
        GpsConfig(refine=EsConfig(feedback=False))


REGISTERED = """
import dataclasses, json
from dataclasses import dataclass
import agents.algorithms as registry

@dataclass
class ToyConfig:
    step: float = 0.5
    feedback = False
    def check(self, num_envs=None):
        if not 0 < self.step:
            raise ValueError("train.toy.step: must be > 0")
    def rsl_rl(self, discrete, num_action_choices, episode_steps=None):
        return {"algorithm": {"class_name": "toy:Toy", "step": self.step},
                "distribution": dict(registry.DETERMINISTIC_GAUSSIAN), "num_steps_per_env": 7}

import __main__
__main__.ToyConfig = ToyConfig
registry.ALGORITHMS["toy"] = registry.Algorithm(
    "toy", "a learner of one entry", num_envs=8, iterations=3, action_type="continuous",
    continuous_only=True, runner="agents.runner:Runner", settings="__main__:ToyConfig")

from agents.config import TrainConfig
from agents.config_io import apply, to_plain
from agents.jobs import TrainJob
job = apply(TrainJob(contour="fls-circle"), {"train.algo": "toy", "train.toy.step": 2.0}, "--set")
part = job.train.check().to_rsl_rl(None, None, 40)
print(json.dumps({"section": to_plain(job.train)["toy"], "algorithm": part["algorithm"],
                  "steps": part["num_steps_per_env"], "batch": job.train.batch_size}))
"""


def test_a_learner_is_added_by_its_registry_entry_alone():
    """A learner registered in agents.algorithms (its settings class named there) is a section of the
    settings, reachable by ``--set``, checked, and configures rsl-rl's runner: nothing else names it."""
    done = subprocess.run([sys.executable, "-c", REGISTERED], capture_output=True, text=True, check=True)
    result = json.loads(done.stdout)
    assert result == {
        "section": {"step": 2.0},
        "algorithm": {"class_name": "toy:Toy", "step": 2.0},
        "steps": 7,
        "batch": 8,
    }


def test_an_exported_student_runs_on_the_env_its_metadata_makes(tmp_path):
    """``warpcut train --algo gps`` then ``warpcut export``: the ONNX file alone (its ``warpcut.options``
    metadata for ``gym.make``) plays the run's student, plan included, step for step through a whole cut."""
    ort = pytest.importorskip("onnxruntime")
    import gymnasium as gym

    import warpcut.gym  # noqa: F401 -- registers the env
    from agents.export import export_policy
    from agents.jobs import TrainJob
    from agents.training import train_contour

    job = TrainJob(contour="circle-small", sim=SMALL, train=gps_config(iterations=1), eval_trials=2)
    result = train_contour(job, tmp_path / "run", progress=False)
    assert result["summary"]["teacher"]["env_steps"] > 0
    paths = export_policy(tmp_path / "run", tmp_path / "exported")
    session = ort.InferenceSession(str(paths["onnx"]))
    options = json.loads(session.get_modelmeta().custom_metadata_map["warpcut.options"])
    env = gym.make("warpcut/PatternCut-v0", **options)
    actor = load_policy(tmp_path / "run")
    obs, _ = env.reset(seed=0)
    done, steps, moved = False, 0, 0.0
    while not done:
        with torch.no_grad():
            expected = actor(TensorDict({"policy": torch.as_tensor(obs[None])}, batch_size=[1])).numpy()
        action = session.run(None, {"obs": obs[None].astype(np.float32)})[0]
        np.testing.assert_allclose(action, expected, atol=1e-5)
        moved += float(np.abs(action).sum())
        obs, _, terminated, truncated, info = env.step(expected[0])
        done, steps = terminated or truncated, steps + 1
    assert steps == actor.lookup.plan.shape[0] and np.isfinite(info["error_vertices"])
    if result["summary"]["kept"] != "still":
        assert moved > 0  # the plan's moves are in the file


def test_evaluates_grad_column_plays_the_teachers_plans_as_it_would_have_found_them(tmp_path):
    """With gps in the rl column, the grad column reads each contour's plan from its teacher (the same
    optimiser, settings, pinch point, order and seed) instead of optimising it again, and its row is the row
    the grad column gives alone."""
    from agents.jobs import EvaluateJob
    from agents.pipelines import evaluate_table
    from agents.plan_optimizer.config import grad_config

    grad = grad_config("es", iterations=2)
    job = EvaluateJob(
        contours=["circle-small"], trials=2, candidates=3, sim=SMALL, grad=grad,
        train=gps_config(iterations=1), methods=["none", "grad", "rl"],
    )  # fmt: skip
    both = evaluate_table(job, tmp_path / "both", log=lambda _: None)
    teacher = tmp_path / "both" / "policies" / "circle-small" / "teacher" / "circle-small.json"
    assert json.loads((tmp_path / "both" / "grad" / "circle-small.json").read_text()) == json.loads(
        teacher.read_text()
    )
    alone = evaluate_table(
        dataclasses.replace(job, methods=["none", "grad"]), tmp_path / "alone", log=lambda _: None
    )
    a, b = both.table["rows"][0], alone.table["rows"][0]
    assert a["grad_trials_error_vertices"] == b["grad_trials_error_vertices"]
    assert (
        json.loads((tmp_path / "alone" / "grad" / "circle-small.json").read_text())["plan"]
        == json.loads(teacher.read_text())["plan"]
    )


def test_a_run_stopped_while_its_teacher_is_optimised_resumes_with_its_teacher(tmp_path, monkeypatch):
    """Ctrl-C in the teacher's optimisation saves a checkpoint without a plan; the resumed run optimises the
    teacher (from its state file) and trains on it, ending as a run never stopped."""
    import agents.plan_optimizer.optimizer

    cfg = gps_config(iterations=1)
    check = validation(cfg, 5)
    straight = train(gps_env(cfg, 5), cfg, tmp_path / "b", seed=5, progress=False, validate=check)
    optimize = agents.plan_optimizer.optimizer.optimize_plan

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(agents.plan_optimizer.optimizer, "optimize_plan", stopped)
    with pytest.raises(KeyboardInterrupt):
        train(gps_env(cfg, 5), cfg, tmp_path / "a", seed=5, progress=False, validate=validation(cfg, 5))
    monkeypatch.setattr(agents.plan_optimizer.optimizer, "optimize_plan", optimize)
    resumed = train(
        gps_env(cfg, 5), cfg, tmp_path / "a", seed=5, resume=tmp_path / "a", progress=False,
        validate=validation(cfg, 5),
    )  # fmt: skip
    assert resumed["teacher"]["best_iteration"] == straight["teacher"]["best_iteration"]
    a = read_checkpoint(tmp_path / "a" / "latest.pt")["actor_state_dict"]
    b = read_checkpoint(tmp_path / "b" / "latest.pt")["actor_state_dict"]
    assert torch.count_nonzero(a["lookup.plan"]) > 0 and all(torch.equal(a[k], b[k]) for k in a)


def test_the_correction_trains_on_randomised_sheets_and_is_selected_on_both(tmp_path):
    """With ``train.gps.randomize`` the correction trains on sheets drawn anew at every reset, model selection
    scores the nominal sheet's held-out episodes and as many randomised ones, and the run's env (what it is
    evaluated and exported on) stays the job's nominal one; a job that randomises its env keeps its own."""
    from agents.jobs import TrainJob
    from agents.training import learner_sheets, train_contour
    from envs.vector import PatternCutVecEnv

    options = PatternCutOptions(contour="circle-small", sim_config=SMALL)
    gps = GpsConfig(teacher_iterations=2, refine=EsConfig(population=4), randomize=("gravity",))
    cfg = dataclasses.replace(gps_config(), gps=gps)
    trained_on, validated_on = learner_sheets(cfg, options)
    assert trained_on.randomize == ("gravity",) and [o.randomize for o in validated_on] == [(), ("gravity",)]
    own = dataclasses.replace(options, randomize=("noise",))
    assert learner_sheets(cfg, own) == (own, [own])
    nominal = dataclasses.replace(gps_config(), gps=dataclasses.replace(gps, randomize=()))
    assert learner_sheets(nominal, options) == (options, [options])
    assert GpsConfig().randomize == ("gravity", "noise_std")  # the default: sheets that differ

    # at this resolution the randomised sheets' cut is a step longer than the nominal sheet's (49 and 48)
    sim = dataclasses.replace(SMALL, resolution=15)
    job = TrainJob(
        contour="circle-small", sim=sim, train=dataclasses.replace(cfg, iterations=1), eval_trials=2
    )
    train_contour(job, tmp_path / "run", progress=False)
    state = read_checkpoint(tmp_path / "run" / "latest.pt")
    assert len(state["infos"]["validation_baseline"]) == 2 * cfg.validation_trials
    assert not json.loads((tmp_path / "run" / "options.json").read_text()).get("randomize")
    # the plan table is the teacher's length, so the nominal cut plays the plan's moves step for step
    teacher = json.loads((tmp_path / "run" / "teacher" / "circle-small.json").read_text())["plan"]
    nominal = PatternCutVecEnv(1, dataclasses.replace(options, sim_config=sim))
    assert len(teacher) == nominal.scene.episode_steps == 48
    randomised = PatternCutVecEnv(8, dataclasses.replace(options, sim_config=sim, randomize=("gravity",)))
    randomised.reset(seed=0)
    assert randomised.scene.episode_steps == 49
    actor = load_policy(tmp_path / "run" / "latest.pt")
    assert actor.lookup.plan.shape[0] == 48
    times = torch.arange(48) / 48
    torch.testing.assert_close(actor.lookup(times), torch.as_tensor(teacher, dtype=torch.float32)[:, :3])
    longer = dataclasses.replace(job, train=dataclasses.replace(cfg, iterations=2))
    train_contour(longer, tmp_path / "run", resume=tmp_path / "run", progress=False)  # resumes the table
    assert load_policy(tmp_path / "run" / "latest.pt").lookup.plan.shape[0] == 48


def test_a_student_saved_before_its_correction_was_centred_plays_as_it_did(trained):
    """A gps checkpoint without the nominal observations loads (:func:`agents.policies.load_policy`'s
    upgrade) as an uncentred student: plan plus correction."""
    out, _ = trained
    actor = load_policy(out / "latest.pt")
    old = {k: v for k, v in actor.state_dict().items() if not k.startswith("nominal.")}
    actor.load_state_dict(actor.upgrade_state(old))
    assert float(actor.nominal.centred) == 0.0
    steps = actor.lookup.plan.shape[0]
    obs = torch.rand(steps, actor.obs_dim) * 0.2
    obs[:, 0] = torch.arange(steps) / steps
    td = TensorDict({"policy": obs}, batch_size=[steps])
    with torch.no_grad():
        uncentred = actor.mlp(actor.obs_normalizer(obs)) + actor.lookup.plan
        torch.testing.assert_close(actor(td), uncentred)


def test_a_policy_worse_on_the_guarded_nominal_episodes_is_not_kept():
    """With randomised validation episodes beside the nominal sheet's, a policy that gains on the randomised
    ones but does worse on the nominal ones than the initial policy, on average, is not kept: even by less
    than the selection margin's standard error."""
    from agents.runner import Runner

    runner = Runner.__new__(Runner)
    runner.guarded_episodes, runner.selection_margin = 4, 1.0
    runner.validation_baseline = [[1.0], [1.2], [0.8], [1.0], [5.0], [5.0], [5.0], [5.0]]
    runner.validation = [{}, {}]
    worse_nominal = [1.5, 1.6, 1.4, 1.5, 2.0, 2.0, 2.0, 2.0]
    level_nominal = [1.0, 1.1, 0.8, 1.0, 2.0, 2.0, 2.0, 2.0]
    worse_within_se = [1.3, 1.2, 0.6, 1.0, 2.0, 2.0, 2.0, 2.0]  # +0.025 on average, SE 0.1
    assert not runner._guarded_ok(np.asarray(worse_nominal))
    assert runner._guarded_ok(np.asarray(level_nominal))
    assert not runner._guarded_ok(np.asarray(worse_within_se))
    runner.validation = [{}]  # the initial validation itself
    assert runner._guarded_ok(np.asarray(worse_nominal))
    runner.validation, runner.guarded_episodes = [{}, {}], None
    assert runner._guarded_ok(np.asarray(worse_nominal))


def test_a_run_saved_before_the_correction_was_centred_is_refused_on_resume_in_one_line(tmp_path):
    """Its checkpoint lacks the nominal observations: resuming it says so and what to do instead."""
    cfg = gps_config(iterations=1)
    train(gps_env(cfg), cfg, tmp_path / "a", seed=0, progress=False, validate=validation(cfg))
    path = tmp_path / "a" / "latest.pt"
    state = read_checkpoint(path)
    state["actor_state_dict"] = {k: v for k, v in state["actor_state_dict"].items() if "nominal" not in k}
    torch.save(state, path)
    with pytest.raises(ValueError, match="earlier warpcut, whose correction is not centred.*start a new run"):
        train(gps_env(cfg), gps_config(iterations=2), tmp_path / "a", seed=0, resume=path, progress=False)
