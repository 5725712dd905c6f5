"""``warpcut simulate``, ``plan`` and ``contours`` end to end: their flags, the config file, ``--set`` and
``--print-config`` of simulate's job, settings the invocation would ignore, options given twice."""

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from cli_runner import invoke, refused

from agents.cli import main
from agents.cli.options import setting_keys
from agents.config_io import to_plain
from agents.jobs import SimulateJob

SMALL = ["--set", "sim.resolution=9"]
"""A 9 x 9 sheet."""


def test_contours_lists_the_suite_and_writes_json(tmp_path):
    out = tmp_path / "contours.json"
    code, stdout, _ = invoke(["contours", "--json", str(out)])
    assert code == 0
    assert "fls-circle" in stdout and "closed" in stdout and "open" in stdout
    rows = json.loads(out.read_text())["contours"]
    assert len(rows) >= 18
    circle = next(r for r in rows if r["name"] == "fls-circle")
    assert circle["closed"] is True and circle["length_mm"] == pytest.approx(157.08, abs=0.1)


def test_simulate_writes_results_json(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "results.json"
    code, stdout, _ = invoke(
        ["simulate", "--contour", "fls-circle", "--policy", "none,fixed,analytic", "--pinch", "83,83"]
        + ["--set", "sim.resolution=13", "--trials", "2", "--set", "sim.noise_std=0.01", "--device", "cpu"]
        + ["--json", str(out)]
    )
    assert code == 0, stdout
    report = json.loads(out.read_text())
    assert report["contour"] == "fls-circle"
    assert set(report["results"]) == {"none", "fixed", "analytic"}
    for r in report["results"].values():
        assert {"error_vertices", "error_mm2", "improvement_pct"} <= set(r)
    assert report["results"]["none"]["improvement_pct"] == 0.0
    assert report["results"]["none"]["error_vertices"] > 0
    assert report["results"]["fixed"]["pinch"] == pytest.approx([83.0, 83.0])
    assert "improvement" in stdout and "analytic" in stdout and "13x13" in stdout
    # plots: on by default, in a run folder of their own (not beside the file the user named), said
    (figure,) = (tmp_path / "logs").glob("simulate-*/regions.png")
    assert str(figure.relative_to(tmp_path)) in stdout and not (tmp_path / "regions.png").exists()


def test_simulate_accepts_a_contour_file(tmp_path):
    path = tmp_path / "mine.json"
    path.write_text(
        json.dumps({"name": "mine", "closed": True, "points": [[70, 50], [50, 70], [30, 50], [50, 30]]})
    )
    code, stdout, _ = invoke(
        ["simulate", "--contour", str(path), "--policy", "none", *SMALL, "--set", "plots=false"]
    )
    assert code == 0 and "contour mine" in stdout


def test_simulate_has_at_most_15_options_and_its_flags_set_keys_of_its_job():
    command = main.commands["simulate"]
    assert len(command.params) <= 15  # click's --help is not among them
    names = {p.opts[0] for p in command.params}
    assert names == {
        *("--contour", "--policy", "--pinch", "--trials", "--seed", "--device", "--json", "--record"),
        "--out",
        *("--video", "--generalist", "--config", "--set", "--print-config"),
    }
    keys = set(to_plain(SimulateJob()))
    assert set(setting_keys(command).values()) <= keys
    for key in ("sim", "colour_by", "export_mesh", "plots", "policy", "pinch", "trials", "seed"):
        assert key in keys, key


def test_simulate_config_set_and_print_config_round_trip(tmp_path):
    """--print-config prints the job the flags, --set and a file resolve to; given back with --config it
    resolves to itself; a file's settings run as the flags and --set do."""
    args = ["simulate", "--contour", "circle-small", "--policy", "none,fixed", "--pinch", "74,31.5"]
    args += ["--trials", "2", "--seed", "3", "--set", "sim.noise_std=0.02", *SMALL, "--set", "plots=false"]
    code, printed, _ = invoke([*args, "--print-config"])
    assert code == 0, printed
    job = yaml.safe_load(printed)
    assert job["policy"] == ["none", "fixed"] and job["pinch"] == [74.0, 31.5] and job["trials"] == 2
    assert job["seed"] == 3 and job["sim"]["noise_std"] == 0.02 and job["sim"]["resolution"] == 9
    assert job["plots"] is False and job["record"] is None and job["export_mesh"] is None
    assert set(job) == set(to_plain(SimulateJob()))  # every key, each at its place
    config = tmp_path / "simulate.yaml"
    config.write_text(printed)
    code, again, _ = invoke(["simulate", "--config", str(config), "--print-config"])
    assert code == 0 and again == printed
    # The file's settings run as the flags do: the same report.
    code, _, _ = invoke([*args, "--json", str(tmp_path / "flags.json")])
    assert code == 0
    code, _, _ = invoke(["simulate", "--config", str(config), "--json", str(tmp_path / "file.json")])
    assert code == 0
    assert (tmp_path / "file.json").read_text() == (tmp_path / "flags.json").read_text()
    # A flag overrides the file; --set overrides the file; a flag and --set of one key are refused.
    code, printed, _ = invoke(["simulate", "--config", str(config), "--trials", "4", "--print-config"])
    assert code == 0 and yaml.safe_load(printed)["trials"] == 4
    code, printed, _ = invoke(
        ["simulate", "--config", str(config), "--set", "sim.score=separated", "--print-config"]
    )
    assert code == 0 and yaml.safe_load(printed)["sim"]["score"] == "separated"
    code, _, stderr = invoke(["simulate", "--config", str(config), "--trials", "4", "--set", "trials=5"])
    assert code == 2 and "--trials and --set trials: both set trials" in stderr
    # JSON and TOML files too, and the keys that only --set reaches.
    (tmp_path / "s.json").write_text(
        json.dumps({"contour": "circle-small", "policy": "none", "export_mesh": "m"})
    )
    code, printed, _ = invoke(["simulate", "--config", str(tmp_path / "s.json"), "--print-config"])
    assert (
        code == 0
        and yaml.safe_load(printed)["policy"] == ["none"]
        and yaml.safe_load(printed)["export_mesh"] == "m"
    )
    (tmp_path / "s.toml").write_text(
        'contour = "wave-1"\ncolour_by = "height"\nrecord = 2\n[sim]\nfixture = "rows"\n'
    )
    code, printed, _ = invoke(["simulate", "--config", str(tmp_path / "s.toml"), "--print-config"])
    loaded = yaml.safe_load(printed)
    assert (
        code == 0
        and loaded["sim"]["fixture"] == "rows"
        and (loaded["record"], loaded["colour_by"]) == (2, "height")
    )


def test_simulate_export_mesh_and_plots_are_keys(tmp_path):
    meshes = tmp_path / "meshes"
    code, stdout, _ = invoke(
        [
            "simulate",
            "--contour",
            "circle-small",
            "--policy",
            "none",
            *SMALL,
            "--set",
            f"export_mesh={meshes}",
        ]
        + ["--set", "plots=false", "--json", str(tmp_path / "r.json")]
    )
    assert code == 0, stdout
    assert [p.name.split("_")[0] for p in meshes.glob("*.glb")] == ["none"]
    assert not list(tmp_path.glob("*.png"))


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--policy", "none", "--pinch", "50,40"],
            r"pinch: only fixed, analytic and generalist pinch, and policy is none",
        ),
        (["--policy", "none", "--set", "pinch=[50,40]"], r"pinch: only fixed, analytic and generalist pinch"),
        (["--set", "colour_by=height"], r"colour_by: colours a recording, and record is off \(add --record"),
        (["--set", "record=null", "--set", "colour_by=height"], "colour_by: colours a recording"),
    ],
)
def test_simulate_refuses_a_setting_it_would_ignore(args, message, capfd):
    line = refused(["simulate", "--contour", "circle-small", *args], capfd)
    assert re.search(message, line) and line.endswith("drop it (see 'warpcut simulate --help')"), line


def test_the_ignored_setting_rule_reads_the_job_and_a_config_file(tmp_path, capfd):
    """The rule is the job's (``unused_keys``, from its own settings), checked against what is given: a file
    that sets the pinch for a policy without one is refused; a saved job, every key at its default where
    unused, runs again; the pinch or the colours apply where fixed or a recording are on."""
    unused = {"pinch", "allow_infeasible_pinch", "colour_by", "generalist"}
    assert SimulateJob(policy=["none"]).unused_keys().keys() == unused
    assert SimulateJob(policy=["analytic"], record=1, pinch=[83.0, 83.0]).unused_keys().keys() == {
        "generalist"
    }
    bad = tmp_path / "bad.yaml"
    bad.write_text("contour: circle-small\npolicy: [none]\npinch: [50, 40]\n")
    assert "pinch: only fixed, analytic and generalist pinch" in refused(
        ["simulate", "--config", str(bad)], capfd
    )
    saved = tmp_path / "saved.yaml"
    code, printed, _ = invoke(
        ["simulate", "--contour", "circle-small", "--policy", "none", *SMALL, "--print-config"]
    )
    assert code == 0 and "pinch: null" in printed and "colour_by: strain" in printed
    saved.write_text(printed)
    code, stdout, _ = invoke(["simulate", "--config", str(saved), "--set", "plots=false"])
    assert code == 0, stdout
    code, _, _ = invoke(["simulate", "--config", str(bad), "--policy", "fixed", "--print-config"])
    assert code == 0


@pytest.mark.parametrize(
    "args",
    [
        ["simulate", "--contour", "circle-small", "--trials", "2", "--trials", "3"],
        ["simulate", "--contour", "circle-small", "--contour", "wave-1"],
        ["simulate", "--contour", "circle-small", "--print-config", "--print-config"],
        ["plan", "--contour", "circle-small", "--candidates", "2", "--candidates", "3"],
        ["bench", "--repeats", "1", "--repeats", "2"],
        ["contours", "--json", "a.json", "--json", "b.json"],
        ["export", ".", "--out", "a", "--out", "b"],
        ["replay", "r.rrd", "--web", "--web"],
    ],
)
def test_an_option_given_twice_is_refused(args, capfd):
    flag = next(a for a in args if args.count(a) == 2)
    assert refused(args, capfd).startswith(f"error: {flag}: given twice; give it once")


def test_simulate_set_may_repeat_but_not_one_key(capfd):
    args = ["simulate", "--contour", "circle-small", "--set", "trials=2", "--set", "seed=1", "--print-config"]
    code, printed, _ = invoke(args)
    assert code == 0 and yaml.safe_load(printed)["seed"] == 1
    line = refused(["simulate", "--contour", "circle-small", "--set", "trials=2", "--set", "trials=3"], capfd)
    assert "--set trials: given twice" in line


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--contour", "no-such-shape"], "unknown contour 'no-such-shape'.*fls-circle"),
        (["--contour", "fls-circle", "--policy", "none,magic"], "policy.*unknown magic"),
        (["--contour", "fls-circle", "--pinch", "50"], "--pinch.*expected X,Y"),
        (["--contour", "fls-circle", "--pinch", "150,40", "--policy", "fixed"], "off the 100 x 100 mm sheet"),
        (["--contour", "fls-circle", "--trials", "0"], "--trials"),
        (["--contour", "fls-circle", "--set", "trials=0"], "trials: must be an integer >= 1"),
        (
            ["--contour", "fls-circle", "--set", "sim.resolution=2"],
            r"--set: sim\.resolution: an integer in \[5, 100\]",
        ),
        (
            ["--contour", "fls-circle", "--set", "sim.score=best"],
            r"--set: sim\.score: one of 'path', 'separated' \(got 'best'\)",
        ),
        (["--contour", "fls-circle", "--set", "colour_by=rainbow", "--record"], "colour_by: choose one of"),
        (["--contour", "fls-circle", "--set", "noise=0"], "--set: noise: unknown setting"),
        (["--contour", "fls-circle", "--set", "export_mesh=/dev/null/m"], r"export_mesh: cannot write"),
        (["--contour", "fls-circle", "--device", "tpu"], "device: unknown device 'tpu'"),
        ([], "contour: give the contour to cut \\(--contour\\)"),
        (["--contour", "fls-circle", "--record", "-1"], "--record: N must be a positive integer"),
        (["--contour", "fls-circle", "--record=-2"], r"--record: N must be a positive integer \(got -2"),
        (["--contour", "fls-circle", "-5"], "No such option '-5'"),
        (["--contour", "fls-circle", "--record", "2", "-7"], "No such option '-7'"),
        (["--contour", "fls-circle", "--seed", "-1"], "--seed.*-1 is not in the range 0<=x<="),
        (["--contour", "fls-circle", "--video", "0"], "--video"),
        (["--contour", "fls-circle", "--noise", "0"], "No such option '--noise'"),
        (
            ["--contour", "circle-small", "--policy", "none", *SMALL, "--json", "/dev/null/sub/results.json"],
            r"--json: cannot write /dev/null/sub/results.json \(/dev/null is not a directory\)",
        ),
    ],
)
def test_simulate_bad_arguments_exit_2_with_one_line(args, message, capfd):
    line = refused(["simulate", *args], capfd)
    assert re.search(message, line), line


def test_console_script_runs():
    script = shutil.which("warpcut", path=str(Path(sys.executable).parent)) or shutil.which("warpcut")
    assert script, "the warpcut console script is not installed (pip install -e .)"
    proc = subprocess.run(
        [script, "simulate", "--contour", "circle-small", "--policy", "none", *SMALL, "--set", "plots=false"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "circle-small" in proc.stdout and "Traceback" not in proc.stderr


def test_plan_prints_and_writes_the_plan_json(tmp_path):
    out = tmp_path / "plan.json"
    code, stdout, _ = invoke(
        ["plan", "--contour", "fls-circle", "--candidates", "4", "--arm-length", "15", "--resolution", "17"]
        + ["--json", str(out)]
    )
    assert code == 0, stdout
    assert "segment 0: notch (75.0, 50.0)" in stdout and "chosen: pinch" in stdout
    plan = json.loads(out.read_text())
    assert len(plan["segments"]) == 2 and sorted(plan["order"]) == [0, 1]
    assert {"points", "notch", "termination"} <= set(plan["segments"][0])
    assert all({"point", "feasible", "error_vertices"} <= set(c) for c in plan["pinch_candidates"])
    feasible = [c for c in plan["pinch_candidates"] if c["feasible"]]
    assert plan["chosen"]["error_vertices"] == min(c["error_vertices"] for c in feasible)


@pytest.mark.parametrize("name", ["plan", "bench", "export", "replay", "contours"])
def test_the_commands_without_a_job_keep_at_most_15_options(name):
    command = main.commands[name]
    assert len([p for p in command.params if p.opts[0].startswith("--")]) <= 15
    assert type(command).__name__ == "Command"  # an option given twice is refused


def test_an_improvement_over_no_error_is_said_to_mean_nothing(monkeypatch):
    """Where no tension's error is zero within float precision, simulate prints n/a and says why instead of
    an improvement of +45.2% over 0.0."""
    import agents.evaluation

    def row(error, improvement):
        return {"error_vertices": error, "error_mm2": error * 17.4, "improvement_pct": improvement,
                "ci95_pct": 0.0, "pinch": None, "pinch_feasible": True, "pinch_problem": None}  # fmt: skip

    report = {"results": {"none": row(3e-5, 0.0), "fixed": row(1.6e-5, float("nan"))}}
    monkeypatch.setattr(agents.evaluation, "compare_policies", lambda *args, **kwargs: report)
    code, stdout, _ = invoke(
        ["simulate", "--contour", "circle-small", "--policy", "fixed", "--set", "plots=false"]
    )
    assert code == 0 and "+45" not in stdout and "nan" not in stdout, stdout
    assert (
        "n/a" in stdout
        and "improvement n/a: no tension's error (3e-05 vertices) is zero within float" in stdout
    )
