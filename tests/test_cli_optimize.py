"""``warpcut optimize`` end to end (small sheets, a few iterations): its flags, its config file, ``--set`` and
``--print-config``, and its run directory (``config.json``, ``--resume``)."""

import dataclasses
import json

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from agents.cli import main
from agents.plan_optimizer.config import GRAD_CONFIGS

pytestmark = pytest.mark.usefixtures("one_torch_thread")

SMALL = ["--contour", "circle-small", "--trials", "2", "--set", "candidates=2", "--set", "sim.resolution=13"]
"""A small job: a 13 x 13 sheet, 2 pinch candidates, 2 evaluation trials."""
TAPE = [
    "--estimator",
    "tape",
    "--iterations",
    "2",
    "--set",
    "grad.trials=2",
    "--set",
    "grad.validation_trials=2",
]
"""A short tape optimisation."""


def invoke(args):
    """Run the CLI in-process and return (exit code, stdout, stderr)."""
    result = CliRunner().invoke(main, ["optimize", *args], standalone_mode=True, catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def test_optimize_writes_the_plan_its_evaluation_and_its_job(tmp_path):
    out, report_path = tmp_path / "run", tmp_path / "optimize.json"
    args = SMALL + TAPE + ["--device", "cpu", "--out", str(out)]
    code, stdout, stderr = invoke(args + ["--json", str(report_path)])
    assert code == 0, stderr
    report = json.loads(report_path.read_text())
    assert set(report["evaluation"]) == {"none", "fixed", "grad"} and report["trials"] == 2
    assert report["optimized"]["best_iteration"] in (0, 1, 2)
    assert len(report["optimized"]["plan"]) > 0 and (out / "circle-small.json").is_file()
    assert not (out / "circle-small.state.json").exists()  # finished: the state is gone, the plan kept
    assert json.loads((out / "results.json").read_text())["contour"] == "circle-small"
    job = json.loads((out / "config.json").read_text())
    assert job["grad"]["iterations"] == 2 and job["grad"]["trials"] == 2 and job["sim"]["resolution"] == 13
    assert job["candidates"] == 2 and job["contour"] == "circle-small"
    assert "grad" in stdout and "kept iteration" in stdout
    code, _, stderr = invoke(args)  # a finished run directory is not overwritten
    assert code != 0 and "--overwrite" in stderr


def test_optimize_by_evolution_strategies_takes_the_es_defaults(tmp_path):
    out = tmp_path / "run"
    args = SMALL + ["--estimator", "es", "--iterations", "2", "--set", "grad.validation_trials=2"]
    code, _, stderr = invoke(
        args + ["--set", "grad.es_population=4", "--out", str(out), "--json", str(out) + ".json"]
    )
    assert code == 0, stderr
    report = json.loads((tmp_path / "run.json").read_text())
    es = dataclasses.asdict(GRAD_CONFIGS["es"])
    expected = {**es, "iterations": 2, "es_population": 4, "validation_trials": 2}
    assert report["settings"] == expected  # the step is es's, not tape's
    assert report["optimized"]["env_steps"] == 2 * 4 * es["es_trials"] * len(report["optimized"]["plan"])
    assert json.loads((out / "circle-small.json").read_text())["settings"] == report["settings"]
    code, _, stderr = invoke(args + ["--set", "grad.es_population=3", "--out", str(tmp_path / "odd")])
    assert code == 2 and "grad.es_population: must be even" in stderr
    code, _, stderr = invoke(args + ["--set", "grad.optimize_pinch=true", "--out", str(tmp_path / "pinch")])
    assert code == 2 and "grad.optimize_pinch: the pinch point moves only with estimator 'tape'" in stderr
    assert not (tmp_path / "odd").exists() and not (tmp_path / "pinch").exists()  # refused before any work


def test_optimize_a_closed_loop_policy_under_randomisation(tmp_path):
    out = tmp_path / "run"
    args = SMALL + ["--estimator", "es", "--iterations", "1", "--set", "grad.es_population=2"]
    args += ["--set", "grad.validation_trials=1", "--set", "grad.es_feedback_phases=2"]
    ranged = [
        "--set",
        "grad.es_randomize=gravity,noise",
        "--set",
        "grad.es_randomize_ranges={noise: [0, 0.27]}",
    ]
    code, _, stderr = invoke(args + ranged + ["--set", "grad.es_feedback_sag=true", "--out", str(out)])
    assert code == 0, stderr
    plan = json.loads((out / "circle-small.json").read_text())
    assert np.asarray(plan["gains"]).shape == (2, 3, 4)  # scheduled on the sag: [e, s e]
    assert plan["settings"]["es_feedback_phases"] == 2 and plan["settings"]["es_randomize"] == "gravity,noise"
    assert plan["settings"]["es_feedback_sag"] is True
    assert plan["settings"]["es_randomize_ranges"] == {"noise_std": [0.0, 0.27]}
    code, _, stderr = invoke(
        args + ranged + ["--set", "grad.es_feedback_sag=true", "--out", str(out), "--resume"]
    )
    assert code == 0, stderr  # the saved settings read back equal
    bad = ["--set", "grad.es_randomize=gravity", "--set", "grad.es_randomize_ranges={noise: [0, 0.27]}"]
    code, _, stderr = invoke(args + bad + ["--out", str(tmp_path / "bad")])
    assert code == 2 and "grad.es_randomize_ranges: noise not randomised" in stderr
    code, _, stderr = invoke(
        ["--contour", "circle-small", "--estimator", "tape", "--set", "grad.es_feedback_phases=1"]
    )
    assert code == 2 and "grad.es_feedback_phases: only estimator 'es'" in stderr
    code, _, stderr = invoke(
        ["--contour", "circle-small", "--estimator", "es", "--set", "grad.es_feedback_sag=true"]
    )
    assert code == 2 and "grad.es_feedback_sag: there are no gains" in stderr


def test_a_range_set_by_its_own_key_is_kept():
    """A key inside a mapping field (grad.es_randomize_ranges.noise) is kept when the estimator's own
    defaults replace the rest of grad."""
    args = ["--contour", "circle-small", "--estimator", "es", "--set", "grad.es_randomize=noise"]
    code, stdout, stderr = invoke(
        args + ["--set", "grad.es_randomize_ranges.noise=[0,0.27]", "--print-config"]
    )
    assert code == 0, stderr
    assert yaml.safe_load(stdout)["grad"]["es_randomize_ranges"] == {"noise_std": [0.0, 0.27]}


def test_a_config_file_yaml_or_toml_sets_the_job_and_print_config_reads_back(tmp_path):
    """--config takes YAML and TOML; flags and --set override it; --print-config's YAML is a config file
    that gives the same job."""
    (tmp_path / "job.yaml").write_text(
        "contour: kidney\ntrials: 3\nsim:\n  noise_std: 0.0\n  resolution: 13\n"
        "grad:\n  estimator: es\n  es_population: 4\n  es_feedback_phases: 2\n"
    )
    (tmp_path / "job.toml").write_text(
        'contour = "kidney"\ntrials = 3\n[sim]\nnoise_std = 0.0\nresolution = 13\n'
        '[grad]\nestimator = "es"\nes_population = 4\nes_feedback_phases = 2\n'
    )
    printed = []
    for name in ("job.yaml", "job.toml"):
        code, stdout, stderr = invoke(["--config", str(tmp_path / name), "--print-config"])
        assert code == 0, stderr
        printed.append(stdout)
    assert printed[0] == printed[1]
    job = yaml.safe_load(printed[0])
    assert job["contour"] == "kidney" and job["trials"] == 3 and job["sim"]["noise_std"] == 0.0
    grad = job["grad"]
    assert grad["estimator"] == "es" and grad["es_population"] == 4 and grad["es_feedback_phases"] == 2
    assert grad["iterations"] == GRAD_CONFIGS["es"].iterations  # the estimator's own, not tape's
    assert grad["learning_rate"] == GRAD_CONFIGS["es"].learning_rate
    (tmp_path / "printed.yaml").write_text(printed[0])
    code, again, _ = invoke(["--config", str(tmp_path / "printed.yaml"), "--print-config"])
    assert code == 0 and again == printed[0]  # the round trip
    flags = ["--contour", "circle-small", "--iterations", "3", "--set", "grad.es_sigma_mm=0.5"]
    code, stdout, _ = invoke(["--config", str(tmp_path / "job.yaml"), *flags, "--print-config"])
    job = yaml.safe_load(stdout)
    assert job["contour"] == "circle-small" and job["grad"]["iterations"] == 3
    assert job["grad"]["es_sigma_mm"] == 0.5 and job["grad"]["es_population"] == 4  # the file's kept
    (tmp_path / "bad.yaml").write_text("grad:\n  population: 4\n")
    code, _, stderr = invoke(["--config", str(tmp_path / "bad.yaml"), "--contour", "kidney"])
    assert code == 2 and "grad.population: unknown setting" in stderr and "es_population" in stderr


def test_a_setting_the_estimator_does_not_read_is_refused(tmp_path):
    """es's settings with tape (and tape's with es) would be ignored: refused by name, whether given by --set
    or by a config file; a run directory's config.json, which holds them at their defaults, is not."""
    code, _, stderr = invoke(["--contour", "kidney", "--estimator", "tape", "--set", "grad.es_population=4"])
    assert code == 2 and "grad.es_population: read by estimator es only (--estimator es)" in stderr
    (tmp_path / "es.yaml").write_text("contour: kidney\ngrad:\n  estimator: tape\n  es_sigma_mm: 0.5\n")
    code, _, stderr = invoke(["--config", str(tmp_path / "es.yaml")])
    assert code == 2 and "grad.es_sigma_mm: read by estimator es only" in stderr
    code, _, stderr = invoke(["--contour", "kidney", "--estimator", "es", "--set", "grad.window=5"])
    assert code == 2 and "grad.window: read by estimator tape only (--estimator tape)" in stderr
    code, stdout, _ = invoke(["--contour", "kidney", "--print-config"])
    (tmp_path / "all.yaml").write_text(stdout)  # every key, those of tape at their defaults
    code, _, stderr = invoke(["--config", str(tmp_path / "all.yaml"), "--print-config"])
    assert code == 0, stderr


def test_a_run_directorys_config_runs_the_same_job_and_resume_keeps_its_settings(tmp_path):
    first, second = tmp_path / "first", tmp_path / "second"
    code, _, stderr = invoke(SMALL + TAPE + ["--pinch", "60,30", "--device", "cpu", "--out", str(first)])
    assert code == 0, stderr
    config = str(first / "config.json")
    code, _, stderr = invoke(["--config", config, "--device", "cpu", "--out", str(second)])
    assert code == 0, stderr
    a, b = (json.loads((run / "results.json").read_text()) for run in (first, second))
    assert a["pinch"] == b["pinch"] == [60.0, 30.0] and a["settings"] == b["settings"]
    assert a["optimized"]["plan"] == b["optimized"]["plan"] and a["evaluation"] == b["evaluation"]
    assert (first / "config.json").read_text() == (second / "config.json").read_text()
    code, _, stderr = invoke(["--config", config, "--trials", "3", "--out", str(first), "--resume"])
    assert (
        code == 2 and f"--resume: {first} was started with other settings (trials: 2 then, 3 now)" in stderr
    )
    code, _, stderr = invoke(
        ["--config", config, "--set", "grad.learning_rate=0.1", "--out", str(first), "--resume"]
    )
    assert code == 2 and "grad.learning_rate: 0.3 then, 0.1 now" in stderr
    code, stdout, stderr = invoke(["--config", config, "--device", "cpu", "--out", str(first), "--resume"])
    assert code == 0 and "optimising" not in stderr, stderr  # the finished plan is kept
    assert json.loads((first / "results.json").read_text())["optimized"] == a["optimized"]
