"""Per-env parameters changed between episodes, domain randomisation, and the sensitivity studies
(:mod:`agents.pipelines.robustness`; the command line's tests: tests/test_cli_robustness.py)."""

import json
import re

import numpy as np
import pytest
from click.testing import CliRunner

from agents.cli import main
from agents.config import TrainConfig
from agents.jobs import RobustnessJob, TrainJob
from agents.pipelines import robustness
from agents.pipelines.robustness import check_job, robustness_study, robustness_table
from agents.pipelines.robustness_studies import check_runs, check_study, parse_studies
from agents.plan_optimizer.config import GradConfig
from envs.options import EnvConfig, PatternCutOptions
from envs.vector import PatternCutVecEnv
from warpcut.contours import load_contour
from warpcut.sim.config import RANDOMIZE_LEVELS, RANDOMIZE_RANGES, ConfigError, SimConfig, randomize_ranges
from warpcut.task import CuttingTask

pytestmark = pytest.mark.usefixtures("one_torch_thread")
RES = 13  # a coarse sheet: fast, and fine enough for the FLS circle


def invoke(args):
    result = CliRunner().invoke(main, args, standalone_mode=True, catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def test_parameters_set_between_episodes_cut_as_a_batch_built_with_them():
    """Per-env gravity and noise set on a running task give the same bits as a task built with them, and
    setting the nominal values back gives the nominal bits; settled sheets are not settled twice."""
    contour = load_contour("fls-circle")
    gravity, noise = [300.0, 521.0, 800.0], [0.0, 0.03, 0.1]
    built = CuttingTask(SimConfig(resolution=RES, gravity=gravity, noise_std=noise), contour, 3, seed=3)
    expected = built.run(None)
    task = CuttingTask(SimConfig(resolution=RES), contour, 3, seed=3)
    nominal = task.run(None)
    task.set_params(gravity=gravity, noise_std=noise)
    assert task.done, "a change of parameters ends the episode: reset next"
    changed = task.run(None)
    np.testing.assert_array_equal(changed.error_mm2, expected.error_mm2)
    assert task.num_steps == built.num_steps
    assert not np.array_equal(changed.error_mm2, nominal.error_mm2)
    sheets = len(task.sim._settle_cache)
    task.set_params(gravity=521.0, noise_std=0.03)
    np.testing.assert_array_equal(task.run(None).error_mm2, nominal.error_mm2)
    assert len(task.sim._settle_cache) == sheets, "a sheet settled before was settled again"


def test_parameters_swapped_between_envs_lay_each_env_out_on_its_own_sheet():
    """The same set of values, assigned to other envs: each env's trajectory follows its new sheet."""
    contour = load_contour("fls-circle")
    task = CuttingTask(SimConfig(resolution=RES, gravity=[300.0, 800.0]), contour, 2, seed=1)
    task.set_params(gravity=[800.0, 300.0])
    built = CuttingTask(SimConfig(resolution=RES, gravity=[800.0, 300.0]), contour, 2, seed=1)
    np.testing.assert_array_equal(task._tips, built._tips)
    np.testing.assert_array_equal(task.run(None).error_mm2, built.run(None).error_mm2)


def test_set_params_names_a_bad_parameter():
    task = CuttingTask(SimConfig(resolution=RES), load_contour("fls-circle"), 2)
    with pytest.raises(ValueError, match="set_params: unknown stiffness; choose from damping"):
        task.set_params(stiffness=1.0)
    with pytest.raises(ConfigError, match="gravity"):
        task.set_params(gravity=[-1.0, 2.0])
    with pytest.raises(ConfigError, match="noise_std: got 3 values for 2 envs"):
        task.set_params(noise_std=[0.1, 0.2, 0.3])


def test_randomize_ranges_take_aliases_defaults_and_name_what_is_wrong():
    assert randomize_ranges("gravity,noise") == {
        "gravity": RANDOMIZE_RANGES["gravity"],
        "noise_std": RANDOMIZE_RANGES["noise_std"],
    }
    assert randomize_ranges(["elasticity"], {"elasticity": [0.8, 1.0]}) == {"elasticity": (0.8, 1.0)}
    for names, ranges, message in [
        ("wind", None, "randomize: unknown parameter 'wind'; choose from gravity"),
        ("gravity", {"gravity": [5.0, 1.0]}, "randomize_ranges: gravity: give finite low <= high"),
        ("gravity", {"gravity": [0.0]}, r"randomize_ranges: gravity: give \[low, high\]"),
        (
            "gravity",
            {"gravity": [-5.0, 1.0]},
            r"randomize_ranges: gravity: \[-5, 1\]: a number in \[0, 100000\] mm/s\^2",
        ),
        ("gravity", {"noise_std": [0.0, 0.1]}, "randomize_ranges: noise_std not randomised; add it"),
    ]:
        with pytest.raises(ValueError, match=message):
            randomize_ranges(names, ranges)


def test_randomised_envs_draw_their_parameters_per_env_and_per_reset_on_the_levels():
    options = PatternCutOptions(
        contour="fls-circle", resolution=RES, randomize=["gravity", "noise"], device="cpu"
    )
    env = PatternCutVecEnv(8, options)
    draws = []
    for seed in (0, 1, 0):
        env.reset(seed=seed)
        params = env.task.sim.params
        draws.append((params["gravity"].copy(), params["noise_std"].copy()))
    (g0, n0), (g1, _), (g2, n2) = draws
    low, high = RANDOMIZE_RANGES["gravity"]
    levels = low + (high - low) * np.arange(RANDOMIZE_LEVELS) / (RANDOMIZE_LEVELS - 1)
    assert g0.shape == (8,) and len(np.unique(g0)) > 1, "every env draws its own gravity"
    assert np.all(np.isclose(g0[:, None], levels[None, :], rtol=1e-6).any(axis=1))
    assert not np.array_equal(g0, g1), "a new episode draws anew"
    np.testing.assert_array_equal(g0, g2)  # a seed gives the same draws
    np.testing.assert_array_equal(n0, n2)
    # The episode is laid out on each env's own settled sheet: the same as a batch built with the draws.
    built = CuttingTask(SimConfig(resolution=RES, gravity=g2, noise_std=n2), load_contour("fls-circle"), 8)
    np.testing.assert_array_equal(env.task._tips, built._tips)
    assert env.scene.episode_steps == built.num_steps


def test_options_keep_the_randomisation_and_evaluate_on_the_nominal_sheet():
    options = PatternCutOptions(randomize=["gravity"], randomize_ranges={"gravity": [100.0, 900.0]})
    again = PatternCutOptions.from_dict(json.loads(json.dumps(options.to_dict())))
    assert again.randomized() == {"gravity": (100.0, 900.0)}
    assert again.nominal().randomized() == {} and again.nominal().contour == options.contour
    with pytest.raises(ValueError, match="options: randomize: a list of parameter names"):
        PatternCutOptions.from_dict({**options.to_dict(), "randomize": "gravity"})
    with pytest.raises(ValueError, match="options: randomize: unknown parameter 'wind'"):
        PatternCutOptions.from_dict({**options.to_dict(), "randomize": ["wind"]})


def test_studies_and_their_values_are_checked():
    assert parse_studies("noise, force") == ["noise", "force"]
    assert parse_studies("all") == ["resolution", "noise", "force"]
    with pytest.raises(ValueError, match="study: choose from resolution, noise, force or all"):
        parse_studies("wind")
    assert check_study("resolution", [12.0, 25]) == [12, 25]
    with pytest.raises(ValueError, match="values: resolutions are whole numbers"):
        check_study("resolution", [12.5])
    with pytest.raises(ValueError, match="values: force -1.*gravity"):
        check_study("force", [-1.0])
    for label in ("fixed", "grad", "nominal", "values", "2nd"):
        with pytest.raises(ValueError, match=f"runs: label '{label}' must be a plain name"):
            check_runs({label: "."})
    with pytest.raises(ValueError, match="runs: .* is not one trained policy's run"):
        check_runs({"rl": "tests"})
    job = check_job(RobustnessJob(contour="fls-circle", study=["all"]))
    assert job.study == ["resolution", "noise", "force"]  # one spelling: config.json compares on resume
    for wrong, message in [
        (dict(study=[]), "study: choose from"),
        (dict(study=["noise", "force"], values=[0.0]), "values: give the values of one study"),
        (dict(study=["noise"], methods=["rl"]), "methods: unknown rl; choose from none,fixed,analytic,gener"),
        (dict(study=["noise"], trials=0), "trials: must be an integer >= 1"),
        (dict(study=["noise"], contour=None), r"contour: give the contour \(--contour\), or trained runs"),
        (dict(study=["noise"], plans={"fixed": "x.json"}), "plans: label 'fixed' must be a plain name"),
        (dict(study=["noise"], grad=GradConfig(iterations=0)), "grad.iterations: must be a positive integer"),
    ]:
        with pytest.raises(ValueError, match=message):
            check_job(RobustnessJob(**{"contour": "fls-circle", **wrong}))


def test_force_study_is_one_batch_with_a_sheet_per_gravity():
    """Every gravity settles its own sheet in one batch: with no gravity the sheet lies flat and the cut
    lands where it should, so no tension's error is far below the nominal sheet's."""
    report = robustness_study(
        "fls-circle", "force", values=[0.0, 521.0], trials=2, config=SimConfig(resolution=RES), device="cpu"
    )
    assert report["study"] == "force" and report["values"] == [0.0, 521.0] and report["nominal"] == 521.0
    assert report["methods"] == ["fixed", "analytic"] and report["metric"] == "improvement_pct"
    for method in ("fixed", "analytic"):
        assert set(report[method]) >= {"median", "q25", "q75"}
        assert all(len(report[method][q]) == 2 for q in ("median", "q25", "q75"))
        assert all(
            lo <= med <= hi
            for lo, med, hi in zip(*(report[method][q] for q in ("q25", "median", "q75")), strict=True)
        )
    flat, hanging = report["none_error_mm2"]["median"]
    assert flat < 0.25 * hanging
    # Every trial is kept, and the median's interval is computed from them.
    for method in ("fixed", "none_error_mm2"):
        per_trial, cis = report[method]["per_trial"], report[method]["median_ci95"]
        assert [len(row) for row in per_trial] == [2, 2]
        for row, (low, high), median in zip(per_trial, cis, report[method]["median"], strict=True):
            assert min(row) <= low <= median <= high <= max(row)


def _study(study: str, values: list[float], nominal: float, rows: list[list[float]]) -> dict:
    """A study report with one method, ``p``, as robustness_study writes them (the statistics used)."""
    rows_ = np.asarray(rows, dtype=np.float64)
    return {
        "study": study, "values": values, "nominal": nominal, "methods": ["p"],
        "p": {
            "median": [float(np.median(r)) for r in rows_],
            "median_ci95": [list(np.percentile(r, [2.5, 97.5])) for r in rows_],  # stands in for bootstrap
            "per_trial": rows_.tolist(),
        },
    }  # fmt: skip


def _tables():
    """The script that writes docs/robustness.md's tables and checks the robustness target (it lives beside
    them, not in the library: no command reads it)."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scripts" / "robustness_tables.py"
    spec = importlib.util.spec_from_file_location("robustness_tables", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


tables = _tables()
robustness_target = tables.robustness_target


def test_sweep_medians_compare_each_policy_with_the_plan(tmp_path):
    """A row per study: each method's median over the sweep of its per-value medians, and the values where a
    policy's median is at least the plan's."""
    report = {
        "study": "noise", "contour": "c", "values": [0.0, 0.03, 0.06], "methods": ["none", "fixed"],
        "runs": {"p": "RUN"}, "plans": {"plan": "FILE"},
        "fixed": {"median": [10.0, 20.0, 30.0]}, "p": {"median": [50.0, 40.0, 45.0]},
        "plan": {"median": [45.0, 42.0, 44.0]},
    }  # fmt: skip
    path = tmp_path / "robustness-noise.json"
    path.write_text(json.dumps(report))
    lines = tables.sweep_medians([path])
    assert lines[0] == "| contour | study | fixed | p | plan | values where ≥ the plan |"
    assert lines[2] == "| c | noise | +20.0 | +45.0 | +44.0 | p 2/3 |"


def test_robustness_target_reads_medians_and_intervals():
    """The target's two readings: medians alone, and 95% intervals that tell a clear miss from one the
    trials cannot decide."""
    rng = np.random.default_rng(0)
    spread = rng.normal(0.0, 1.0, 30)
    force = _study("force", [0.0, 521.0], 521.0, [list(-20.0 + spread), list(40.0 + spread)])
    noise = _study(
        "noise", [0.0, 0.03, 0.06, 0.09], 0.03,
        [[30.0] * 30, list(50.0 + 20 * spread), list(49.0 + 20 * spread[::-1]), list(20.0 + spread)],
    )  # fmt: skip
    result = robustness_target({"force": force, "noise": noise}, "p")
    assert result["force"]["below"] == [0.0] and not result["force"]["median_met"]
    assert result["force"]["ci"] == ["out", "in"] and result["force"]["ci_met"] == "no"
    n = result["noise"]
    assert n["nominal"] == 0.03 and n["values"] == [0.0, 0.06, 0.09]
    assert n["band"] == pytest.approx(0.1 * abs(np.median(50.0 + 20 * spread)))
    # 0.06 is close to the nominal by its median, but 30 noisy trials cannot show it within 10%: open.
    assert n["ci"][1] == "open" and n["ci"][2] == "out" and n["ci_met"] == "no"
    assert n["deterministic"] == [0.0]  # thirty identical trials: one outcome
    assert not n["median_met"] and n["within"] == 1
    both_fine = robustness_target({"force": _study("force", [0.0], 521.0, [list(5.0 + spread)])}, "p")
    assert both_fine["force"]["ci_met"] == "yes" and both_fine["force"]["median_met"]
    with pytest.raises(ValueError, match="policy: 'q' is not in the force report"):
        robustness_target({"force": force}, "q")


def test_robustness_target_counts_diverging_more_often_than_no_tension_against_the_policy():
    """A value where the policy's sheet diverged in more trials than no tension's is out in both readings,
    whatever the remaining trials say."""
    spread = np.random.default_rng(1).normal(0.0, 1.0, 30)
    force = _study("force", [0.0, 521.0], 521.0, [list(5.0 + spread), list(40.0 + spread)])
    noise = _study("noise", [0.03, 0.27], 0.03, [list(50.0 + spread), list(50.0 + spread[::-1])])
    fine = robustness_target({"force": force, "noise": noise}, "p")
    assert fine["force"]["ci_met"] == "yes" and fine["noise"]["ci_met"] == "yes"
    assert fine["force"]["diverged_more"] == [] and fine["noise"]["median_met"]
    force["diverged"] = {"none": [1, 0], "p": [1, 2]}  # as many as none at 0, more at 521
    noise["diverged"] = {"none": [0, 0], "p": [0, 1]}
    result = robustness_target({"force": force, "noise": noise}, "p")
    f, n = result["force"], result["noise"]
    assert f["diverged_more"] == [521.0] and f["ci"] == ["in", "out"] and f["ci_met"] == "no"
    assert not f["median_met"] and f["below"] == []  # the medians alone are above 0
    assert n["diverged_more"] == [0.27] and n["ci"] == ["out"] and n["ci_one_sided"] == ["out"]
    assert n["within"] == 0 and not n["median_met"] and not n["median_met_one_sided"]
    assert not n["nominal_diverged_more"] and not fine["noise"]["nominal_diverged_more"]
    noise["diverged"] = {"none": [0, 0], "p": [1, 0]}  # the policy fails more often at the nominal value
    n = robustness_target({"noise": noise}, "p")["noise"]
    assert n["nominal_diverged_more"] and n["diverged_more"] == [0.03]
    assert n["ci"] == ["out"] and n["ci_met"] == "no" and n["ci_met_one_sided"] == "no"
    assert n["within"] == 0 and not n["median_met"] and not n["median_met_one_sided"]


@pytest.mark.usefixtures("unbounded_noise")
def test_a_study_scores_the_trials_that_did_not_diverge_and_counts_the_rest():
    """At an absurd process noise some sheets blow up: the study goes on, leaves each diverged trial out
    of its pair with no tension, and counts them per method and value (report, log and table)."""
    lines = []
    report = robustness_study(
        "fls-circle", "noise", values=[0.03, 30.0], trials=6, methods=["none", "fixed"],
        config=SimConfig(resolution=RES), device="cpu", log=lines.append,
    )  # fmt: skip
    diverged = report["diverged"]
    assert diverged["none"][0] == diverged["fixed"][0] == 0
    assert (
        0 < max(diverged["none"][1], diverged["fixed"][1])
        and min(diverged["none"][1], diverged["fixed"][1]) < 6
    )
    left_out = sum(v is None for v in report["fixed"]["per_trial"][1])
    assert max(diverged["none"][1], diverged["fixed"][1]) <= left_out < 6  # a pair goes if either diverged
    assert report["fixed"]["median"][1] is not None and np.isfinite(report["fixed"]["median"][1])
    assert any(re.search(r"noise 30: diverged trials \(left out of their pairs\): none \d", x) for x in lines)
    assert any(
        x.startswith("at 30: diverged trials (left out of their pairs)") for x in robustness_table(report)
    )


def test_resolution_study_skips_a_mesh_too_coarse_for_the_contour():
    """At 10 x 10 the analytic tensioner's grasp finds no room beside the FLS circle: that resolution is
    skipped for every method, the others run."""
    report = robustness_study(
        "fls-circle", "resolution", values=[10, RES], trials=2, methods=["none", "analytic"], device="cpu"
    )
    assert report["skipped"] == [10.0] and report["metric"] == "error_pct_of_sheet"
    assert report["methods"] == ["none", "analytic"]
    assert report["none"]["median"][0] is None and report["analytic"]["median"][0] is None
    assert 0 < report["none"]["median"][1] < 100


def test_train_names_a_bad_randomised_parameter(tmp_path):
    code, _, err = invoke(
        ["train", "--contour", "fls-circle", "--set", "env.randomize=[wind]", "--out", str(tmp_path / "x")]
    )
    assert code == 2 and "randomize: unknown parameter 'wind'" in err


def test_grad_plays_its_plan_at_every_value_and_is_optimised_once(tmp_path):
    settings = GradConfig(iterations=2, trials=2, validation_trials=2)
    job = RobustnessJob(
        contour="fls-circle", study=["noise", "force"], methods=["none", "grad"], trials=2,
        sim=SimConfig(resolution=RES), grad=settings,
    )  # fmt: skip
    reports = robustness(job, tmp_path, device="cpu")
    plan = json.loads((tmp_path / "grad" / "fls-circle.json").read_text())
    assert len(plan["history"]) == settings.iterations + 1
    for report in reports:
        assert report["methods"] == ["grad"] and len(report["grad"]["median"]) == len(report["values"])
    # The second study read the plan back: the file was written once, before it.
    assert (tmp_path / "grad" / "fls-circle.json").stat().st_mtime <= (
        tmp_path / "robustness-noise.json"
    ).stat().st_mtime


def test_relative_reward_weighs_each_sheet_by_its_no_tension_error():
    """Each env's reward is its plain reward times the nominal sheet's no-tension error over its own: 1 on
    the nominal sheet, larger on a flatter one, clipped on a sheet that hangs flat."""
    from warpcut.task import RELATIVE_REWARD_MAX_SCALE

    gravity = [521.0, 260.5, 0.0]
    plain = PatternCutVecEnv(3, PatternCutOptions(contour="fls-circle", resolution=RES, gravity=gravity))
    options = PatternCutOptions(contour="fls-circle", resolution=RES, relative_reward=True)
    scaled = PatternCutVecEnv(3, options)
    scaled.reset(seed=0)
    scaled.task.set_params(gravity=gravity)  # as a randomised reset would draw them
    scaled.scene.reset(np.random.default_rng(0), True)
    plain.scene.reset(np.random.default_rng(0), True)
    scale = scaled.scene.reward_scale
    np.testing.assert_array_equal(plain.scene.reward_scale, np.ones(3))
    assert scale[0] == pytest.approx(1.0) and 1.0 < scale[1] < RELATIVE_REWARD_MAX_SCALE
    assert scale[2] == RELATIVE_REWARD_MAX_SCALE
    none = CuttingTask(
        SimConfig(resolution=RES, gravity=gravity, noise_std=0.0), load_contour("fls-circle"), 3
    )
    errors = none.run(None).error_mm2
    assert scale[1] == pytest.approx(errors[0] / errors[1])
    actions = np.zeros((3, *plain.scene.action_space.shape), dtype=np.float32)  # hold still
    for _ in range(plain.scene.episode_steps):
        _, r_plain, *_ = plain.scene.step(actions)
        _, r_scaled, *_ = scaled.scene.step(actions)
        np.testing.assert_allclose(r_scaled, r_plain * scale)
    assert (r_plain < 0).all(), "the last step carries the final error"


def test_a_run_cut_in_another_order_is_paired_with_no_tension_in_that_order(tmp_path):
    """Two runs of one contour with different cut orders: each policy's improvement is over no tension cut
    in its own order, so the same run gives the same figures whether it comes first or second."""
    loop = load_contour("fls-circle")
    half = len(loop.points) // 2
    other = [loop.points[: half + 1].tolist(), loop.points[half:].tolist() + [loop.points[0].tolist()]]
    runs = {}
    for label, segments in (("whole", None), ("split", other)):
        code, _, err = invoke(
            ["train", "--contour", "fls-circle", "--algo", "es",
            "--iterations", "1", "--num-envs", "4", "--set",
             "train.es.population=4", "--set", "train.validation_trials=0", "--set", "eval_trials=2",
             "--device", "cpu", "--out", str(tmp_path / label), "--no-progress", "--set", "plots=false"]
        )  # fmt: skip
        assert code == 0, err
        if segments is not None:  # the run's own order, as a plan would give it
            path = tmp_path / label / "options.json"
            options = json.loads(path.read_text())
            path.write_text(json.dumps({**options, "segments": segments}))
        runs[label] = tmp_path / label
    both = robustness_study(None, "noise", runs=runs, values=[0.03], trials=2, methods=["none"], device="cpu")
    alone = robustness_study(
        None, "noise", runs={"split": runs["split"]}, values=[0.03], trials=2, methods=["none"]
    )
    assert both["own_order_none"] == ["split"] and alone["own_order_none"] == []
    assert both["split"]["median"] == alone["split"]["median"]


def test_a_randomised_run_compares_its_pinch_candidates_on_the_nominal_sheet(tmp_path):
    """``warpcut run --randomize``: each candidate's policy validated on randomised sheets; the candidates
    are compared by their policies' error on the nominal sheet's validation episodes."""
    from agents.policies import nominal_validation_error

    out = tmp_path / "run"
    code, _, err = invoke(
        ["run", "--contour", "circle-small", "--set", "env.randomize=[gravity]", "--set", "candidates=2",
         "--set", "rl_candidates=1", "--set", "train.iterations=2", "--set", "trials=2", "--set",
         "train.num_envs=8", "--set", "train.algo=es",
         "--set", "train.es.population=4", "--set", f"sim.resolution={RES}",
         "--device", "cpu", "--out", str(out), "--set", "plots=false"]
    )  # fmt: skip
    assert code == 0, err
    candidate = json.loads((out / "results.json").read_text())["candidates"][0]
    assert "rl_training_validation_error" in candidate
    run = out / candidate["run"]
    assert json.loads((run / "options.json").read_text())["randomize"] == ["gravity"]
    expected = nominal_validation_error(run, 16, seed=0, device="cpu")
    assert candidate["rl_validation_error_vertices"] == pytest.approx(expected)


def test_apg_refuses_randomised_sheets_in_the_library_and_on_the_command_line(tmp_path):
    from agents.algorithms import algorithm

    APG_FIXED_SHEET = algorithm("apg").fixed_sheet  # noqa: N806 -- the registry's refusal
    from agents.training import train_contour

    job = TrainJob(
        contour="fls-circle", sim=SimConfig(resolution=RES),
        env=EnvConfig(randomize=["gravity"], action_type="continuous"),
        train=TrainConfig(algo="apg", iterations=1, num_envs=2, validation_trials=0),
    )  # fmt: skip
    with pytest.raises(ValueError, match=re.escape(APG_FIXED_SHEET)):
        train_contour(job, tmp_path / "apg", device="cpu", progress=False)
    args = ["train", "--contour", "fls-circle", "--algo", "apg", "--set", "env.relative_reward=true"]
    code, _, err = invoke(args + ["--out", str(tmp_path / "cli")])
    assert code == 2 and APG_FIXED_SHEET in err


def test_optimised_plans_are_played_as_methods_closed_loop_included(tmp_path):
    from agents.plan_optimizer.optimizer import optimize_plan
    from warpcut.io import write_json
    from warpcut.planning import plan_cut

    config = SimConfig(resolution=RES)
    contour = load_contour("fls-circle")
    planned = plan_cut(contour, config.replace(noise_std=0.0))
    settings = GradConfig(
        estimator="es", iterations=1, es_population=2, es_trials=1, validation_trials=1, es_feedback_phases=1
    )
    result = optimize_plan(contour, planned.chosen["pinch"], planned.ordered_segments(), config, settings)
    result.gains = np.full((1, 3, 2), 0.5, np.float32)  # strong feedback: it must change the cut
    write_json(tmp_path / "closed.json", result.to_json())
    write_json(tmp_path / "open.json", {**result.to_json(), "gains": None})
    plans = {"closed": str(tmp_path / "closed.json"), "open": str(tmp_path / "open.json")}
    job = RobustnessJob(
        contour="fls-circle", study=["noise"], plans=plans, methods=["none"], values=[0.0, 0.03], trials=2,
        sim=config,
    )  # fmt: skip
    (report,) = robustness(job, tmp_path / "out", device="cpu")
    assert report["methods"] == ["closed", "open"] and report["plans"]["closed"].endswith("closed.json")
    assert len(report["closed"]["median"]) == 2
    assert report["closed"]["mean"] != report["open"]["mean"]  # the gains acted
    write_json(tmp_path / "other.json", {**result.to_json(), "contour": "kidney"})
    with pytest.raises(ValueError, match="plans: .*other.json is a plan for 'kidney', not 'fls-circle'"):
        robustness_study("fls-circle", "noise", plans={"x": tmp_path / "other.json"}, config=config)
    with pytest.raises(ValueError, match="plans: label 'fixed' must be a plain name"):
        robustness_study("fls-circle", "noise", plans={"fixed": tmp_path / "open.json"}, config=config)
    (tmp_path / "bad.json").write_text("{}")
    with pytest.raises(ValueError, match="plans: .*bad.json is not an optimised plan"):
        robustness_study("fls-circle", "noise", plans={"x": tmp_path / "bad.json"}, config=config)
