"""End-to-end tests of the ``warpcut`` command line (fast ones; one runs the installed console script)."""

import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest
import yaml
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
        (
            ["train", "--contour", "circle-small", "--contour", "wave-1"],
            "--contour: given twice; give it once",
        ),
        (["run", "--seed", "1", "--seed", "2"], "--seed: given twice; give it once"),
        (["evaluate", "--trials", "2", "--trials", "3"], "--trials: given twice; give it once"),
        (["run", "--set", "seed=1", "--set", "seed=2"], "--set seed: given twice; give it once"),
        (["run", "--seed", "1", "--set", "seed=2"], "--seed and --set seed: both set seed; give one"),
        (["run", "--set", "nope=1"], "--set: nope: unknown setting; the top level has .*budget"),
        (
            ["train", "--set", "train.es.nope=1"],
            "--set: train.es.nope: unknown setting; train.es has .*sigma",
        ),
        (["evaluate", "--set", "trials=many"], r"--set: trials: expected an integer \(got 'many'\)"),
        (
            ["train", "--set", "env.allow_z=maybe"],
            r"--set: env.allow_z: expected true or false \(got 'maybe'\)",
        ),
        (["run", "--set", "sim"], "--set: expected KEY=VALUE"),
        (["run", "--set", "sim=1"], r"--set: sim: is a section; set its fields, e.g. sim.FIELD=VALUE"),
        (
            ["evaluate", "--config", "no-such.yaml"],
            r"--config: no-such.yaml: no such file, nor a preset \(paper",
        ),
        (["train", "--algo", "magic"], "Invalid value for '--algo'"),
        (["train", "--print-config"], "contour: give the contour to train on"),
        (["evaluate", "--markdown", "t.md"], "No such option '--markdown'"),
        (["run", "--recipe", "paper"], "No such option '--recipe'"),
        (["run", "--shared-policy"], "No such option '--shared-policy'"),
        (["run", "--trials", "3"], "--trials: 'run' has no such option; it is a setting: --set trials=VALUE"),
        (["run", "--num-envs", "8"], "'run' has no such option; it is a setting: --set train.num_envs=VALUE"),
        (["run", "--set", "budget=huge"], "budget: choose one of fast, paper"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(args, message, capfd, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a command that went ahead would write its default run directory here
    with pytest.raises(SystemExit) as exit_info:
        main.main(args=args, prog_name="warpcut")
    assert exit_info.value.code == 2
    err = capfd.readouterr().err.strip().splitlines()
    err = [line for line in err if not line.startswith("Warp CUDA warning")]
    assert len(err) == 1, err
    assert err[0].startswith("error: ")
    assert re.search(message, err[0]), err[0]
    assert not list(tmp_path.iterdir())


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


SMALL = ["--set", "sim.resolution=13"]
"""A 13 x 13 sheet: the commands' fast runs."""
TINY_ES = ["--set", "train.algo=es", "--set", "train.iterations=2", "--set", "train.num_envs=8",
           "--set", "train.es.population=4",
           "--set", "train.validation_trials=2"]  # fmt: skip
"""es for 2 iterations on 8 envs (4 perturbed policies), validated on 2 episodes."""


def test_train_resume_export_and_evaluate_with_checkpoints(tmp_path):
    import gymnasium as gym

    import warpcut.gym  # noqa: F401
    from envs.options import PatternCutOptions
    from envs.pattern_cut import PatternCutEnv

    run = tmp_path / "runs" / "circle-small"
    args = [
        "train",
        "--contour",
        "circle-small",
        "--algo",
        "es",
        "--iterations",
        "2",
        "--num-envs",
        "8",
        *SMALL,
    ]
    args += ["--set", "train.es.population=4", "--set", "train.validation_trials=2", "--set", "eval_trials=2"]
    code, stdout, _ = invoke([*args, "--no-progress", "--out", str(run), "--record"])
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
    assert not (run / "request.json").exists()
    # The final evaluation is recorded: the trained policy and no tension, each in its own tree.
    entities = read_summary(run / "recording.rrd").entity_paths
    assert "/rl/env_0/sheet" in entities and "/none/env_0/sheet" in entities
    assert "/rl/env_1/sheet" not in entities
    assert any(p.name.startswith("events.out.tfevents") for p in run.iterdir())
    summary = json.loads((run / "summary.json").read_text())
    assert summary["iterations"] == 2 and summary["algo"] == "es"
    # The env's defaults are the default learner's: the registered env observes and acts as the policy.
    options = json.loads((run / "options.json").read_text())
    assert options["action_type"] == "continuous" and options["contour_features"] and options["allow_z"]
    trained_env = PatternCutEnv(options=PatternCutOptions.from_dict({**options, "device": "cpu"}))
    env = gym.make("warpcut/PatternCut-v0", contour="fls-circle", device="cpu")
    assert env.observation_space.shape == (47,) == trained_env.observation_space.shape
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (3,), np.float32) == trained_env.action_space

    code, stdout, _ = invoke(["train", "--resume", str(run), "--iterations", "3", "--no-progress"])
    assert code == 0, stdout
    assert json.loads((run / "summary.json").read_text())["iterations"] == 3
    assert (run / "model_2.pt").is_file()
    # The run directory's config.json, given back, is the same job.
    code, stdout, _ = invoke(["train", "--config", str(run / "config.json"), "--print-config"])
    assert code == 0 and yaml.safe_load(stdout) == json.loads((run / "config.json").read_text())

    code, stdout, _ = invoke(["export", str(run)])
    assert (
        code == 0
        and (run / "exported" / "policy.pt").is_file()
        and (run / "exported" / "policy.onnx").is_file()
    )

    out = tmp_path / "table.json"
    code, stdout, _ = invoke(
        ["evaluate", "--contours", "circle-small", "--methods", "none,analytic,rl", "--trials", "2",
         "--checkpoints", str(tmp_path / "runs"), "--set", "plan=false", *SMALL,
         "--out", str(tmp_path / "eval"), "--json", str(out)]
    )  # fmt: skip
    assert code == 0, stdout
    report = json.loads(out.read_text())
    assert report["rows"][0]["contour"] == "circle-small"
    assert {"rl_improvement_pct", "rl_ci95", "analytic_improvement_pct", "none_error_vertices"} <= set(
        report["rows"][0]
    )
    assert "rl_improvement_pct" in report["mean"]
    assert "| **mean** |" in (tmp_path / "eval" / "results.md").read_text()  # always written
    svg = (tmp_path / "eval" / "regions" / "circle-small.svg").read_text()  # rl's cut shown beside the rest
    assert all(f"{m}: " in svg for m in ("none", "analytic", "rl"))


def test_evaluate_two_contours_two_trials_writes_table_json(tmp_path):
    out = tmp_path / "results.json"
    code, stdout, _ = invoke(
        [
            "evaluate",
            "--contours",
            "fls-circle,s-curve",
            "--methods",
            "none,fixed,analytic",
            "--trials",
            "2",
            "--set",
            "sim.noise_std=0.02",
            "--set",
            "candidates=3",
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
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["sim"]["noise_std"] == 0.02 and config["candidates"] == 3 and config["trials"] == 2
    for name in ("improvement.png", "plans/fls-circle.png", "plans/s-curve.svg", "results.md"):
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
        ["evaluate", "--contours", "fls-circle,s-curve", "--methods", "none", "--trials", "1",
         "--set", "plan=false", "--set", "plots=false", "--set", "record=3", *SMALL, "--out", str(out)]
    )  # fmt: skip
    assert code == 0, stdout
    assert stderr.count("warning: record 3") == 1 and "recording 1" in stderr, stderr
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


def test_train_ppo_trains_discrete_moves_unless_told(tmp_path):
    """``--algo ppo`` trains PPO's own discrete moves; ``--set env.action_type=continuous`` keeps PPO on
    continuous ones."""
    run = tmp_path / "cont"
    args = [
        "train",
        "--contour",
        "circle-small",
        "--algo",
        "ppo",
        "--iterations",
        "1",
        "--num-envs",
        "4",
        *SMALL,
    ]
    args += [
        "--set",
        "train.ppo.num_steps_per_env=4",
        "--set",
        "eval_trials=2",
        "--set",
        "train.validation_trials=2",
    ]
    code, stdout, _ = invoke([*args, "--print-config"])
    assert code == 0 and yaml.safe_load(stdout)["env"]["action_type"] == "discrete"
    code, stdout, _ = invoke(
        [*args, "--set", "env.action_type=continuous", "--no-progress", "--out", str(run)]
    )
    assert code == 0, stdout
    assert json.loads((run / "options.json").read_text())["action_type"] == "continuous"
    config = json.loads((run / "config.json").read_text())
    assert config["train"]["algo"] == "ppo" and config["env"]["action_type"] == "continuous"
    assert "rl_error_vertices" in json.loads((run / "evaluation.json").read_text())


def test_run_end_to_end_on_a_tiny_budget(tmp_path):
    out = tmp_path / "run"
    code, stdout, _ = invoke(
        ["run", "--contour", "fls-circle", *SMALL, "--set", "candidates=2", "--set", "rl_candidates=2",
         "--set", "trials=2", *TINY_ES, "--out", str(out), "--json", str(tmp_path / "r.json"), "--record"]
    )  # fmt: skip
    assert code == 0, stdout
    runs = ["rl/candidate-0", "rl/candidate-1"]
    names = [
        "config.json",
        "plan.json",
        "results.json",
        "regions.png",
        "improvement.png",
        "pinch_candidates.png",
    ]
    for name in names + [f"{r}/{f}" for r in runs for f in ("best.pt", "options.json", "learning_curve.png")]:
        assert (out / name).is_file(), name
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
    assert options["pinch_point"] == pytest.approx(chosen["pinch"])
    assert len(options["segments"]) == len(plan["segments"])
    assert {"none", "fixed", "analytic", "rl"} <= {line.split()[0] for line in stdout.splitlines() if line}
    # The run directory's config.json is the job: given back, the same job.
    config = json.loads((out / "config.json").read_text())
    assert config["candidates"] == 2 and config["train"]["es"]["population"] == 4
    code, stdout, _ = invoke(["run", "--config", str(out / "config.json"), "--print-config"])
    assert code == 0 and yaml.safe_load(stdout) == config


def test_run_with_a_quick_analytic_plan(tmp_path):
    """--policy analytic: no training; the analytic policy picks the candidate and pinches there."""
    code, stdout, _ = invoke(
        ["run", "--contour", "fls-circle", *SMALL, "--set", "candidates=3", "--policy", "analytic",
         "--set", "trials=1", "--out", str(tmp_path / "run"), "--json", str(tmp_path / "r.json"),
         "--set", "plots=false"]
    )  # fmt: skip
    assert code == 0, stdout
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["policy"] == "analytic" and "rl_error_vertices" not in report["rows"][0]
    scores = [c["analytic_error_vertices"] for c in report["candidates"]]
    chosen = report["candidates"][report["chosen_candidate"]]
    assert chosen["analytic_error_vertices"] == min(scores)
    assert report["rows"][0]["analytic_pinch"] == pytest.approx(chosen["pinch"])
    assert not (tmp_path / "run" / "rl").exists() and not list((tmp_path / "run").glob("*.png"))


def test_cli_defaults_are_the_library_defaults():
    """One home for every default: a flag of train, run or evaluate shows the default of its key in the job
    (agents.jobs), and the jobs' sections are the library's own (SimConfig, EnvConfig, TrainConfig,
    GradConfig), whose env defaults are the default learner's."""
    from agents.algorithms import DEFAULT_ALGORITHM, algorithm
    from agents.cli import evaluate, run, train
    from agents.cli.options import setting_keys
    from agents.config import EVALUATION_CANDIDATES, EVALUATION_TRIALS, VALIDATION_TRIALS, TrainConfig
    from agents.config_io import flatten, to_plain
    from agents.jobs import EvaluateJob, RunJob, TrainJob
    from agents.plan_optimizer.config import GRAD_CONFIG
    from envs.options import EnvConfig, PatternCutOptions

    seen = set()
    for module, job_class in ((train, TrainJob), (run, RunJob), (evaluate, EvaluateJob)):
        plain = flatten(to_plain(job_class()))
        for param in module.command.params:
            key = setting_keys(module.command).get(param.name)
            if key is None or param.default is None:
                continue
            default = param.default.split(",") if isinstance(plain[key], list) else param.default
            assert default == plain[key], (module.command.name, param.name)
            seen.add((module.command.name, param.name))
    assert {
        ("train", "algo"),
        ("train", "seed"),
        ("run", "contour"),
        ("run", "budget"),
        ("run", "run_policy"),
        ("run", "algo"),
        ("evaluate", "contours"),
        ("evaluate", "methods"),
        ("evaluate", "trials"),
        ("evaluate", "algo"),
    } <= seen
    for job in (TrainJob(), RunJob(), EvaluateJob()):
        assert job.sim == SimConfig() and job.env == EnvConfig() and job.train == TrainConfig()
    assert (
        EvaluateJob().grad == GRAD_CONFIG
        and EvaluateJob().trials == TrainJob().eval_trials == EVALUATION_TRIALS
    )
    assert (
        EvaluateJob().candidates == EVALUATION_CANDIDATES
        and TrainConfig().validation_trials == VALIDATION_TRIALS
    )
    assert (
        TrainConfig().algo == DEFAULT_ALGORITHM
        and EnvConfig().action_type == algorithm(DEFAULT_ALGORITHM).action_type
    )
    env_defaults = {
        name: getattr(EnvConfig(), name) for name in ("contour_features", "action_type", "allow_z")
    }
    assert {name: getattr(PatternCutOptions(), name) for name in env_defaults} == env_defaults


def test_no_command_prints_the_help():
    code, stdout, _ = invoke([])
    assert code == 0 and stdout.startswith("Usage: ") and "evaluate" in stdout


def test_each_learner_trains_on_its_own_default_batch():
    from agents.algorithms import ALGORITHMS
    from agents.config import TrainConfig

    for name, entry in ALGORITHMS.items():
        assert TrainConfig(algo=name).batch_size == entry.num_envs
    assert TrainConfig(algo="apg").batch_size < TrainConfig(algo="ppo").batch_size
    assert TrainConfig(algo="apg", num_envs=3).batch_size == 3
    assert TrainConfig(algo="apg").total_iterations(100) == ALGORITHMS["apg"].iterations
    assert TrainConfig(algo="ppo", iterations=5).total_iterations(100) == 5


def test_train_apg_runs_and_refuses_discrete_actions(tmp_path):
    """APG runs, on its own default batch (16 envs, not es's or PPO's 256)."""
    run = tmp_path / "apg"
    args = ["train", "--contour", "circle-small", "--algo", "apg", "--iterations", "1", *SMALL]
    code, stdout, _ = invoke(
        [
            *args,
            "--set",
            "eval_trials=2",
            "--set",
            "train.validation_trials=2",
            "--no-progress",
            "--out",
            str(run),
        ]
    )
    assert code == 0, stdout
    config = json.loads((run / "config.json").read_text())["train"]
    assert config["algo"] == "apg" and config["num_envs"] is None  # the learner's
    summary = json.loads((run / "summary.json").read_text())
    steps = json.loads((run / "options.json").read_text())
    assert summary["algo"] == "apg" and summary["iterations"] == 1
    assert summary["env_steps"] % 16 == 0 and summary["env_steps"] // 16 > 16  # 16 envs, one whole cut each
    assert steps["action_type"] == "continuous"
    code, _, stderr = invoke([*args, "--set", "env.action_type=discrete", "--out", str(tmp_path / "other")])
    assert code == 2 and "algo: apg plays continuous moves; set env.action_type=continuous" in stderr
    assert not (tmp_path / "other").exists()


def test_train_es_trains_its_feedback_path_and_refuses_a_population_that_does_not_fit(tmp_path):
    """es, the default learner, trains the policy MLP with a linear feedback path on the tracking error with
    its own settings (``train.es.*``); a policy that observes no tracking error trains without the path when
    told, and is refused before anything is written otherwise; so is a population that does not divide the
    envs."""
    from agents.checkpoints import read_checkpoint

    run = tmp_path / "es"
    args = ["train", "--contour", "circle-small", "--iterations", "1", "--num-envs", "8", *SMALL]
    args += [
        "--set",
        "eval_trials=1",
        "--set",
        "train.validation_trials=0",
        "--no-progress",
        "--set",
        "plots=false",
    ]
    four = ["--set", "train.algo=es", "--set", "train.es.population=4"]
    code, stdout, _ = invoke(
        [*args, *four, "--set", "train.es.feedback_learning_rate=0.2", "--out", str(run)]
    )
    assert code == 0, stdout
    config = json.loads((run / "config.json").read_text())["train"]
    assert config["algo"] == "es" and config["es"]["population"] == 4
    assert config["es"]["feedback_learning_rate"] == 0.2
    policy = read_checkpoint(run / "latest.pt")["policy"]
    assert policy["actor"]["class_name"] == "agents.models:FeedbackMLPModel"
    assert policy["num_action_choices"] is None and policy["obs_shapes"]["policy"] == [47]
    blind = [*four, "--set", "env.contour_features=false"]
    code, _, stderr = invoke([*args, *blind, "--out", str(tmp_path / "refused")])
    assert code == 2 and "train.es.feedback=false" in stderr and not (tmp_path / "refused").exists()
    code, stdout, _ = invoke(
        [*args, *blind, "--set", "train.es.feedback=false", "--out", str(tmp_path / "blind")]
    )
    assert code == 0, stdout
    policy = read_checkpoint(tmp_path / "blind" / "latest.pt")["policy"]
    assert policy["actor"]["class_name"] == "rsl_rl.models:MLPModel"
    assert policy["obs_shapes"]["policy"] == [40]  # the paper's observation: no contour features
    code, _, stderr = invoke(
        [*args, "--set", "train.algo=es", "--set", "train.es.population=6", "--out", str(tmp_path / "other")]
    )
    assert code == 2 and "es.population: 6 must divide num_envs (8)" in stderr
    assert "e.g. train.es.population=8" in stderr and not (tmp_path / "other").exists()


def test_evaluate_trains_apg_on_its_own_default_batch(tmp_path):
    out = tmp_path / "run"
    args = [
        "evaluate",
        "--contours",
        "circle-small",
        "--methods",
        "none,rl",
        "--algo",
        "apg",
        "--trials",
        "2",
    ]
    args += ["--set", "train.iterations=1", "--set", "candidates=2", *SMALL, "--set", "plots=false"]
    code, stdout, _ = invoke([*args, "--out", str(out)])
    assert code == 0, stdout
    config = json.loads((out / "config.json").read_text())["train"]
    assert config["algo"] == "apg" and config["num_envs"] is None
    policy = json.loads((out / "policies" / "circle-small" / "config.json").read_text())["train"]
    assert policy["algo"] == "apg" and policy["num_envs"] is None
    summary = json.loads((out / "policies" / "circle-small" / "summary.json").read_text())
    assert summary["algo"] == "apg" and summary["env_steps"] % 16 == 0


def test_evaluate_with_the_grad_column(tmp_path):
    out = tmp_path / "run"
    args = ["evaluate", "--contours", "circle-small", "--methods", "none,fixed,grad", "--trials", "2"]
    args += [
        "--set",
        "grad.iterations=1",
        "--set",
        "candidates=2",
        *SMALL,
        "--set",
        "plots=false",
        "--out",
        str(out),
    ]
    code, stdout, _ = invoke(args)
    assert code == 0, stdout
    table = json.loads((out / "results.json").read_text())
    row = table["rows"][0]
    assert "grad_improvement_pct" in row and row["grad_best_iteration"] in (0, 1)
    assert table["grad_initial_plan_contours"] in (0, 1)
    assert (out / "grad" / "circle-small.json").is_file()
    assert "grad kept its initial plan" in stdout


@pytest.mark.parametrize(
    "args",
    [
        ["train", "--contour", "circle-small", "--algo", "ppo", "--set", "env.randomize=[gravity,noise]"],
        [
            "run",
            "--contour",
            "wave-1",
            "--algo",
            "es",
            "--set",
            "sim.noise_std=0.01",
            "--set",
            "train.es.sigma=0.02",
        ],
        [
            "evaluate",
            "--contours",
            "fls-circle,wave-1",
            "--methods",
            "none,fixed,rl,grad",
            "--config",
            "paper",
        ],
    ],
    ids=["train", "run", "evaluate"],
)
def test_print_config_is_yaml_that_config_reads_back_to_the_same_job(args, tmp_path):
    """``--print-config`` prints the whole job as YAML; given back with ``--config`` it is the same job, and
    flags and ``--set`` override it."""
    code, stdout, _ = invoke([*args, "--print-config"])
    assert code == 0, stdout
    printed = yaml.safe_load(stdout)
    assert isinstance(printed, dict) and {"seed", "sim", "env", "train"} <= set(printed)
    path = tmp_path / "job.yaml"
    path.write_text(stdout)
    code, again, _ = invoke([args[0], "--config", str(path), "--print-config"])
    assert code == 0 and again == stdout
    code, seeded, _ = invoke(
        [args[0], "--config", str(path), "--seed", "7", "--set", "sim.dt=0.02", "--print-config"]
    )
    assert code == 0 and yaml.safe_load(seeded) == {
        **printed,
        "seed": 7,
        "sim": {**printed["sim"], "dt": 0.02},
    }
    (tmp_path / "job.json").write_text(json.dumps(printed))
    (tmp_path / "job.toml").write_text(f"seed = 3\n[sim]\ndt = {printed['sim']['dt']}\n")
    code, from_json, _ = invoke([args[0], "--config", str(tmp_path / "job.json"), "--print-config"])
    assert code == 0 and from_json == stdout
    code, from_toml, _ = invoke(
        [args[0], "--config", str(tmp_path / "job.toml"), *args[1:3], "--print-config"]
    )
    assert code == 0 and yaml.safe_load(from_toml)["seed"] == 3


def test_algo_ppo_makes_the_actions_discrete_unless_set():
    def env(*args):
        code, stdout, stderr = invoke(["train", "--contour", "circle-small", *args, "--print-config"])
        assert code == 0, stderr
        return yaml.safe_load(stdout)["env"]

    assert env()["action_type"] == "continuous" and env("--algo", "es")["action_type"] == "continuous"
    assert env("--algo", "ppo")["action_type"] == "discrete"
    assert env("--algo", "ppo", "--set", "env.action_type=continuous")["action_type"] == "continuous"
    assert env("--config", "paper") == {**env(), "contour_features": False, "action_type": "discrete",
                                        "allow_z": False, "dense_reward": False}  # fmt: skip
    for command in (["run"], ["evaluate"]):
        code, stdout, _ = invoke([*command, "--algo", "ppo", "--print-config"])
        assert code == 0 and yaml.safe_load(stdout)["env"]["action_type"] == "discrete"


def test_the_env_defaults_are_the_default_learners():
    """``gymnasium.make`` with only a contour builds the env the default ``warpcut train`` trains in: 47
    observations (the paper's 40 and the contour features) and 3 continuous moves."""
    import gymnasium as gym

    import warpcut.gym  # noqa: F401
    from envs.options import ENV_FIELDS

    env = gym.make("warpcut/PatternCut-v0", contour="fls-circle", device="cpu")
    assert env.observation_space.shape == (47,)
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
    code, stdout, _ = invoke(["train", "--contour", "fls-circle", "--print-config"])
    assert code == 0
    trained = yaml.safe_load(stdout)["env"]
    assert trained == {name: to_plain_value(getattr(env.unwrapped.options, name)) for name in ENV_FIELDS}


def to_plain_value(value):
    """An option's value as a job's YAML holds it."""
    from agents.config_io import to_plain

    return to_plain(value)


def test_set_reads_numbers_in_exponent_notation():
    code, stdout, stderr = invoke(["run", "--set", "sim.noise_std=1e-3", "--print-config"])
    assert code == 0, stderr
    assert yaml.safe_load(stdout)["sim"]["noise_std"] == 0.001


def test_a_seed_is_refused_where_its_noise_would_repeat_a_smaller_seeds(capfd):
    """The noise kernels key on the seed modulo 2^31 - 1: ``--seed 2147483647`` would replay ``--seed 0``'s
    noise bit for bit, and a seed near it would reach it with an offset (validation's); ``--set seed`` takes
    the range ``--seed`` takes."""
    from cli_runner import refused

    from agents.config import SEED_RANGE

    top, simulate = SEED_RANGE[1], ["simulate", "--contour", "circle-small"]
    for args in (["--seed", "2147483647"], ["--seed", str(top + 1)]):
        assert f"not in the range 0<=x<={top}" in refused([*simulate, *args], capfd)
    for value in (top + 1, 2_147_483_647):
        error = refused([*simulate, "--set", f"seed={value}"], capfd)
        assert error == f"error: --set: seed: an integer in [0, {top}] (got {value})"
    code, stdout, _ = invoke([*simulate, "--seed", str(top), "--print-config"])
    assert code == 0 and f"seed: {top}" in stdout


def test_a_setting_given_twice_in_one_file_or_value_is_refused(tmp_path, capfd):
    """YAML and JSON parsers keep the last of a key given twice without a word: a config that sets ``seed``
    twice is refused, naming it; a key merged in with ``<<:`` and then set is YAML's override, and kept."""
    from cli_runner import refused

    simulate = ["simulate", "--contour", "circle-small", "--print-config"]
    for name, text in [
        ("twice.yaml", "seed: 1\nsim:\n  dt: 0.016\nseed: 2\n"),
        ("twice.json", '{"seed": 1, "seed": 2}'),
    ]:
        (tmp_path / name).write_text(text)
        assert "(seed: given twice in one mapping; give it once)" in refused(
            [*simulate, "--config", str(tmp_path / name)], capfd
        )
    error = refused([*simulate, "--set", "sim={noise_std: 0.1, noise_std: 0.2}"], capfd)
    assert error == "error: --set sim: noise_std: given twice in one mapping; give it once"
    (tmp_path / "merged.yaml").write_text("sim:\n  <<: {noise_std: 0.02, dt: 0.016}\n  noise_std: 0.01\n")
    code, stdout, _ = invoke([*simulate, "--config", str(tmp_path / "merged.yaml")])
    assert code == 0 and yaml.safe_load(stdout)["sim"]["noise_std"] == 0.01


def test_advice_names_each_setting_as_the_command_gives_it(tmp_path, capfd):
    """A refusal's advice names only what the command has, in its form: plan's --resolution and
    --arm-radius (plan has no --pinch), train's --set sim.resolution=N and --pinch; a sheet too small to
    grasp is blamed, not the arm; from Python the settings are named as keys."""
    from cli_runner import refused

    from warpcut.contours import load_contour
    from warpcut.planning.feasibility import no_pinch_error

    error = refused(["plan", "--contour", "circle-small", "--resolution", "5"], capfd)
    assert error.endswith("use resolution 8 or finer (--resolution 8)"), error
    error = refused(["plan", "--contour", "fls-circle", "--arm-radius", "60"], capfd)
    assert "(--arm-radius R or --arm-length L)" in error and "pinch" not in error.split("arm.radius_mm")[1]
    error = refused(["train", "--contour", "fls-circle", "--set", "sim.resolution=5"], capfd)
    assert (
        "(--set sim.resolution=12), or pinch an infeasible point of your choosing (--pinch X,Y --set "
        in error
    )
    assert "--resolution" not in error
    contour = tmp_path / "small.json"
    contour.write_text('{"name": "t", "closed": true, "points": [[4, 4], [6, 4], [6, 6], [4, 6]]}')
    sheet = ["--set", "sim.width_mm=10", "--set", "sim.height_mm=10"]
    error = refused(["simulate", "--contour", str(contour), "--policy", "fixed", *sheet], capfd)
    assert error.startswith("error: sheet: 10 x 10 mm is too small to grasp") and "thinner arm" not in error
    assert "(--set sim.width_mm=W --set sim.height_mm=H)" in error
    message = str(no_pinch_error(load_contour("fls-circle"), SimConfig(resolution=5)))
    assert "(sim.resolution=12), or pinch an infeasible point of your choosing (pinch=X,Y " in message


REFUSED_BEFORE_TORCH = """
import sys
from agents.cli import main
try:
    main.main(args=sys.argv[1:], prog_name="warpcut")
except SystemExit as stop:
    print(stop.code, "torch" in sys.modules)
"""


@pytest.mark.parametrize(
    "args",
    [
        ["run", "--contour", "kidny"],
        ["run", "--set", "train.es.sigam=0.01"],
        ["evaluate", "--methods", "none,fixd"],
        ["train"],
        ["train", "--contour", "kidny"],
        ["optimize", "--contour", "kidny"],
        ["robustness", "--contour", "kidny"],
        ["generalist", "--contours", "kidny"],
        ["simulate", "--contour", "kidny"],
    ],
)
def test_a_mistyped_setting_is_refused_before_torch_loads(args, tmp_path):
    """Settings and names are checked before torch is imported (several seconds on a busy machine): a
    refusal comes as fast as a mistyped flag's."""
    done = subprocess.run(
        [sys.executable, "-c", REFUSED_BEFORE_TORCH, *args], capture_output=True, text=True, cwd=tmp_path
    )
    last = (done.stdout.strip().splitlines() or [""])[-1]  # after anything a library prints as it starts
    assert last.split() == ["2", "False"], (done.stdout, done.stderr[-500:])
