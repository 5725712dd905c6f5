"""The generalist: the look-ahead observation, the reward relative to no tension, gain scheduling, training
over many contours, playing one zero-shot in every command, fine-tuning from it, and the shipped one."""

import json

import numpy as np
import pytest
import torch

from agents.checkpoints import policy_layout
from agents.config import FINE_TUNING_GAIN, GENERALIST_GAINS, GENERALIST_LOOKAHEAD
from agents.generalist import (
    GENERALIST_FILE,
    SHIPPED_DIR,
    generalist_cut,
    generalist_settings,
    load_generalist,
)
from agents.jobs import GeneralistJob
from envs.observations import LOOKAHEAD_POINT, observation_bounds, observation_names
from envs.options import PatternCutOptions
from envs.vector import PatternCutVecEnv
from tests.cli_runner import invoke, refused
from warpcut.planning.generate import generate_contours, resolve_specs
from warpcut.sim.config import SimConfig
from warpcut.validation import ConfigError

SMALL = ["--set", "sim.resolution=13"]
COARSE = SimConfig(resolution=13)


def _hold(env: PatternCutVecEnv) -> np.ndarray:
    return np.zeros((env.num_envs, 3), dtype=np.float32)


def test_the_lookahead_block_is_laid_out_as_named_and_bounded():
    names = observation_names(12, True, 3)
    low, high = observation_bounds(12, True, 3)
    assert len(names) == low.size == high.size == 47 + 2 + 6 * 3
    assert names[47:49] == ["pinch_dx", "pinch_dy"]
    assert names[-6:] == [n.format(j=3) for n in LOOKAHEAD_POINT]
    assert observation_bounds(12, True)[0].size == 47  # no look-ahead: the layout is unchanged


def test_lookahead_needs_the_contour_features_and_a_count():
    with pytest.raises(ConfigError, match="lookahead.*contour_features"):
        PatternCutOptions(lookahead=4, contour_features=False)
    with pytest.raises(ConfigError, match="lookahead"):
        PatternCutOptions(lookahead=-1)
    with pytest.raises(ConfigError, match="relative_reward.*no_tension"):
        PatternCutOptions(reward_reference="no_tension", relative_reward=True)


def test_the_lookahead_sees_the_planned_path_ahead_and_each_env_its_own_progress():
    contours = generate_contours(2, "test", 0, COARSE)
    env = PatternCutVecEnv(2, PatternCutOptions(contour=contours, lookahead=4, resolution=13, noise_std=0.0))
    obs, _ = env.reset(seed=0)
    task = env.task
    for _ in range(5):
        obs, *_ = env.step(_hold(env))
    names = observation_names(env.options.num_fiducials, True, 4)
    progress = obs[:, names.index("time")]
    assert np.allclose(progress, np.minimum(task.update_index / task.trajectory_updates, 1.0), atol=1e-6)
    assert progress[0] != progress[1]  # each contour's own length, not the batch's clock
    # the first point ahead: the planned tip's move from the tip now, 2 steps past the next update
    tip = task.tip_positions(task.update_index - 1)
    ahead = task.tip_positions(task.update_index + 2 * 2)
    half = 50.0
    move = obs[:, [names.index("ahead_1_dx"), names.index("ahead_1_dy")]]
    assert np.allclose(move, (ahead[:, :2] - tip[:, :2]) / half, atol=1e-5)
    # the look-ahead of update u + 0 is the tracking error of the next update
    tips, targets = task.lookahead([0])
    assert np.allclose(tips[:, 0], task.tip_positions(), equal_nan=True)
    assert np.allclose(targets[:, 0], task.target_world(), equal_nan=True)


def test_a_reward_relative_to_no_tension_makes_the_episode_cost_the_error_over_no_tensions():
    from agents.evaluation import run_method
    from envs.rsl import EPISODE_COST_KEY, PatternCutRslEnv

    contours = generate_contours(2, "train", 0, COARSE)
    config = COARSE.replace(noise_std=0.0)
    options = PatternCutOptions(contour=contours, sim_config=config, reward_reference="no_tension")
    env = PatternCutRslEnv(PatternCutVecEnv(2, options, autoreset_mode="same_step"), seed=0)
    costs = None
    for _ in range(int(env.max_episode_length)):
        _, _, _, extras = env.step(torch.zeros(2, 3))
        costs = extras.get(EPISODE_COST_KEY, costs)
    pinches = env.env.task.pinch_points
    held = run_method(contours, list(pinches), None, 1, config, "cpu", 0).error_mm2[:, 0]
    none = run_method(contours, [None, None], None, 1, config, "cpu", 0).error_mm2[:, 0]
    assert np.allclose(costs.numpy(), held / none, rtol=1e-6)


def test_scheduled_gains_are_played_alike_by_the_actor_and_by_es_population():
    from agents.es.algorithm import ES
    from agents.training import training_env

    job = GeneralistJob(generated=2, sim=COARSE)
    cfg = job.training_config(2)
    contours = generate_contours(2, "train", 0, COARSE)
    options = PatternCutOptions(contour=contours * 32, lookahead=2, sim_config=COARSE)
    env = training_env(options, cfg, 0)
    from agents.models import feedback_inputs

    rsl = cfg.to_rsl_rl(None, feedback_inputs(env), int(env.max_episode_length))
    alg = ES.construct_algorithm(env.get_observations(), env, rsl, "cpu")
    assert alg.actor.mlp.scheduled
    torch.manual_seed(1)
    with torch.no_grad():
        for p in alg.params:
            p.normal_(0.0, 0.3)
    alg._batch = alg._unpack(np.repeat(alg._theta()[None], alg.population, axis=0))
    obs = env.get_observations()
    obs["policy"] = torch.randn_like(obs["policy"])
    batched = alg._forward(alg.actor.get_latent(obs))
    single = alg.actor(obs)
    assert torch.allclose(batched, single, atol=1e-5)
    assert policy_layout(alg.actor.state_dict()) == (obs["policy"].shape[1], 3)  # 3 moves, not 12 outputs


def test_a_generalist_job_refuses_what_cannot_train_many_contours():
    with pytest.raises(ValueError, match="train.algo"):
        GeneralistJob(train=GeneralistJob().train.__class__(algo="ppo")).check()
    with pytest.raises(ValueError, match="env.lookahead"):
        job = GeneralistJob()
        job.env.lookahead = 0
        job.check()
    job = GeneralistJob()
    job.train.num_envs = 100
    with pytest.raises(ValueError, match="train.num_envs"):
        job.training_config(48)
    with pytest.raises(ValueError, match="generated"):
        GeneralistJob(generated=0).check()


def test_generated_contours_are_named_and_resolved_by_their_specs():
    named = resolve_specs(["gen-test-0:2", "fls-circle", "gen-test-0-0003-open"])
    assert [n for n, _ in named] == [
        "gen-test-0-0000-blob", "gen-test-0-0001-polygon", "fls-circle", "gen-test-0-0003-open",
    ]  # fmt: skip
    assert named[3][1].points.tolist() == generate_contours(4, "test", 0)[3].points.tolist()
    with pytest.raises(ValueError, match="is a polygon"):
        resolve_specs(["gen-test-0-0001-blob"])
    with pytest.raises(ValueError, match="split"):
        resolve_specs(["gen-exam-0:2"])


@pytest.fixture(scope="module")
def generalist_run(tmp_path_factory):
    """A generalist trained for one iteration on two coarse generated contours."""
    out = tmp_path_factory.mktemp("generalist") / "run"
    args = [
        "generalist", "--generated", "2", "--validation-contours", "1", "--iterations", "1", "--out",
        str(out), "--no-progress", "--set", "candidates=2", "--set", "train.algo=es",
        "--set", "train.es.population=2", *SMALL,
    ]  # fmt: skip
    code, output, _ = invoke(args)
    assert code == 0, output
    return out, output


def test_a_generalist_trains_over_generated_contours_into_its_run_directory(generalist_run):
    out, output = generalist_run
    assert "kept iteration" in output and "held-out contours" in output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["contours"] == 2
    settings = generalist_settings(out)
    assert settings["env"]["lookahead"] == GENERALIST_LOOKAHEAD
    assert settings["training_contours"] == ["gen-train-0-0000-blob", "gen-train-0-0001-polygon"]
    assert settings["validation_contours"] == ["gen-validation-0-0000-blob"]
    assert (out / "best.pt").is_file() and (out / "plans.json").is_file()


def test_a_generalist_run_resumes_to_train_longer(generalist_run, tmp_path):
    import shutil

    out = tmp_path / "run"
    shutil.copytree(generalist_run[0], out)
    code, output, _ = invoke(
        ["generalist", "--out", str(out), "--resume", "--iterations", "2", "--no-progress"]
    )
    assert code == 0, output
    assert json.loads((out / "summary.json").read_text())["iterations"] == 2


def test_a_generalist_refines_the_shipped_one_by_its_name(tmp_path):
    """``init=generalist`` names the shipped generalist, as train's ``init`` does."""
    out = tmp_path / "refined"
    code, output, _ = invoke(
        ["generalist", "--generated", "1", "--validation-contours", "1", "--iterations", "1",
         "--out", str(out), "--no-progress", "--set", "candidates=1", "--set", "train.es.population=2",
         "--set", "init=generalist", *SMALL]
    )  # fmt: skip
    assert code == 0, output
    shipped = torch.load(SHIPPED_DIR / "best.pt", weights_only=False)["actor_state_dict"]
    started = torch.load(out / "model_0.pt", weights_only=False)["actor_state_dict"]  # after one es step
    assert shipped.keys() == started.keys()
    body = [k for k in shipped if k.startswith("mlp.body")]
    assert all(torch.allclose(shipped[k], started[k], atol=0.005) for k in body)  # one Adam step


def test_a_resumed_generalist_keeps_its_settings(generalist_run, tmp_path, capfd):
    import shutil

    out = tmp_path / "run"
    shutil.copytree(generalist_run[0], out)
    line = refused(["generalist", "--out", str(out), "--resume", "--generated", "3"], capfd)
    assert "generated" in line and "keeps its settings" in line


def test_every_command_plays_a_generalist_zero_shot(generalist_run, tmp_path):
    out = str(generalist_run[0])
    code, output, _ = invoke(
        ["simulate", "--contour", "gen-test-0-0000-blob", "--policy", "fixed,generalist", "--generalist", out,
         "--trials", "2", "--set", "plots=false", *SMALL]
    )  # fmt: skip
    assert code == 0, output
    assert "generalist" in output.splitlines()[-1]
    results = tmp_path / "evaluate"
    code, output, _ = invoke(
        ["evaluate", "--contours", "gen-test-0:2", "--methods", "none,fixed,generalist", "--generalist", out,
         "--trials", "2", "--out", str(results), "--set", "candidates=2", "--set", "plots=false", *SMALL]
    )  # fmt: skip
    assert code == 0, output
    report = json.loads((results / "results.json").read_text())
    rows = report["rows"]
    assert [r["contour"] for r in rows] == ["gen-test-0-0000-blob", "gen-test-0-0001-polygon"]
    assert all(np.isfinite(r["generalist_improvement_pct"]) for r in rows)
    for row in rows:  # where it holds still, fixed tension's trials; its own trials recorded either way
        shown = "fixed" if row["generalist_holds_still"] else "generalist_played"
        assert row["generalist_trials_error_vertices"] == row[f"{shown}_trials_error_vertices"]
    assert report["generalist_still_contours"] == sum(r["generalist_holds_still"] for r in rows)
    assert all(r["generalist_gain"] in GENERALIST_GAINS for r in rows)
    held = report["generalist_still_contours"]
    assert f"held still (its choice cut no better on fresh episodes) on {held} of 2" in output
    code, output, _ = invoke(
        ["run", "--contour", "circle-small", "--policy", "generalist", "--generalist", out, "--out",
         str(tmp_path / "run"), "--set", "candidates=2", "--set", "trials=2", "--set", "plots=false", *SMALL]
    )  # fmt: skip
    assert code == 0, output
    assert any(line.startswith("generalist ") for line in output.splitlines())


def test_the_generalist_column_is_paired_with_the_baselines_trials(generalist_run):
    """A generalist that holds still (its policy zeroed) scores as fixed tension does, trial by trial."""
    from agents.evaluation import run_method
    from agents.generalist import generalist_result, load_generalist

    contours = generate_contours(2, "test", 0, COARSE)
    pinches = [np.asarray(p) for p in PatternCutOptions(contour=contours, sim_config=COARSE).per_env(2)[1]]
    held = run_method(contours, pinches, None, 2, COARSE, "cpu", 3)
    still = _still_generalist(generalist_run)
    played = generalist_result(load_generalist(still), contours, pinches, None, 2, COARSE, "cpu", 3)
    assert np.array_equal(played.error_mm2, held.error_mm2)


def _pushing_generalist(generalist_run):
    """A copy of the fixture's generalist that pushes the grasp up and away every step, as far as it may."""
    state = torch.load(generalist_run[0] / "best.pt", weights_only=True)
    last = [k for k in state["actor_state_dict"] if k.startswith("mlp.") and k.endswith("bias")][-1]
    state["actor_state_dict"][last].fill_(50.0)  # every step the largest move (at any gain), up and away
    pushing = generalist_run[0].parent / "pushing"
    pushing.mkdir(exist_ok=True)
    torch.save(state, pushing / "best.pt")
    (pushing / GENERALIST_FILE).write_text((generalist_run[0] / GENERALIST_FILE).read_text())
    return pushing


def _still_generalist(generalist_run):
    """A copy of the fixture's generalist with its policy zeroed: it holds still."""
    state = torch.load(generalist_run[0] / "best.pt", weights_only=True)
    for key, value in state["actor_state_dict"].items():
        if key.startswith("mlp.") and "weight" in key or key.endswith("bias"):
            value.zero_()
    still = generalist_run[0].parent / "still"
    still.mkdir(exist_ok=True)
    torch.save(state, still / "best.pt")
    (still / GENERALIST_FILE).write_text((generalist_run[0] / GENERALIST_FILE).read_text())
    return still


def _candidates(contours, count):
    """Per contour the first ``count`` sampled pinch points (the whole contour cut), the first the planned."""
    from warpcut.planning import plan_cut

    plans = [plan_cut(c, COARSE, num_candidates=count, seed=0, device="cpu") for c in contours]
    return [[(np.asarray(c["pinch"]), p.ordered_segments(c["order"])) for c in p.ranked()] for p in plans]


def test_the_guarded_generalist_plays_where_it_validates_best_and_else_holds_still(
    generalist_run, monkeypatch
):
    """Contour by contour: the generalist at the candidate with its lowest validation error, where that
    choice cuts better than holding still at the first candidate on fresh episodes, else holding still there
    (fixed tension, trial for trial, ties included); its own trials at its best candidate everywhere on
    request."""
    import agents.generalist as module
    from agents.evaluation import run_method
    from agents.policies import VALIDATION_SEED_OFFSET

    contours = generate_contours(3, "test", 0, COARSE)
    candidates = [listed[:2] for listed in _candidates(contours, 2)]
    generalist = module.load_generalist(generalist_run[0])
    validation = np.array([[1.0, 0.5], [2.0, 3.0], [3.0, 4.0]])  # the choice: 1, 0, 0
    fresh, fresh_still = (
        np.array([[1.0], [2.0], [3.0]]),
        np.array([[2.0], [2.0], [1.0]]),
    )  # plays on the first
    validation_seed, fresh_seed = 3 + VALIDATION_SEED_OFFSET, 3 + 2 * VALIDATION_SEED_OFFSET
    played_validation = module.generalist_result

    def fake(gen, contours_, pinches, segments, trials, config, device, seed, *a, **k):
        result = played_validation(gen, contours_, pinches, segments, trials, config, device, seed, *a, **k)
        if seed in (validation_seed, fresh_seed):
            result.error_vertices[:] = validation.reshape(-1, 1) if seed == validation_seed else fresh
        return result

    monkeypatch.setattr(module, "generalist_result", fake)
    still_validation = run_method

    def fake_still(contours_, pinches, policy, trials, config, device, seed, *a, **k):
        result = still_validation(contours_, pinches, policy, trials, config, device, seed, *a, **k)
        assert seed == fresh_seed  # holding still is scored on the fresh episodes only
        result.error_vertices[:] = fresh_still
        return result

    import agents.evaluation

    monkeypatch.setattr(agents.evaluation, "run_method", fake_still)
    guarded = module.guarded_result(
        generalist, contours, candidates, 2, COARSE, "cpu", 3, played_everywhere=True, gains=[1], finalists=1
    )
    assert guarded.plays.tolist() == [True, False, False] and guarded.chosen == [1, 0, 0]
    assert guarded.gain.tolist() == [1.0, 1.0, 1.0]
    first = [listed[0] for listed in candidates]
    held = still_validation(
        contours, [p for p, _ in first], None, 2, COARSE, "cpu", 3, segments=[s for _, s in first]
    )
    best = [candidates[0][1], first[1], first[2]]
    raw = played_validation(
        generalist, contours, [p for p, _ in best], [s for _, s in best], 2, COARSE, "cpu", 3
    )
    assert np.array_equal(guarded.result.error_vertices[0], raw.error_vertices[0])
    assert np.array_equal(guarded.result.error_vertices[1:], held.error_vertices[1:])
    assert np.array_equal(guarded.result.error_mm2[1:], held.error_mm2[1:])
    assert np.array_equal(guarded.played.error_vertices, raw.error_vertices)
    assert np.allclose(guarded.result.pinches[0], candidates[0][1][0])


def test_the_guarded_generalist_chooses_the_gain_on_its_moves_it_validates_best_with(
    generalist_run, monkeypatch
):
    """The best candidates (its moves as they are) are tried with each other gain too, and the candidate and
    gain with the lowest validation error is played: its trials are the generalist's with its moves scaled
    by that gain, which leaves them bit for bit at a gain of 1 and holds still at 0."""
    import agents.generalist as module
    from agents.evaluation import run_method
    from agents.policies import VALIDATION_SEED_OFFSET

    contours = generate_contours(2, "test", 0, COARSE)
    candidates = [listed[:2] for listed in _candidates(contours, 2)]
    generalist = module.load_generalist(generalist_run[0])
    real = module.generalist_result
    batches = []

    def fake(gen, contours_, pinches, segments, trials, config, device, seed, *a, gains=None, **k):
        result = real(gen, contours_, pinches, segments, trials, config, device, seed, *a, gains=gains, **k)
        if seed == 3 + VALIDATION_SEED_OFFSET:  # the first contour best at 1.5, the second at 1
            batches.append(list(gains))
            best = [1.5 if c is contours[0] else 1.0 for c in contours_]
            errors = [1.0 + (g != b) for g, b in zip(gains, best, strict=True)]
            result.error_vertices[:] = np.array(errors).reshape(-1, 1)
        return result

    monkeypatch.setattr(module, "generalist_result", fake)
    guarded = module.guarded_result(
        generalist, contours, candidates, 2, COARSE, "cpu", 3, gains=[1, 0.5, 1.5], finalists=1
    )
    assert batches == [[1.0] * 4, [0.5, 1.5] * 4]  # every candidate, then the shortlist with each other gain
    assert guarded.gain.tolist() == [1.5, 1.0] and guarded.chosen == [0, 0]
    stills = run_method(contours, [c[0][0] for c in candidates], None, 2, COARSE, "cpu", 3,
                        segments=[c[0][1] for c in candidates])  # fmt: skip
    plays = guarded.plays
    expected = real(generalist, contours, [c[0][0] for c in candidates], [c[0][1] for c in candidates], 2,
                    COARSE, "cpu", 3, gains=np.where(plays, [1.5, 1.0], 0.0))  # fmt: skip
    assert np.array_equal(guarded.result.error_vertices, expected.error_vertices)
    as_is = real(generalist, contours, [c[0][0] for c in candidates], [c[0][1] for c in candidates], 2,
                 COARSE, "cpu", 3)  # fmt: skip
    ones = real(generalist, contours, [c[0][0] for c in candidates], [c[0][1] for c in candidates], 2,
                COARSE, "cpu", 3, gains=[1.0, 1.0])  # fmt: skip
    zeros = real(generalist, contours, [c[0][0] for c in candidates], [c[0][1] for c in candidates], 2,
                 COARSE, "cpu", 3, gains=[0.0, 0.0])  # fmt: skip
    assert np.array_equal(ones.error_vertices, as_is.error_vertices)
    assert np.array_equal(zeros.error_vertices, stills.error_vertices)


def test_the_generalist_judges_its_pinch_points_with_the_jobs_arm(generalist_run):
    """A pinch point under the paper's arm but clear of a thin, short one: the generalist's batch judges it
    with the arm it is given, as the other methods' batches do (its problem names the arm with the paper's
    only)."""
    from agents.evaluation import run_method
    from agents.generalist import generalist_result, load_generalist
    from warpcut.planning import ArmModel, pinch_problems

    contour = generate_contours(1, "test", 0, COARSE)[0]
    thin = ArmModel(radius_mm=0.5, length_mm=5.0)
    grid = np.array([[x, y] for x in range(5, 96, 3) for y in range(5, 96, 3)], dtype=float)
    default, narrow = pinch_problems(grid, contour, COARSE), pinch_problems(grid, contour, COARSE, arm=thin)
    point = next(
        p for p, a, b in zip(grid, default, narrow, strict=True) if a and "arm" in a and "arm" not in b
    )
    generalist = load_generalist(generalist_run[0])
    for arm in (None, thin):
        played = generalist_result(generalist, [contour], [point], None, 1, COARSE, "cpu", 0,
                                   allow_infeasible_pinch=True, arm=arm)  # fmt: skip
        still = run_method(
            [contour], [point], None, 1, COARSE, "cpu", 0, arm=arm, allow_infeasible_pinch=True
        )
        assert played.pinch_problems == still.pinch_problems
        assert ("under the cutting arm" in played.pinch_problems[0]) == (arm is None)


def test_a_generalist_with_discrete_moves_chooses_no_gain():
    from agents.generalist import Generalist, _gains

    def generalist(action_type):
        return Generalist({"env": {"action_type": action_type}}, None)

    assert _gains(GENERALIST_GAINS, generalist("discrete")) == (1.0,)
    assert _gains(GENERALIST_GAINS, generalist("continuous")) == GENERALIST_GAINS
    with pytest.raises(ValueError, match="generalist_gains"):
        _gains([0.5], generalist("discrete"))


@pytest.mark.parametrize("gains", [[], [0.5], [1, 0], [1, -1], [1, float("nan")], "x"])
def test_gains_without_one_or_not_positive_are_refused_by_name(gains):
    from agents.config import check_gains

    with pytest.raises(ValueError, match=r"^generalist_gains: .*1 among them"):
        check_gains(gains)
    assert check_gains([1, 1.25]) == (1.0, 1.25)


def test_a_generalist_that_validates_no_better_than_holding_still_holds_still(generalist_run):
    """A generalist that holds still validates as holding still does at the planned pinch point, exactly
    (paired noise), so the guard keeps the still grasp; one that pushes the grasp away validates worse at
    every candidate."""
    from agents.generalist import guarded_result, load_generalist

    contours = generate_contours(2, "test", 0, COARSE)
    candidates = _candidates(contours, 2)
    planned = [listed[:1] for listed in candidates]
    guarded = guarded_result(
        load_generalist(_still_generalist(generalist_run)), contours, planned, 1, COARSE, "cpu", 5
    )
    assert not guarded.plays.any()
    assert guarded.best.tolist() == guarded.still.tolist()  # at any gain, on the same fresh episodes
    guarded = guarded_result(load_generalist(_pushing_generalist(generalist_run)), contours, candidates, 1,
                             COARSE, "cpu", 5)  # fmt: skip
    assert not guarded.plays.any() and (guarded.best > guarded.still).all()
    assert all((v > s).all() for v, s in zip(guarded.validation, guarded.still, strict=True))


def test_training_for_one_contour_starts_from_a_generalist(generalist_run, tmp_path):
    import shutil

    source = tmp_path / "generalist"  # a generalist whose policy is not "hold still"
    shutil.copytree(generalist_run[0], source)
    state = torch.load(source / "best.pt", weights_only=True)
    torch.manual_seed(0)
    for key, value in state["actor_state_dict"].items():
        if key.startswith("mlp."):
            value.copy_(torch.randn_like(value) * 0.1)
    torch.save(state, source / "best.pt")
    out = tmp_path / "tuned"
    code, output, _ = invoke(
        ["train", "--contour", "circle-small", "--iterations", "1", "--out", str(out), "--no-progress",
         "--set", f"init={source}", "--set", "train.num_envs=4", "--set", "train.algo=es",
         "--set", "train.es.population=2",
         "--set", "train.validation_trials=2", "--set", "eval_trials=1", "--set", "plots=false", *SMALL]
    )  # fmt: skip
    assert code == 0, output
    config = json.loads((out / "config.json").read_text())
    assert config["init"] == str(source) and config["env"]["lookahead"] == GENERALIST_LOOKAHEAD
    assert config["train"]["es"]["scheduled"]  # the generalist's network, and its MLP's σ and step
    assert (config["train"]["es"]["sigma"], config["train"]["es"]["learning_rate"]) == (0.01, 0.003)
    assert config["init_gain"] == FINE_TUNING_GAIN != 1
    contour = resolve_specs(["circle-small"], COARSE)[0][1]
    pinch, segments = generalist_cut(load_generalist(source), contour, COARSE)  # where it plays
    assert config["pinch"] == pinch.tolist() and config["segments"] == [s.tolist() for s in segments]
    assert "where it plays" in output
    first = torch.load(out / "model_0.pt", weights_only=True)["actor_state_dict"]  # after one es step
    general = state["actor_state_dict"]
    scaled = ("mlp.body.4.weight", "mlp.body.4.bias", "mlp.feedback.weight")  # its moves, halved
    for key in (k for k in general if k.startswith("mlp.")):
        start = general[key] * (FINE_TUNING_GAIN if key in scaled else 1.0)
        step = 0.11 if key == "mlp.feedback.weight" else 0.0031  # one Adam step: the MLP's, the gains'
        torch.testing.assert_close(first[key], start, atol=step, rtol=0)
    assert first["mlp.body.4.weight"].abs().max() > 0.05  # not the fresh policy's zeroed output layer


def test_fine_tuning_is_es_only(generalist_run, capfd):
    line = refused(
        ["train", "--contour", "circle-small", "--algo", "ppo", "--set", f"init={generalist_run[0]}", *SMALL],
        capfd,
    )
    assert "init" in line and "es" in line


def test_a_generalist_that_is_not_one_is_named(tmp_path, capfd):
    line = refused(["simulate", "--contour", "fls-circle", "--policy", "generalist", "--generalist",
                    str(tmp_path)], capfd)  # fmt: skip
    assert f"{tmp_path}" in line and GENERALIST_FILE in line
    (tmp_path / GENERALIST_FILE).write_bytes((SHIPPED_DIR / GENERALIST_FILE).read_bytes())  # no best.pt
    line = refused(["simulate", "--contour", "fls-circle", "--policy", "generalist", "--generalist",
                    str(tmp_path)], capfd)  # fmt: skip
    assert "but no policy (best.pt)" in line and "warpcut generalist" in line and "warpcut train" not in line


def test_warpcut_ships_a_small_generalist_with_its_command_and_figures():
    assert (SHIPPED_DIR / "best.pt").stat().st_size < 300_000
    assert sum(f.stat().st_size for f in SHIPPED_DIR.rglob("*") if f.is_file()) < 1_000_000
    settings = generalist_settings("generalist")
    assert [p.name for p in sorted(SHIPPED_DIR.glob("member-*"))] == settings["members"]
    assert settings["command"].startswith("warpcut generalist")
    assert settings["env"]["lookahead"] == GENERALIST_LOOKAHEAD
    assert settings["figures"]["validation_improvement_pct"] is not None
    from agents.generalist import load_generalist

    actor = load_generalist("generalist").actor
    assert policy_layout(actor.state_dict())[0] == observation_bounds(12, True, GENERALIST_LOOKAHEAD)[0].size


def test_the_sensitivity_studies_take_the_generalist(generalist_run, tmp_path):
    code, output, _ = invoke(
        ["robustness", "--contour", "circle-small", "--study", "noise", "--methods", "none,fixed,generalist",
         "--trials", "2", "--set", "values=[0.0,0.1]", "--set", f"generalist={generalist_run[0]}", "--out",
         str(tmp_path / "rob"), "--set", "plots=false", *SMALL]
    )  # fmt: skip
    assert code == 0, output
    report = json.loads((tmp_path / "rob" / "robustness-noise.json").read_text())
    assert report["methods"] == ["fixed", "generalist"]
    assert np.isfinite(report["generalist"]["median"]).all()


def test_run_holds_still_where_the_generalist_validates_no_better(generalist_run, tmp_path):
    """A generalist that pushes the grasp away validates worse than holding still at every candidate and
    gain: run keeps the still grasp at the plan's pinch, fixed tension trial for trial."""
    out = tmp_path / "run"
    still = _pushing_generalist(generalist_run)
    code, output, _ = invoke(
        ["run", "--contour", "circle-small", "--policy", "generalist", "--generalist", str(still),
         "--out", str(out), "--set", "candidates=2", "--set", "trials=2", "--set", "plots=false", *SMALL]
    )  # fmt: skip
    assert code == 0, output
    report = json.loads((out / "results.json").read_text())
    row = report["rows"][0]
    assert report["generalist_holds_still"] is True
    assert row["generalist_trials_error_vertices"] == row["fixed_trials_error_vertices"]
    assert "still_error_vertices" in report["candidates"][0]


def _with_members(generalist_run, main, *members):
    """A generalist directory with ``main``'s policy and ``members`` (generalist directories) as its members,
    laid out as warpcut ships one."""
    import shutil

    from agents.generalist import MEMBERS

    out = generalist_run[0].parent / ("with-" + "-".join(p.name for p in (main, *members)))
    shutil.rmtree(out, ignore_errors=True)
    shutil.copytree(main, out)
    names = [f"member-{k}" for k in range(1, len(members) + 1)]
    for name, member in zip(names, members, strict=True):
        shutil.copytree(member, out / name)
    settings = json.loads((out / GENERALIST_FILE).read_text())
    (out / GENERALIST_FILE).write_text(json.dumps({**settings, MEMBERS: names}))
    return out


def test_each_member_of_a_generalist_plays_its_own_contours(generalist_run):
    """``members`` says which policy plays each contour: a member that holds still cuts fixed tension's
    trials there, bit for bit, and the generalist's own policy its own trials on the others."""
    from agents.evaluation import run_method
    from agents.generalist import generalist_result

    pushing, still = _pushing_generalist(generalist_run), _still_generalist(generalist_run)
    both = load_generalist(_with_members(generalist_run, pushing, still))
    assert len(both.members) == 1 and len(both.actors) == 2
    contours = generate_contours(2, "test", 0, COARSE)
    pinches = [listed[0][0] for listed in _candidates(contours, 1)]
    mixed = generalist_result(both, contours, pinches, None, 2, COARSE, "cpu", 3, members=[1, 0])
    held = run_method(contours, pinches, None, 2, COARSE, "cpu", 3)
    own = generalist_result(load_generalist(pushing), contours, pinches, None, 2, COARSE, "cpu", 3)
    assert np.array_equal(mixed.error_vertices[0], held.error_vertices[0])
    assert np.array_equal(mixed.error_vertices[1], own.error_vertices[1])
    assert not np.array_equal(own.error_vertices[0], held.error_vertices[0])  # the members differ there


def test_the_guarded_generalist_plays_the_member_it_validates_best(generalist_run, monkeypatch):
    """Every candidate is validated with each member's moves; the (member, candidate) with the lowest
    validation error plays, and the fine-tuning cut is its own policy's alone."""
    import agents.generalist as module
    from agents.policies import VALIDATION_SEED_OFFSET

    contours = generate_contours(2, "test", 0, COARSE)
    candidates = [listed[:2] for listed in _candidates(contours, 2)]
    generalist = load_generalist(_with_members(generalist_run, generalist_run[0], generalist_run[0]))
    real, batches = module.generalist_result, []

    def fake(gen, contours_, pinches, segments, trials, config, device, seed, *a, members=None, **k):
        result = real(
            gen, contours_, pinches, segments, trials, config, device, seed, *a, members=members, **k
        )
        if seed == 3 + VALIDATION_SEED_OFFSET:  # the first contour best with member 1, the second with 0
            batches.append(list(members))
            best = [1 if c is contours[0] else 0 for c in contours_]
            errors = [1.0 + (m != b) for m, b in zip(members, best, strict=True)]
            result.error_vertices[:] = np.array(errors).reshape(-1, 1)
        return result

    monkeypatch.setattr(module, "generalist_result", fake)
    guarded = module.guarded_result(
        generalist, contours, candidates, 2, COARSE, "cpu", 3, gains=[1], finalists=1
    )
    assert batches == [[0, 0, 1, 1, 0, 0, 1, 1]]  # per contour each member at every candidate
    assert guarded.member.tolist() == [1, 0] and guarded.chosen == [0, 0]
    assert [v.tolist() for v in guarded.validation] == [[1.0, 1.0], [1.0, 1.0]]  # the best member's
    batches.clear()
    generalist_cut(generalist, contours[0], COARSE, seed=3, device="cpu")
    assert batches and all(set(b) == {0} for b in batches)


def test_the_generalist_s_finalists_play_again_on_fresh_episodes(generalist_run, monkeypatch):
    """With finalists, each contour's best options by the validation episodes play again on fresh ones and
    the lowest mean over both wins; with one, the best on the validation episodes alone, and no more
    episodes."""
    import agents.generalist as module
    from agents.policies import VALIDATION_SEED_OFFSET as OFFSET

    contours = generate_contours(2, "test", 0, COARSE)
    candidates = [listed[:3] for listed in _candidates(contours, 3)]
    generalist = load_generalist(generalist_run[0])
    real, seen = module.generalist_result, []
    validation = {3 + OFFSET: [1.0, 2.0, 3.0], 3 + 3 * OFFSET: [5.0, 1.0, 0.0]}  # per candidate

    def fake(gen, contours_, pinches, segments, trials, config, device, seed, *a, **k):
        result = real(gen, contours_, pinches, segments, trials, config, device, seed, *a, **k)
        if seed in validation:
            at = [
                next(i for i, (p, _) in enumerate(candidates[contours.index(c)]) if np.allclose(p, q))
                for c, q in zip(contours_, pinches, strict=True)
            ]
            seen.append((seed, at))
            result.error_vertices[:] = np.array([validation[seed][i] for i in at]).reshape(-1, 1)
        return result

    monkeypatch.setattr(module, "generalist_result", fake)
    guarded = module.guarded_result(
        generalist, contours, candidates, 2, COARSE, "cpu", 3, gains=[1], finalists=1
    )
    assert guarded.chosen == [0, 0] and [seed for seed, _ in seen] == [3 + OFFSET]
    seen.clear()
    guarded = module.guarded_result(
        generalist, contours, candidates, 2, COARSE, "cpu", 3, gains=[1], finalists=2
    )
    assert seen[1] == (3 + 3 * OFFSET, [0, 1, 0, 1])  # the best two of each contour, on fresh episodes
    assert guarded.chosen == [1, 1]  # (2 + 1) / 2 beats (1 + 5) / 2; the third never plays again


def test_a_generalist_ships_with_its_members_and_refuses_a_member_that_differs(generalist_run, tmp_path):
    from agents.generalist import MEMBERS
    from agents.pipelines.generalist import ship_generalist

    dest = ship_generalist(generalist_run[0], tmp_path / "shipped", members=[generalist_run[0]])
    settings = json.loads((dest / GENERALIST_FILE).read_text())
    assert settings[MEMBERS] == ["member-1"] and (dest / "member-1" / "best.pt").is_file()
    assert len(load_generalist(dest).members) == 1
    ship_generalist(None, dest, members=[generalist_run[0]])  # joins the generalist already there
    assert json.loads((dest / GENERALIST_FILE).read_text())[MEMBERS] == ["member-1", "member-2"]
    assert len(load_generalist(dest).members) == 2
    member = dest / "member-1" / GENERALIST_FILE
    own = json.loads(member.read_text())
    member.write_text(json.dumps({**own, "env": {**own["env"], "lookahead": own["env"]["lookahead"] + 1}}))
    with pytest.raises(ValueError, match=r"member 'member-1': observes or acts otherwise .*lookahead differ"):
        load_generalist(dest)
    (dest / GENERALIST_FILE).write_text(json.dumps({**settings, MEMBERS: ["../shipped"]}))
    with pytest.raises(ValueError, match=r"member '\.\./shipped': name a folder inside"):
        load_generalist(dest)
    (dest / GENERALIST_FILE).write_text(json.dumps({**settings, MEMBERS: "member-1"}))
    with pytest.raises(ValueError, match=r"members must be a list"):
        load_generalist(dest)


def test_evaluate_and_run_play_a_generalist_with_members(generalist_run, tmp_path, capfd):
    """A member that pushes the grasp away never validates best beside one that holds still: evaluate's
    column and run play the still member's choices or hold still, and ``generalist_members=1`` keeps the
    generalist's own policy alone."""
    both = str(
        _with_members(generalist_run, _pushing_generalist(generalist_run), _still_generalist(generalist_run))
    )
    base = ["--contours", "gen-test-0:2", "--methods", "none,fixed,generalist", "--generalist", both,
            "--trials", "2", "--set", "candidates=2", "--set", "plots=false", *SMALL]  # fmt: skip
    for members, expected in ((None, 1), (1, 0)):
        results = tmp_path / f"evaluate-{members}"
        extra = [] if members is None else ["--set", f"generalist_members={members}"]
        code, output, _ = invoke(["evaluate", *base, "--out", str(results), *extra])
        assert code == 0, output
        rows = json.loads((results / "results.json").read_text())["rows"]
        assert [r["generalist_member"] for r in rows] == [expected, expected]
    code, output, _ = invoke(
        ["run", "--contour", "circle-small", "--policy", "generalist", "--generalist", both, "--out",
         str(tmp_path / "run"), "--set", "candidates=2", "--set", "trials=2", "--set", "plots=false", *SMALL]
    )  # fmt: skip
    assert code == 0, output
    chosen = json.loads((tmp_path / "run" / "results.json").read_text())
    assert "generalist_member" in json.dumps(chosen)
    for key in ("generalist_members", "generalist_finalists"):
        line = refused(["evaluate", *base, "--set", f"{key}=0"], capfd)
        assert key in line and ">= 1" in line
