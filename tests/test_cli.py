"""End-to-end tests of the ``warpcut`` command line (fast ones; one runs the installed console script)."""

import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from agents.cli import main
from warpcut.contours import load_contour
from warpcut.planning import default_pinch
from warpcut.planning.segmentation import segment_contour
from warpcut.sim.config import SimConfig
from warpcut.viz import read_summary


def invoke(args):
    """Run the CLI in-process and return (exit code, stdout, stderr)."""
    result = CliRunner().invoke(main, args, standalone_mode=True, catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["nonsense"], "No such command"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(args, message, capfd):
    with pytest.raises(SystemExit) as exit_info:
        main.main(args=args, prog_name="warpcut")
    assert exit_info.value.code == 2
    err = capfd.readouterr().err.strip().splitlines()
    err = [line for line in err if not line.startswith("Warp CUDA warning")]
    assert len(err) == 1, err
    assert err[0].startswith("error: ")
    assert re.search(message, err[0]), err[0]


def test_warp_starts_quietly_unless_asked():
    # Without NVIDIA's driver, Warp's C code prints a CUDA warning on every start; warpcut silences it
    # (and Warp's banner) unless WARPCUT_VERBOSE is set.
    code = (
        "import warpcut.sim.simulator, warpcut.sim._warp as w; w.wp.init(); print(w.wp.is_cuda_available())"
    )
    env = {k: v for k, v in os.environ.items() if k != "WARPCUT_VERBOSE"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    assert done.stderr == "", done.stderr
    verbose = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env={**env, "WARPCUT_VERBOSE": "1"}
    )
    assert "Warp 1." in verbose.stdout + verbose.stderr  # the banner is back
    if done.stdout.strip() == "False":
        assert "CUDA" in verbose.stdout + verbose.stderr  # what a CPU-only machine says about CUDA
    # Started with standard error closed (cron, daemons): nothing to silence, and nothing breaks.
    closed = subprocess.run(
        ["bash", "-c", f'"{sys.executable}" -c "{code}" 2>&-'], capture_output=True, text=True, env=env
    )
    assert closed.returncode == 0 and closed.stdout.strip() == done.stdout.strip()


def test_train_resume_export_and_evaluate_with_checkpoints(tmp_path):
    run = tmp_path / "runs" / "circle-small"
    common = ["--num-envs", "4", "--steps-per-env", "4", "--eval-trials", "2", "--no-progress"]
    code, stdout, _ = invoke(
        ["train", "--contour", "circle-small", "--iterations", "2", "--out", str(run), "--record", *common]
    )
    assert code == 0, stdout
    for name in (
        "config.json",
        "options.json",
        "summary.json",
        "evaluation.json",
        "latest.pt",
        "best.pt",
        "model_1.pt",
        "recording.rrd",
        "learning_curve.png",
    ):
        assert (run / name).is_file(), name
    # The final evaluation is recorded: the trained policy and no tension, each in its own tree.
    entities = read_summary(run / "recording.rrd").entity_paths
    assert "/rl/env_0/sheet" in entities and "/none/env_0/sheet" in entities
    assert "/rl/env_1/sheet" not in entities
    assert any(p.name.startswith("events.out.tfevents") for p in run.iterdir())
    assert json.loads((run / "summary.json").read_text())["iterations"] == 2

    code, stdout, _ = invoke(
        ["train", "--contour", "circle-small", "--iterations", "3", "--resume", str(run), *common]
    )
    assert code == 0, stdout
    assert json.loads((run / "summary.json").read_text())["iterations"] == 3
    assert (run / "model_2.pt").is_file()

    code, stdout, _ = invoke(["export", str(run)])
    assert (
        code == 0
        and (run / "exported" / "policy.pt").is_file()
        and (run / "exported" / "policy.onnx").is_file()
    )

    out = tmp_path / "table.json"
    code, stdout, _ = invoke(
        [
            "evaluate",
            "--contours",
            "circle-small",
            "--methods",
            "none,analytic,rl",
            "--trials",
            "2",
            "--checkpoints",
            str(tmp_path / "runs"),
            "--no-plan",
            "--out",
            str(tmp_path / "eval"),
            "--json",
            str(out),
            "--markdown",
            str(tmp_path / "t.md"),
        ]
    )
    assert code == 0, stdout
    report = json.loads(out.read_text())
    assert report["rows"][0]["contour"] == "circle-small"
    assert {"rl_improvement_pct", "rl_ci95", "analytic_improvement_pct", "none_error_vertices"} <= set(
        report["rows"][0]
    )
    assert "rl_improvement_pct" in report["mean"]
    assert "| **mean** |" in (tmp_path / "t.md").read_text()
    svg = (tmp_path / "eval" / "regions" / "circle-small.svg").read_text()  # rl's cut shown beside the rest
    assert all(f"{m}: " in svg for m in ("none", "analytic", "rl"))


def test_evaluate_two_contours_two_trials_writes_table_json(tmp_path):
    out = tmp_path / "results.json"
    code, stdout, _ = invoke(
        [
            "evaluate",
            "--contours",
            "fls-circle",
            "--contours",
            "s-curve",
            "--methods",
            "none,fixed,analytic",
            "--trials",
            "2",
            "--noise",
            "0.02",
            "--candidates",
            "3",
            "--out",
            str(tmp_path / "run"),
            "--json",
            str(out),
        ]
    )
    assert code == 0, stdout
    report = json.loads(out.read_text())
    assert report["planned"] is True
    plans = json.loads((tmp_path / "run" / "plans.json").read_text())
    assert report["analytic_pinch"] == "feasible"
    for row in report["rows"]:  # fixed pinches where planned; analytic at the centroid, or nearest to it
        contour = load_contour(row["contour"])
        assert row["fixed_pinch"] == pytest.approx(plans[row["contour"]]["chosen"]["pinch"])
        segments = segment_contour(contour)
        assert row["analytic_pinch"] == pytest.approx(
            list(default_pinch(contour, SimConfig(), segments=segments))
        )
    # The paper's arm (the default) keeps the grasp off the disc: its centroid is not feasible.
    assert report["rows"][0]["analytic_pinch"] != pytest.approx(list(load_contour("fls-circle").centroid))
    assert report["score"] == "path"
    assert report["rows"][0]["none_separated_fraction"] is not None
    assert [r["contour"] for r in report["rows"]] == ["fls-circle", "s-curve"]
    for row in report["rows"]:
        assert row["none_error_vertices"] > 0
        for m in ("fixed", "analytic"):
            assert isinstance(row[f"{m}_improvement_pct"], float) and row[f"{m}_ci95"] >= 0
    assert set(report["mean"]) >= {"fixed_improvement_pct", "analytic_improvement_pct"}
    assert (tmp_path / "run" / "results.json").is_file()
    for name in ("improvement.png", "plans/fls-circle.png", "plans/s-curve.svg"):
        assert (tmp_path / "run" / name).stat().st_size > 0, name
    # The cut regions: a figure per contour, every method's first trial.
    regions = tmp_path / "run" / "regions"
    assert sorted(p.name for p in regions.iterdir()) == [
        "fls-circle.png",
        "fls-circle.svg",
        "s-curve.png",
        "s-curve.svg",
    ]
    for path in regions.iterdir():
        assert path.stat().st_size > 1000, path
    svg = (regions / "s-curve.svg").read_text()
    assert "<svg" in svg[:1000] and "first of 2 trials" in svg
    assert all(f"wrote {regions / name}" in stdout for name in ("fls-circle.png", "s-curve.svg"))


def test_evaluate_no_plots_and_record_clamped_to_the_first_contour(tmp_path):
    out = tmp_path / "run"
    code, stdout, stderr = invoke(
        [
            "evaluate",
            "--contours",
            "fls-circle,s-curve",
            "--methods",
            "none",
            "--trials",
            "1",
            "--no-plan",
            "--no-plots",
            "--record",
            "3",
            "--out",
            str(out),
        ]
    )
    assert code == 0, stdout
    assert stderr.count("warning: --record 3") == 1 and "recording 1" in stderr, stderr
    assert not list(out.rglob("*.png")) and not list(out.rglob("*.svg")) and not (out / "regions").exists()
    entities = read_summary(out / "recording.rrd").entity_paths
    assert "/none/env_0/sheet" in entities and "/none/env_1/sheet" not in entities  # not s-curve's env


def test_evaluate_reports_missing_checkpoints(tmp_path, capfd):
    with pytest.raises(SystemExit) as exit_info:
        main.main(
            args=[
                "evaluate",
                "--contours",
                "fls-circle",
                "--methods",
                "none,rl",
                "--checkpoints",
                str(tmp_path),
                "--out",
                str(tmp_path / "o"),
            ],
            prog_name="warpcut",
        )
    assert exit_info.value.code == 2
    assert "no trained run for 'fls-circle'" in capfd.readouterr().err


def test_train_continuous_actions(tmp_path):
    run = tmp_path / "cont"
    code, stdout, _ = invoke(
        [
            "train",
            "--contour",
            "circle-small",
            "--actions",
            "continuous",
            "--iterations",
            "1",
            "--num-envs",
            "4",
            "--steps-per-env",
            "4",
            "--eval-trials",
            "2",
            "--no-progress",
            "--out",
            str(run),
        ]
    )
    assert code == 0, stdout
    assert json.loads((run / "options.json").read_text())["action_type"] == "continuous"
    assert json.loads((run / "config.json").read_text())["train"]["discrete"] is False
    assert "rl_error_vertices" in json.loads((run / "evaluation.json").read_text())


@pytest.mark.parametrize("shared", [False, True], ids=["policy-per-candidate", "shared-policy"])
def test_run_end_to_end_on_a_tiny_budget(tmp_path, shared):
    out = tmp_path / "run"
    code, stdout, _ = invoke(
        [
            "run",
            "--contour",
            "fls-circle",
            "--resolution",
            "17",
            "--candidates",
            "2",
            "--rl-candidates",
            "2",
            "--iterations",
            "1",
            "--trials",
            "2",
            "--num-envs",
            "4",
            "--out",
            str(out),
            "--json",
            str(tmp_path / "r.json"),
        ]
        + (["--shared-policy"] if shared else ["--record"])
    )
    assert code == 0, stdout
    runs = ["rl"] if shared else ["rl/candidate-0", "rl/candidate-1"]
    names = ["plan.json", "results.json", "regions.png", "improvement.png", "pinch_candidates.png"]
    for name in names + [f"{r}/{f}" for r in runs for f in ("best.pt", "options.json", "learning_curve.png")]:
        assert (out / name).is_file(), name
    if not shared:
        entities = read_summary(out / "recording.rrd").entity_paths
        assert {f"/{m}/env_0/sheet" for m in ("none", "fixed", "analytic", "rl")} <= set(entities)
    report = json.loads((tmp_path / "r.json").read_text())
    row = report["rows"][0]
    plan = json.loads((out / "plan.json").read_text())
    assert row["fixed_pinch"] == pytest.approx(plan["chosen"]["pinch"])  # fixed at the planned pinch
    # RL for the best two candidates (by fixed tension), each cut in its best order; rl pinches the
    # candidate that validated best.
    feasible = sorted(
        (c for c in plan["pinch_candidates"] if c["feasible"]), key=lambda c: c["error_vertices"]
    )
    listed = report["candidates"]
    assert [c["pinch"] for c in listed] == [pytest.approx(c["point"]) for c in feasible[:2]]
    assert [c["order"] for c in listed] == [c["best_order"] for c in feasible[:2]]
    chosen = listed[report["chosen_candidate"]]
    assert chosen["rl_validation_error_vertices"] == min(c["rl_validation_error_vertices"] for c in listed)
    assert row["rl_pinch"] == pytest.approx(chosen["pinch"])
    options = json.loads((out / chosen["run"] / "options.json").read_text())
    if shared:
        assert len(options["candidates"]) == 2 and options["observe_pinch"]
        assert (out / "rl" / "candidates.json").is_file()
    else:
        assert options["pinch_point"] == pytest.approx(chosen["pinch"]) and not options["observe_pinch"]
        assert len(options["segments"]) == len(plan["segments"])
    assert {"none", "fixed", "analytic", "rl"} <= {line.split()[0] for line in stdout.splitlines() if line}


def test_run_with_a_quick_analytic_plan(tmp_path):
    """--policy analytic: no training; the analytic policy picks the candidate and pinches there."""
    code, stdout, _ = invoke(
        [
            "run",
            "--contour",
            "fls-circle",
            "--resolution",
            "13",
            "--candidates",
            "3",
            "--policy",
            "analytic",
            "--trials",
            "1",
            "--out",
            str(tmp_path / "run"),
            "--json",
            str(tmp_path / "r.json"),
            "--no-plots",
        ]
    )
    assert code == 0, stdout
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["policy"] == "analytic" and "rl_error_vertices" not in report["rows"][0]
    scores = [c["analytic_error_vertices"] for c in report["candidates"]]
    chosen = report["candidates"][report["chosen_candidate"]]
    assert chosen["analytic_error_vertices"] == min(scores)
    assert report["rows"][0]["analytic_pinch"] == pytest.approx(chosen["pinch"])
    assert not (tmp_path / "run" / "rl").exists()


def test_cli_defaults_are_the_library_defaults():
    """One set of defaults: every command's options show what the library uses (its presets)."""
    import inspect

    from agents.config import (
        EVALUATION_CANDIDATES,
        EVALUATION_TRIALS,
        GRAD_CONFIGS,
        RECIPE,
        VALIDATION_TRIALS,
        GradConfig,
        TrainConfig,
    )
    from agents.gradient import optimize_contour
    from agents.pipeline import evaluate_table
    from agents.rl import train_contour
    from warpcut.planning import ArmModel, plan_cut
    from warpcut.sim.config import ARM_LENGTH_MM, ARM_RADIUS_MM

    train = TrainConfig()
    library = {
        "noise": SimConfig().noise_std,
        "score": SimConfig().score,
        "resolution": SimConfig().resolution,
        "fixture": SimConfig().fixture,
        "arm_length": ArmModel().length_mm,
        "arm_radius": ArmModel().radius_mm,
        "num_envs": train.num_envs,
        "steps_per_env": train.num_steps_per_env,
        "stay_prior": train.stay_prior,
        "reward": "dense" if RECIPE["dense_reward"] else "sparse",
        "observe": "contour" if RECIPE["contour_features"] else "fiducials",
        "action_type": RECIPE["action_type"],
        "allow_z": RECIPE["allow_z"],
        "validation_trials": inspect.signature(train_contour).parameters["validation_trials"].default,
        "eval_trials": inspect.signature(train_contour).parameters["eval_trials"].default,
    }
    evaluate = inspect.signature(evaluate_table).parameters
    assert library["validation_trials"] == VALIDATION_TRIALS and library["eval_trials"] == EVALUATION_TRIALS
    assert library["arm_length"] == ARM_LENGTH_MM == float("inf") and library["arm_radius"] == ARM_RADIUS_MM
    assert library["noise"] > 0 and library["score"] == "path"
    seen = set()
    for name, command in main.commands.items():
        expected = dict(library)
        if name == "run":  # the budget's (agents.config.BUDGETS) and the recipe's, unless overridden
            del expected["num_envs"]
            expected["validation_trials"] = None
        if name in ("train", "evaluate"):  # the algorithm's (agents.config.batch_defaults), resolved later
            expected["iterations"] = expected["num_envs"] = None
        if name == "plan":
            planning = inspect.signature(plan_cut).parameters
            expected["tolerance"] = planning["tolerance_mm"].default
            expected["candidates"] = planning["num_candidates"].default
        if name == "evaluate":
            for key in ("trials", "candidates", "num_envs", "plan", "analytic_pinch", "iterations"):
                expected[key] = evaluate[key].default
            assert expected["candidates"] == EVALUATION_CANDIDATES
            expected["grad_iterations"] = None  # the estimator's (agents.config.GRAD_CONFIGS)
            expected["grad_feedback_phases"] = None
            expected["grad_estimator"] = evaluate["grad"].default.estimator
        if name == "train":
            expected["algo"] = train.algorithm
        if name == "robustness":
            from agents.robustness import robustness

            expected["trials"] = inspect.signature(robustness).parameters["trials"].default
        if name == "optimize":  # iterations and step: the estimator's (GRAD_CONFIGS), resolved later
            grad, es = GradConfig(), GRAD_CONFIGS["es"]
            optimize = inspect.signature(optimize_contour).parameters
            assert optimize["settings"].default == grad
            expected.update(iterations=None, learning_rate=None, estimator=grad.estimator)
            expected["episodes"] = grad.trials
            expected.update(population=es.es_population, population_episodes=es.es_trials)
            expected["sigma"] = es.es_sigma_mm
            expected.update(feedback_phases=None, randomize=None)  # the estimator's
            expected.update(trials=optimize["trials"].default, candidates=optimize["candidates"].default)
        for param in command.params:
            if param.name in expected:
                assert param.default == expected[param.name], (name, param.name)
                seen.add((name, param.name))
    for command in ("simulate", "train", "evaluate", "run"):
        assert {(command, "noise"), (command, "score")} <= seen, command
    assert {
        ("train", "stay_prior"),
        ("train", "iterations"),
        ("train", "algo"),
        ("evaluate", "trials"),
        ("evaluate", "grad_iterations"),
        ("evaluate", "grad_estimator"),
        ("optimize", "estimator"),
        ("optimize", "population"),
        ("optimize", "sigma"),
        ("optimize", "feedback_phases"),
        ("optimize", "iterations"),
        ("optimize", "episodes"),
        ("optimize", "learning_rate"),
        ("optimize", "trials"),
        ("plan", "tolerance"),
        ("robustness", "trials"),
        ("robustness", "noise"),
    } <= seen
    for command in ("plan", "evaluate", "run"):
        assert (command, "arm_length") in seen, command


def test_no_command_prints_the_help():
    code, stdout, _ = invoke([])
    assert code == 0 and stdout.startswith("Usage: ") and "evaluate" in stdout


def test_batch_defaults_are_ppos_and_apgs_own():
    from agents.config import APG_BATCH, TrainConfig, batch_defaults

    assert batch_defaults("ppo") == {"num_envs": TrainConfig.num_envs, "iterations": TrainConfig.iterations}
    assert batch_defaults("apg") == APG_BATCH and APG_BATCH["num_envs"] < TrainConfig.num_envs


def test_train_apg_runs_and_refuses_discrete_actions(tmp_path):
    """APG runs, on its own default batch (16 envs, not PPO's 256)."""
    run = tmp_path / "apg"
    args = ["train", "--contour", "circle-small", "--algo", "apg", "--iterations", "1"]
    code, stdout, _ = invoke(
        args + ["--eval-trials", "2", "--validation-trials", "2", "--no-progress", "--out", str(run)]
    )
    assert code == 0, stdout
    assert "(16 envs, 1 iterations" in stdout
    config = json.loads((run / "config.json").read_text())["train"]
    assert config["algorithm"] == "apg" and config["discrete"] is False and config["num_envs"] == 16
    assert json.loads((run / "options.json").read_text())["action_type"] == "continuous"
    code, _, stderr = invoke(args + ["--actions", "discrete", "--out", str(tmp_path / "other")])
    assert code == 2 and "--actions continuous" in stderr


def test_train_es_runs_with_its_recipe_and_refuses_a_population_that_does_not_fit(tmp_path):
    """es trains the neural policy with its recipe's learning rate and its own population (a plain MLP,
    without the feedback path, with its own σ and step); a resumed run keeps its own step sizes; a
    population that does not divide the envs is refused before anything is written."""
    from agents.config import ES_PLAIN_NETWORK, RECIPES

    run = tmp_path / "es"
    args = ["train", "--contour", "circle-small", "--algo", "es", "--iterations", "1", "--num-envs", "8"]
    code, stdout, _ = invoke(
        args
        + ["--es-population", "4", "--eval-trials", "2", "--validation-trials", "2", "--no-progress"]
        + ["--es-feedback-lr", "0.2", "--out", str(run)]
    )
    assert code == 0, stdout
    assert "(8 envs, 1 iterations" in stdout
    config = json.loads((run / "config.json").read_text())
    assert config["train"]["algorithm"] == "es" and config["train"]["discrete"] is False
    assert config["train"]["learning_rate"] == RECIPES["es"].train["learning_rate"]
    assert config["rsl_rl"]["es"]["population"] == 4
    assert config["rsl_rl"]["es"]["feedback_learning_rate"] == 0.2  # --es-feedback-lr
    assert config["train"]["actor_feedback"] is True  # the recipe's feedback path on the tracking error
    assert config["rsl_rl"]["actor"]["class_name"] == "agents.models:FeedbackMLPModel"
    # A policy that observes no tracking error trains the plain MLP, and a resume keeps the run's own actor.
    blind = tmp_path / "blind"
    common = ["--es-population", "4", "--eval-trials", "1", "--validation-trials", "0", "--no-progress"]
    code, stdout, _ = invoke(args + common + ["--observe", "fiducials", "--out", str(blind)])
    assert code == 0, stdout
    blind_train = json.loads((blind / "config.json").read_text())["train"]
    assert blind_train["actor_feedback"] is False
    assert {k: blind_train[k] for k in ES_PLAIN_NETWORK} == ES_PLAIN_NETWORK  # the plain MLP's own steps
    assert config["train"]["es_sigma"] != ES_PLAIN_NETWORK["es_sigma"]
    # An es run without the path (e.g. from before it) that observes the contour resumes without it.
    from agents.config import TrainConfig
    from agents.rl import train_contour
    from envs.options import PatternCutOptions

    plain = tmp_path / "plain"
    options = PatternCutOptions(contour="circle-small", action_type="continuous", contour_features=True)
    cfg = TrainConfig(num_envs=8, iterations=1, algorithm="es", discrete=False, es_population=4)
    train_contour(options, plain, cfg, eval_trials=1, validation_trials=0, progress=False)
    code, stdout, _ = invoke(["train", "--resume", str(plain), "--iterations", "2"] + common)
    assert code == 0, stdout
    assert json.loads((plain / "summary.json").read_text())["iterations"] == 2
    resumed = json.loads((plain / "config.json").read_text())["train"]
    assert resumed["actor_feedback"] is False
    assert resumed["es_sigma"] == cfg.es_sigma and resumed["learning_rate"] == cfg.learning_rate  # its own
    # A resumed run keeps its step sizes, whatever the defaults say now; another --es-sigma is refused.
    path = run / "config.json"
    trained = json.loads(path.read_text())
    trained["train"].update(es_feedback_sigma=0.3, es_feedback_learning_rate=0.05)
    path.write_text(json.dumps(trained))
    code, stdout, _ = invoke(["train", "--resume", str(run), "--iterations", "2", "--no-progress"])
    assert code == 0, stdout
    resumed = json.loads(path.read_text())["train"]
    assert (resumed["es_feedback_sigma"], resumed["es_feedback_learning_rate"]) == (0.3, 0.05)
    assert json.loads((run / "config.json").read_text())["rsl_rl"]["es"]["feedback_sigma"] == 0.3
    for flag in ("--es-sigma", "--es-feedback-sigma"):
        code, _, stderr = invoke(["train", "--resume", str(run), "--iterations", "3", flag, "0.02"])
        assert code == 2 and f"{flag}: the resumed run" in stderr
    code, _, stderr = invoke(args + ["--es-population", "6", "--out", str(tmp_path / "other")])
    assert code == 2 and "--es-population" in stderr and "e.g. --es-population 8" in stderr
    assert not (tmp_path / "other").exists()


def test_evaluate_trains_apg_on_its_own_default_batch(tmp_path):
    out = tmp_path / "run"
    args = [
        "evaluate",
        "--contours",
        "circle-small",
        "--methods",
        "none,rl",
        "--recipe",
        "apg",
        "--trials",
        "2",
    ]
    args += ["--iterations", "1", "--candidates", "2", "--no-plots", "--out", str(out)]
    code, stdout, _ = invoke(args)
    assert code == 0, stdout
    assert json.loads((out / "request.json").read_text())["arguments"]["num_envs"] == 16
    config = json.loads((out / "policies" / "circle-small" / "config.json").read_text())["train"]
    assert config["algorithm"] == "apg" and config["num_envs"] == 16


def test_evaluate_with_the_grad_column(tmp_path):
    out = tmp_path / "run"
    args = ["evaluate", "--contours", "circle-small", "--methods", "none,fixed,grad", "--trials", "2"]
    args += ["--grad-iterations", "1", "--candidates", "2", "--no-plots", "--out", str(out)]
    code, stdout, _ = invoke(args)
    assert code == 0, stdout
    table = json.loads((out / "results.json").read_text())
    row = table["rows"][0]
    assert "grad_improvement_pct" in row and row["grad_best_iteration"] in (0, 1)
    assert table["grad_initial_plan_contours"] in (0, 1)
    assert (out / "grad" / "circle-small.json").is_file()
    assert "grad kept its initial plan" in stdout


def test_run_refuses_a_shared_policy_on_grad_plans(tmp_path):
    args = ["run", "--contour", "circle-small", "--recipe", "grad-residual", "--shared-policy"]
    code, stdout, stderr = invoke(args + ["--out", str(tmp_path / "run")])
    assert code == 2 and "--shared-policy: a recipe on a base plan" in stderr and "Traceback" not in stdout
    assert not (tmp_path / "run").exists()
