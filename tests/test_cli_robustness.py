"""``warpcut robustness`` end to end (small sheets, two trials): its flags, its config file, ``--set`` and
``--print-config``, and its run directory (``config.json``, ``--resume``)."""

import json
import re

import pytest
import yaml
from click.testing import CliRunner

from agents.cli import main

pytestmark = pytest.mark.usefixtures("one_torch_thread")

RES = 13  # a coarse sheet: fast, and fine enough for the FLS circle
FORCE = ["--contour", "fls-circle", "--study", "force", "--set", "values=[0,521]", "--trials", "2"]
"""A small force study of the baselines on a 13 x 13 sheet."""


def invoke(args):
    """Run the CLI in-process and return (exit code, stdout, stderr)."""
    result = CliRunner().invoke(main, args, standalone_mode=True, catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def robustness(*args):
    return invoke(["robustness", *args])


@pytest.fixture
def in_tmp(tmp_path, monkeypatch):
    """The test's own directory as the working directory (relative paths in its config files)."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.mark.slow
def test_robustness_of_a_randomised_run_end_to_end(tmp_path):
    """``warpcut train`` with domain randomisation keeps it in the run; ``warpcut robustness --run`` sweeps
    the policy with the baselines and writes the report, the figure and its job, which runs again as is."""
    run = tmp_path / "run"
    code, _, err = invoke(
        ["train", "--contour", "fls-circle", "--set", "env.randomize=[gravity,noise_std]", "--set",
         "env.randomize_ranges={gravity: [200, 800]}", "--set", "env.relative_reward=true", "--iterations",
         "2", "--num-envs", "8", "--set", "train.algo=es",
         "--set", "train.es.population=4", "--set", "train.validation_trials=2",
         "--set", "eval_trials=2", "--set", f"sim.resolution={RES}", "--device", "cpu", "--out", str(run),
         "--no-progress", "--set", "plots=false"]
    )  # fmt: skip
    assert code == 0, err
    options = json.loads((run / "options.json").read_text())
    assert options["relative_reward"] is True and options["randomize"] == ["gravity", "noise_std"]
    assert options["randomize_ranges"]["gravity"] == [200, 800]
    path, out = tmp_path / "noise.json", tmp_path / "rob"
    args = ["--study", "noise", "--run", f"dr={run}", "--set", "values=[0,0.05]", "--trials", "2"]
    code, stdout, err = robustness(*args, "--device", "cpu", "--out", str(out), "--json", str(path))
    assert code == 0, err
    report = json.loads(path.read_text())
    assert report["study"] == "noise" and report["values"] == [0.0, 0.05]
    assert report["methods"] == ["fixed", "analytic", "dr"] and report["runs"] == {"dr": str(run)}
    assert len(report["dr"]["median"]) == 2 and "dr" in stdout
    assert (out / "robustness-noise.json").is_file() and (out / "robustness.png").is_file()
    # The first trial's noise is the same for every method: with no noise, every trial of a method is one.
    assert report["fixed"]["q25"][0] == report["fixed"]["q75"][0]
    job = json.loads((out / "config.json").read_text())
    assert job["runs"] == {"dr": str(run)} and job["study"] == ["noise"] and job["values"] == [0.0, 0.05]
    again = tmp_path / "again.json"
    code, _, err = robustness(
        "--config", str(out / "config.json"), "--out", str(tmp_path / "rob2"), "--json", str(again)
    )
    assert code == 0, err
    assert json.loads(again.read_text())["dr"] == report["dr"]
    code, _, err = robustness(*args, "--set", "sim.noise_std=0", "--out", str(tmp_path / "x"))
    assert code == 2 and "sim.noise_std: with --run the nominal sheet is the run's; drop it" in err


def test_robustness_names_what_is_wrong(tmp_path):
    for args, message in [
        (["--study", "noise"], r"contour: give the contour \(--contour\), or trained runs of it \(--run\)"),
        (
            ["--study", "wind", "--contour", "fls-circle"],
            "study: choose from resolution, noise, force or all",
        ),
        (["--contour", "fls-circle"], r"study: choose from .* \(got none\)"),
        (["--study", "noise", "--run", str(tmp_path)], "runs: .* is not one trained policy's run"),
        (
            ["--study", "noise,force", "--contour", "fls-circle", "--set", "values=[0]"],
            "values: give the values of one",
        ),
        (
            ["--study", "force", "--contour", "fls-circle", "--set", "values=[-1]"],
            "values: force -1.0: gravity",
        ),
        (["--study", "noise", "--contour", "fls-circle", "--methods", "none,rl"], "methods: unknown rl"),
        (
            ["--study", "noise", "--contour", "fls-circle", "--values", "0,1"],
            "--values: 'robustness' has no such option; it is a setting: --set values=VALUE",
        ),
        (["--study", "noise", "--contour", "fls-circle", "--set", "value=[0]"], "value: unknown setting"),
    ]:
        code, _, err = robustness(*args, "--out", str(tmp_path / "never"))
        assert code == 2 and err.startswith("error: ") and len(err.strip().splitlines()) == 1, (args, err)
        assert re.search(message, err), (args, err)
    assert not (tmp_path / "never").exists()  # refused before any work


def test_plan_labels_default_to_the_file_name():
    from agents.cli.robustness import _labelled_plans

    assert _labelled_plans(("a/fls-circle.json", "mine=b/fls-circle.json")) == {
        "fls-circle": "a/fls-circle.json",
        "mine": "b/fls-circle.json",
    }
    code, _, err = robustness(
        "--contour", "fls-circle", "--study", "noise", "--plan", "x.json", "--plan", "x.json"
    )
    assert code == 2 and "--plan" in err and "given twice" in err


def test_a_config_file_yaml_or_toml_sets_the_job_and_print_config_reads_back(in_tmp):
    (in_tmp / "job.yaml").write_text(
        "contour: kidney\nstudy: [noise, force]\nmethods: [none, grad]\ntrials: 3\n"
        "plans: {mine: kidney.json}\nsim:\n  resolution: 13\ngrad:\n  estimator: es\n  es_population: 4\n"
    )
    (in_tmp / "job.toml").write_text(
        'contour = "kidney"\nstudy = ["noise", "force"]\nmethods = ["none", "grad"]\ntrials = 3\n'
        '[plans]\nmine = "kidney.json"\n[sim]\nresolution = 13\n[grad]\nestimator = "es"\nes_population = 4\n'
    )
    plan = {"contour": "kidney", "pinch": [50.0, 50.0], "plan": [[0.0, 0.0, 0.0]], "best_iteration": 0}
    (in_tmp / "kidney.json").write_text(json.dumps({**plan, "history": [], "seconds": 0, "env_steps": 0}))
    printed = []
    for name in ("job.yaml", "job.toml"):
        code, stdout, err = robustness("--config", name, "--print-config")
        assert code == 0, err
        printed.append(stdout)
    assert printed[0] == printed[1]
    job = yaml.safe_load(printed[0])
    assert job["study"] == ["noise", "force"] and job["methods"] == ["none", "grad"] and job["trials"] == 3
    assert job["grad"]["estimator"] == "es" and job["grad"]["es_population"] == 4 and job["values"] is None
    assert job["grad"]["iterations"] == 40 and job["sim"]["resolution"] == 13  # es's own steps
    (in_tmp / "printed.yaml").write_text(printed[0])
    code, again, err = robustness("--config", str(in_tmp / "printed.yaml"), "--print-config")
    assert code == 0 and again == printed[0], err  # the round trip
    code, stdout, _ = robustness(
        "--config",
        str(in_tmp / "job.yaml"),
        "--study",
        "all",
        "--set",
        "grad.iterations=2",
        "--print-config",
    )
    job = yaml.safe_load(stdout)
    assert job["study"] == ["resolution", "noise", "force"] and job["grad"]["iterations"] == 2


def test_grad_settings_apply_only_with_the_grad_method(in_tmp):
    """grad.* with no grad method would be ignored: refused by name, whether by --set or a file; with grad in
    --methods they set its optimiser, and a run directory's config.json (grad at its defaults) runs again."""
    code, _, err = robustness(*FORCE, "--set", "grad.iterations=1")
    assert code == 2 and "grad.iterations: read by the grad method only (--methods ...,grad); drop it" in err
    (in_tmp / "grad.yaml").write_text("grad:\n  estimator: tape\n")
    code, _, err = robustness(*FORCE, "--config", "grad.yaml")
    assert code == 2 and re.search(r"grad.estimator(, grad\.\w+)*: read by the grad method only", err)
    grad = ["--methods", "none,grad", "--set", "grad.estimator=tape", "--set", "grad.iterations=1"]
    grad += ["--set", "grad.trials=2"]
    grad += ["--set", "grad.validation_trials=2", "--set", f"sim.resolution={RES}"]
    code, stdout, err = robustness(*FORCE, *grad, "--device", "cpu", "--out", "grad", "--json", "grad.json")
    assert code == 0, err
    report = json.loads((in_tmp / "grad.json").read_text())
    assert report["methods"] == ["grad"] and len(report["grad"]["median"]) == 2
    assert len(json.loads((in_tmp / "grad" / "grad" / "fls-circle.json").read_text())["history"]) == 2


def test_a_run_directorys_config_runs_the_same_job_and_resume_keeps_its_settings(in_tmp):
    args = [*FORCE, "--methods", "none,fixed", "--set", f"sim.resolution={RES}", "--set", "plots=false"]
    code, _, err = robustness(*args, "--device", "cpu", "--out", "first", "--json", "first.json")
    assert code == 0, err
    assert not (in_tmp / "first" / "robustness.png").exists()  # plots=false
    code, _, err = robustness(
        "--config", "first/config.json", "--device", "cpu", "--out", "second", "--json", "second.json"
    )
    assert code == 0, err
    first, second = (json.loads((in_tmp / f"{name}.json").read_text()) for name in ("first", "second"))
    assert first["fixed"] == second["fixed"] and first["none_error_mm2"] == second["none_error_mm2"]
    assert (in_tmp / "first" / "config.json").read_text() == (in_tmp / "second" / "config.json").read_text()
    code, _, err = robustness("--config", "first/config.json", "--trials", "3", "--out", "first", "--resume")
    assert code == 2 and "--resume: first was started with other settings (trials: 2 then, 3 now)" in err
    code, _, err = robustness(
        "--config", "first/config.json", "--set", "sim.gravity=400", "--out", "first", "--resume"
    )
    assert code == 2 and "sim.gravity: 521.0 then, 400.0 now" in err
    code, _, err = robustness(
        "--config", "first/config.json", "--device", "cpu", "--out", "first", "--resume"
    )
    assert code == 0 and "force: kept" in err, err  # the finished study is read back
