"""Nothing a user made is lost. Run directories (claimed, locked, resumed), file names derived from
contour names, outputs that would overwrite inputs, recordings cut short, and SIGTERM/SIGHUP."""

import dataclasses
import errno
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import agents.training
from agents.cli import main
from agents.config import TrainConfig
from agents.config_io import to_plain
from agents.es.config import EsConfig
from agents.jobs import EvaluateJob, RunJob, TrainJob
from agents.pipelines import evaluate_table, run_pipeline
from agents.pipelines.common import TrainingInterrupted
from warpcut.io import RUN_MARKER, claim_run_dir, read_run_marker, safe_name, write_json
from warpcut.sim.config import SimConfig
from warpcut.viz.process import RecordingError, place_file

SMALL = SimConfig(resolution=13)
ROOT = Path(__file__).resolve().parents[1]
TINY = TrainConfig(algo="es", num_envs=4, iterations=2, validation_trials=0, es=EsConfig(population=4))
"""es on 4 envs for 2 iterations (one whole cut each), no validation: a policy in a few seconds."""
TINY_FLAGS = ["--set", "train.num_envs=4", "--set", "train.algo=es", "--set", "train.es.population=4",
              "--set", "sim.resolution=13"]  # fmt: skip


def invoke(args):
    result = CliRunner().invoke(main, args, standalone_mode=True, catch_exceptions=False)
    return result.exit_code, result.output


def contour_file(path: Path, name: str) -> Path:
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    points = np.stack([50 + 20 * np.cos(t), 50 + 20 * np.sin(t)], axis=1)
    path.write_text(json.dumps({"name": name, "closed": True, "points": points.tolist()}))
    return path


def test_safe_names_stay_in_their_directory_and_never_collide():
    assert safe_name("fls-circle") == "fls-circle"
    names = ["/tmp/victim", "../../x", "..", ".", "", "a b", "a/b", "a?b", "-rf", "x" * 200, "é"]
    made = [safe_name(n) for n in names]
    assert len(set(made)) == len(made)
    for name in made:
        assert "/" not in name and name not in (".", "..") and not name.startswith((".", "-"))
        assert 0 < len(name) <= 64


def test_a_contour_name_never_becomes_a_path_outside_the_run(tmp_path):
    """A contour named like a path (`/tmp/victim`, `../../x`) writes its policy, plan and plots inside the run
    directory under a safe name."""
    victim = tmp_path / "victim"
    escaped = tmp_path / "x"
    files = [
        contour_file(tmp_path / "a.json", str(victim)),
        contour_file(tmp_path / "b.json", "../../x"),
    ]
    out = tmp_path / "runs" / "deep" / "out"
    code, output = invoke(
        ["evaluate", "--contours", ",".join(map(str, files)), "--methods", "none,fixed", "--trials", "1",
         "--set", "candidates=2", "--set", "sim.resolution=13", "--out", str(out)]
    )  # fmt: skip
    assert code == 0, output
    assert not victim.exists() and not list(tmp_path.glob("victim*")) and not escaped.exists()
    written = {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()}
    assert (
        f"regions/{safe_name(str(victim))}.png" in written and f"plans/{safe_name('../../x')}.png" in written
    )
    assert all(".." not in p for p in written)


def test_two_contours_with_one_name_are_refused(tmp_path):
    files = [contour_file(tmp_path / "a.json", "same"), contour_file(tmp_path / "b.json", "same")]
    with pytest.raises(ValueError, match="both named 'same'"):
        evaluate_table(
            EvaluateJob(contours=[str(f) for f in files], methods=["none"], trials=1, sim=SMALL),
            tmp_path / "out",
        )


def test_an_existing_run_is_refused_unless_resumed_or_overwritten(tmp_path):
    out = tmp_path / "run"
    args = ["evaluate", "--contours", "circle-small", "--methods", "none,fixed", "--trials", "1",
            "--set", "candidates=2", "--set", "plots=false", "--out", str(out)]  # fmt: skip
    assert invoke(args)[0] == 0
    before = (out / "results.json").read_bytes()
    code, output = invoke(args)
    assert code == 2 and "holds a run of 'warpcut evaluate'" in output and "--resume" in output
    assert "--overwrite" in output and (out / "results.json").read_bytes() == before
    (out / "notes.txt").write_text("the user's, written into the run directory")
    unfinished = out / ".results.json.abcd1234.warpcut.tmp"  # warpcut's own form of a temporary file
    unfinished.write_text("a write the run never finished")
    code, output = invoke([*args, "--overwrite"])
    assert code == 0, output
    assert "--overwrite: deleted" in output and "kept what warpcut did not write: notes.txt" in output
    assert (out / "notes.txt").is_file() and (out / "results.json").is_file()
    assert not list(out.glob(".results.json.*.tmp"))
    code, output = invoke([*args, "--resume", "--overwrite"])
    assert code == 2 and "give one" in output
    code, output = invoke(["evaluate", "--resume", "--contours", "circle-small"])
    assert code == 2 and "--out" in output


@pytest.mark.parametrize("option", ["--overwrite", "--resume"])
def test_a_folder_warpcut_did_not_mark_is_never_deleted_or_written_in(tmp_path, option):
    """A folder is a run only if warpcut marked it: a file named like a run's (config.json, results.json)
    in a user's project proves nothing, and neither --overwrite nor --resume touches the project."""
    project = tmp_path / "project"
    (project / "src").mkdir(parents=True)
    files = {
        "src/main.py": "print(1)",
        "notes.txt": "years of work",
        "config.json": "{}",
        "results.json": "[]",
    }
    for name, text in files.items():
        (project / name).write_text(text)
    for args in (
        ["evaluate", "--contours", "circle-small", "--methods", "none", "--trials", "1"],
        ["train", "--contour", "circle-small", "--iterations", "1", "--no-progress"],
        ["run", "--contour", "circle-small", "--policy", "fixed", "--set", "trials=1"],
    ):
        if args[0] == "train" and option == "--resume":
            given = [*args, "--resume", str(project)]
        else:
            given = [*args, "--out", str(project), option]
        code, output = invoke(given)
        assert code == 2 and "holds files warpcut did not write" in output, (given, output)
        assert len(output.strip().splitlines()) == 1
        assert {
            p.relative_to(project).as_posix(): p.read_text() for p in project.rglob("*") if p.is_file()
        } == files
    for root in ("/", str(tmp_path)):  # never "a run", never offered --overwrite
        code, output = invoke(["evaluate", "--contours", "circle-small", "--methods", "none", "--out", root])
        assert code == 2 and "--overwrite" not in output and "a run" not in output


def test_a_run_resumes_only_as_the_command_that_made_it(tmp_path):
    run = tmp_path / "run"
    code, output = invoke(["train", "--contour", "circle-small", "--iterations", "1", "--no-progress",
                           "--set", "train.num_envs=64", "--set", "eval_trials=1",
                           "--out", str(run)])  # fmt: skip
    assert code == 0, output
    marker = read_run_marker(run)
    assert marker["command"] == "train" and "summary.json" in marker["files"] and "pid" not in marker
    listing = sorted(p.relative_to(run).as_posix() for p in run.rglob("*") if p.is_file())
    assert set(listing) - set(marker["files"]) == {RUN_MARKER}  # every file the run wrote is listed
    assert marker["argv"][:2] == ["warpcut", "train"]
    assert invoke(["export", str(run)])[0] == 0  # export writes beside the run: its files are the run's
    assert {"exported/policy.pt", "exported/policy.onnx"} <= set(read_run_marker(run)["files"])
    before = {p: p.stat().st_mtime_ns for p in run.iterdir()}
    for command in (
        ["evaluate", "--contours", "circle-small", "--methods", "none", "--trials", "1"],
        ["run", "--contour", "circle-small", "--policy", "fixed", "--set", "trials=1"],
    ):
        code, output = invoke([*command, "--out", str(run), "--resume"])
        expected = f"holds a run of 'warpcut train', not of 'warpcut {command[0]}'"
        assert code == 2 and expected in output, output
    assert {p: p.stat().st_mtime_ns for p in run.iterdir()} == before


def test_bad_inputs_are_refused_before_any_work_and_leave_no_run_behind(tmp_path, monkeypatch):
    """NaN through a number, a seed past 32 bits, an output that cannot be written, --resume of a run that
    does not exist, a setting the command would ignore, a learner that cannot train in its env, and a
    study's bad values: each one line naming the flag or key, before anything runs."""
    monkeypatch.chdir(tmp_path)  # a command that went ahead would write its default run directory here
    fresh = str(tmp_path / "new")
    for args, message in [
        (
            ["train", "--contour", "circle-small", "--algo", "ppo", "--set", "train.ppo.stay_prior=.nan"],
            "train.ppo.stay_prior: expected a number (got nan)",
        ),
        (
            ["optimize", "--contour", "circle-small", "--set", "grad.learning_rate=.inf"],
            "grad.learning_rate: must be a positive number",
        ),
        (["simulate", "--contour", "circle-small", "--set", "sim.noise_std=.nan"], "sim.noise_std: expected"),
        (["train", "--contour", "circle-small", "--seed", str(2**40)], "'--seed': 1099511627776 is not in"),
        (
            ["train", "--contour", "circle-small", "--contour", "wave-1"],
            "--contour: given twice; give it once",
        ),
        (
            ["plan", "--contour", "circle-small", "--json", "/proc/x.json"],
            "--json: cannot write /proc/x.json",
        ),
        (["contours", "--json", "/proc/x.json"], "--json: cannot write /proc/x.json"),
        (["optimize", "--contour", "circle-small", "--resume", "--out", fresh], "holds no run to continue"),
        (
            ["evaluate", "--contours", "circle-small", "--resume", "--out", fresh],
            "drop --resume to start one",
        ),
        (
            ["run", "--contour", "circle-small", "--policy", "fixed", "--set", "rl_candidates=3"],
            "rl_candidates: read by --policy rl only",
        ),
        (
            ["evaluate", "--contours", "circle-small", "--methods", "none", "--set", "train.iterations=5"],
            "train.iterations: read by the rl column only",
        ),
        (
            ["evaluate", "--methods", "rl", "--set", "grad.es_feedback_phases=2"],
            "grad.es_feedback_phases: read by the grad column only",
        ),
        (
            ["run", "--algo", "apg", "--set", "env.randomize=[gravity]"],
            "env.randomize: APG differentiates one fixed sheet; train with es or ppo",
        ),
        (
            [
                "train",
                "--contour",
                "circle-small",
                "--algo",
                "apg",
                "--set",
                "env.relative_reward=true",
                "--out",
                fresh,
            ],
            "APG differentiates one fixed sheet",
        ),  # fmt: skip
        (["run", "--set", "train.num_envs=2"], "64 must divide num_envs (2)"),
        (["evaluate", "--set", "train.num_envs=96"], "e.g. train.gps.refine.population=48"),
        (
            ["train", "--contour", "circle-small", "--algo", "apg", "--set", "env.action_type=discrete"],
            "algo: apg",
        ),
        (
            ["evaluate", "--methods", "grad", "--set", "grad.es_feedback_sag=true"],
            "give es_feedback_phases >= 1",
        ),
        (
            ["optimize", "--contour", "circle-small", "--set", "grad.es_population=3"],
            "grad.es_population: must be even",
        ),
    ]:
        code, output = invoke(args)
        assert code == 2 and message in output, (args, output)
        assert len(output.strip().splitlines()) == 1, (args, output)
    assert not Path(fresh).exists() and not list(tmp_path.iterdir())
    out = tmp_path / "study"
    args = ["robustness", "--contour", "circle-small", "--study", "noise", "--trials", "1",
            "--set", "plots=false", "--out", str(out)]  # fmt: skip
    code, output = invoke([*args, "--set", "values=[-1]"])
    assert code != 0 and "values: noise -1" in output
    assert not (out / "config.json").exists()  # so the same --out takes the corrected command
    run = tmp_path / "train"
    code, output = invoke(["train", "--contour", "circle-small", "--pinch", "500,500", "--out", str(run)])
    assert code != 0 and "off the 100 x 100 mm sheet" in output
    assert not (run / "options.json").exists()  # the env refused the options before the run was written


def test_a_run_directory_is_locked_while_a_process_writes_it(tmp_path):
    out = tmp_path / "run"
    holder = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(f"""
            import sys, time
            from warpcut.io import claim_run_dir
            with claim_run_dir({str(out)!r}, command="evaluate"):
                print("held", flush=True)
                time.sleep(60)
        """)],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        code, output = invoke(["evaluate", "--contours", "circle-small", "--methods", "none", "--trials", "1",
                               "--resume", "--out", str(out)])  # fmt: skip
        assert code == 2 and f"in use by warpcut process {holder.pid}" in output
        start = time.perf_counter()  # said at once, before the checks that plan and load (seconds)
        for args in (
            ["run", "--contour", "fls-circle", "--out", str(out), "--resume"],
            ["train", "--resume", str(out)],
        ):
            code, output = invoke(args)
            assert code == 2 and f"in use by warpcut process {holder.pid}" in output, output
        assert time.perf_counter() - start < 2
    finally:
        holder.kill()
        holder.wait()
    with claim_run_dir(out, command=None, resume=True) as claimed:  # the lock died with its process
        with claim_run_dir(out, command=None):  # a claim inside this process's own claim passes
            pass
    assert sorted(p.name for p in claimed.iterdir()) == []  # no lock file, no marker: nothing was written
    refused = tmp_path / "refused"
    (refused / "mine.txt").parent.mkdir()
    (refused / "mine.txt").write_text("")
    with pytest.raises(ValueError, match="holds files warpcut did not write"):
        with claim_run_dir(refused, command="train"):
            pass
    assert [p.name for p in refused.iterdir()] == ["mine.txt"]  # no lock or marker left behind


def test_an_output_that_is_an_input_is_refused(tmp_path):
    contour = contour_file(tmp_path / "disc.json", "disc")
    before = contour.read_bytes()
    code, output = invoke(["evaluate", "--contours", str(contour), "--methods", "none", "--trials", "1",
                           "--json", str(contour), "--out", str(tmp_path / "eval")])  # fmt: skip
    assert code == 2 and "--json" in output and "is an input" in output
    code, output = invoke(["simulate", "--contour", str(contour), "--json", str(contour)])
    assert code == 2 and "is an input" in output
    code, output = invoke(["run", "--contour", str(contour), "--policy", "fixed", "--json", str(contour),
                           "--out", str(tmp_path / "run")])  # fmt: skip
    assert code == 2 and "is an input" in output
    assert contour.read_bytes() == before


def test_json_is_standard_and_missing_values_are_null(tmp_path):
    path = write_json(
        tmp_path / "r.json", {"a": float("nan"), "b": [np.float32(2.5), np.inf], "c": np.array([1.0])}
    )
    text = path.read_text()
    assert "NaN" not in text and "Infinity" not in text
    assert json.loads(text) == {"a": None, "b": [2.5, None], "c": [1.0]}


def test_a_recording_cut_short_never_replaces_a_good_one(tmp_path):
    import rerun as rr

    def record(path: Path, frames: int) -> None:
        stream = rr.RecordingStream("test")
        stream.save(path)
        for k in range(frames):
            stream.set_time("step", sequence=k)
            stream.log("points", rr.Points3D(np.full((100, 3), float(k))))
        stream.flush()
        stream.disconnect()

    path, tmp = tmp_path / "recording.rrd", tmp_path / ".recording.rrd.tmp"
    record(path, 5)
    good = path.read_bytes()
    record(tmp, 50)
    data = tmp.read_bytes()
    tmp.write_bytes(data[: len(data) // 2])  # what a full disk leaves
    with pytest.raises(RecordingError, match="cut short.*still holds the earlier recording"):
        place_file(tmp, path, keep=True)
    assert path.read_bytes() == good and (tmp_path / "recording.partial.rrd").is_file() and not tmp.exists()

    record(tmp, 3)  # a complete one replaces it
    place_file(tmp, path, keep=True)
    assert path.read_bytes() != good and not tmp.exists()

    path.unlink()  # with no earlier recording, one cut short takes its place, and says so
    tmp.write_bytes(data[: len(data) // 2])
    with pytest.raises(RecordingError, match="cut short.*the file holds what was written"):
        place_file(tmp, path, keep=True)
    assert path.read_bytes() == data[: len(data) // 2]


def test_a_recording_on_a_full_disk_keeps_the_earlier_one(tmp_path):
    """`--record` on a disk that fills up (here a file-size limit): the earlier recording stays intact."""
    code = textwrap.dedent("""
        import resource, signal, sys
        from click.testing import CliRunner
        from agents.cli import main
        args = ["simulate", "--contour", "circle-small", "--policy", "none", "--set", "sim.resolution=9",
                "--trials", "2", "--set", "plots=false", "--record", "2", "--out", sys.argv[1]]
        if sys.argv[2] == "full":
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            size = int(sys.argv[3]) // 3
            resource.setrlimit(resource.RLIMIT_FSIZE, (size, size))
        result = CliRunner().invoke(main, args)
        print("exit", result.exit_code)
        print(result.output)
    """)
    out = tmp_path / "sim"
    env = dict(os.environ)
    first = subprocess.run(
        [sys.executable, "-c", code, str(out), "ok"], capture_output=True, text=True, env=env
    )
    assert "exit 0" in first.stdout, first.stdout + first.stderr
    recording = out / "recording.rrd"
    good = recording.read_bytes()
    full = subprocess.run(
        [sys.executable, "-c", code, str(out), "full", str(len(good))],
        capture_output=True,
        text=True,
        env=env,
    )
    assert "exit 0" not in full.stdout, full.stdout + full.stderr
    assert recording.read_bytes() == good


def test_evaluate_resumes_after_an_interruption_keeping_finished_policies(tmp_path, monkeypatch):
    contours = ["circle-small", "wave-1"]
    job = EvaluateJob(contours=contours, methods=["none", "rl"], trials=1, sim=SMALL, plan=False, train=TINY)
    trained = []
    real = agents.training.train_contour

    def train_then_stop(train_job, out_dir, **kw):
        trained.append(Path(out_dir).name)
        if trained == ["circle-small", "wave-1"]:
            raise KeyboardInterrupt  # Ctrl-C as the second policy starts training
        return real(train_job, out_dir, **kw)

    monkeypatch.setattr(agents.training, "train_contour", train_then_stop)
    out = tmp_path / "table"
    with pytest.raises(TrainingInterrupted) as stopped:
        evaluate_table(job, out)
    assert stopped.value.run_dir == out / "policies" / "wave-1"
    with pytest.raises(ValueError, match="holds a run of 'warpcut evaluate'"):
        evaluate_table(job, out)
    with pytest.raises(ValueError, match=r"trials: 1 then, 2 now.*--config .*config.json"):
        evaluate_table(dataclasses.replace(job, trials=2), out, resume=True)
    finished = (out / "policies/circle-small/summary.json").read_bytes()
    trained.clear()
    report = evaluate_table(
        dataclasses.replace(job, record=1, plots=False), out, resume=True
    )  # outputs may change
    assert trained == ["wave-1"]  # circle-small's finished policy was kept, not trained again
    assert (out / "policies/circle-small/summary.json").read_bytes() == finished
    assert [r["contour"] for r in report.table["rows"]] == contours
    assert json.loads((out / "config.json").read_text())["trials"] == 1


def test_run_pipeline_resumes_its_candidates(tmp_path):
    job = RunJob(contour="circle-small", candidates=2, rl_candidates=2, trials=1, sim=SMALL, train=TINY)
    first = run_pipeline(job, tmp_path)
    stamps = {p: p.stat().st_mtime_ns for p in tmp_path.glob("rl/candidate-*/summary.json")}
    assert len(stamps) == 2
    again = run_pipeline(job, tmp_path, resume=True)
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps  # nothing retrained
    assert again.row == first.row
    assert json.loads((tmp_path / "config.json").read_text()) == to_plain(job)


@pytest.mark.parametrize("signum, status", [(signal.SIGTERM, 143), (signal.SIGHUP, 129)])
def test_sigterm_and_sighup_save_the_training_and_say_how_to_resume(tmp_path, signum, status):
    out = tmp_path / "table"
    proc = subprocess.Popen(
        [sys.executable, "-m", "warpcut", "evaluate", "--contours", "circle-small", "--methods", "none,rl",
         "--trials", "1", "--set", "train.iterations=5000", *TINY_FLAGS, "--set", "plan=false",
         "--set", "plots=false", "--out", str(out)],
        stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT,
    )  # fmt: skip
    lines = []
    for line in proc.stderr:
        lines.append(line)
        if "training es for circle-small" in line:
            break
    summary = out / "policies/circle-small/summary.json"
    deadline = time.monotonic() + 60
    while not any(out.glob("policies/circle-small/events.out.tfevents.*")) and time.monotonic() < deadline:
        time.sleep(0.2)
    time.sleep(1.0)
    proc.send_signal(signum)
    rest = proc.stderr.read()
    assert proc.wait(timeout=60) == status, "".join(lines) + rest
    name = signal.Signals(signum).name
    assert f"terminated ({name})" in rest and "checkpoint saved in" in rest and "--resume" in rest
    assert json.loads(summary.read_text())["status"] == "interrupted"
    assert (out / "policies/circle-small/latest.pt").is_file()


def test_checkpoints_of_another_contour_or_an_unfinished_run_are_refused(tmp_path):
    """A circle-small policy filed as fls-circle is refused, not scored as fls-circle's."""
    from agents.training import train_contour

    runs = tmp_path / "runs"
    train = dataclasses.replace(TINY, iterations=1)
    trained = TrainJob(contour="circle-small", sim=SMALL, eval_trials=1, train=train)
    train_contour(trained, runs / "fls-circle", progress=False)
    job = EvaluateJob(
        contours=["fls-circle"],
        methods=["none", "rl"],
        trials=1,
        sim=SMALL,
        plan=False,
        checkpoints=str(runs),
    )
    with pytest.raises(
        ValueError, match="trained on contour 'circle-small', not on the requested 'fls-circle'"
    ):
        evaluate_table(job, tmp_path / "a")

    (runs / "fls-circle").rename(runs / "circle-small")
    summary = runs / "circle-small" / "summary.json"
    summary.write_text(json.dumps({**json.loads(summary.read_text()), "status": "interrupted"}))
    job = dataclasses.replace(job, contours=["circle-small"])
    with pytest.raises(ValueError, match="allow.partial"):
        evaluate_table(job, tmp_path / "b")
    report = evaluate_table(dataclasses.replace(job, allow_partial=True), tmp_path / "c")
    assert np.isfinite(report.table["rows"][0]["rl_improvement_pct"])
    code, output = invoke(["evaluate", "--contours", "circle-small", "--methods", "none,rl", "--trials", "1",
                           "--set", "sim.resolution=13", "--checkpoints", str(runs),
                           "--out", str(tmp_path / "d")])  # fmt: skip
    assert code == 2 and re.search("allow.partial", output) and len(output.strip().splitlines()) == 1


def test_plan_json_never_overwrites_its_contour(tmp_path):
    contour = contour_file(tmp_path / "disc.json", "disc")
    before = contour.read_bytes()
    code, output = invoke(["plan", "--contour", str(contour), "--json", str(contour)])
    assert code == 2 and "is an input" in output and contour.read_bytes() == before


@pytest.mark.parametrize(
    "args",
    [
        ["plan", "--contour", "circle-small"],
        ["contours"],
        ["simulate", "--contour", "circle-small", "--policy", "none", "--set", "plots=false"],
        ["evaluate", "--contours", "circle-small", "--methods", "none", "--out", "OUT"],
        ["bench", "--repeats", "1"],
    ],
)
def test_a_json_output_never_replaces_a_users_file_or_writes_into_another_run(tmp_path, args):
    """``--json`` keeps the promise of the run directories: a file warpcut cannot tell it wrote (a user's
    results, in no run directory) is never replaced, and a file in a run directory the command does not own
    (a finished run's ``config.json``) is never written, before any work."""
    user = tmp_path / "user_results.json"
    user.write_text("the user's")
    run = tmp_path / "run"
    with claim_run_dir(run, command="train"):
        write_json(run / "config.json", {"train": True})
    for path, why in [(user, "lies in no run directory of warpcut's"), (run / "config.json", "does not own"),
                      (run / "new.json", "does not own")]:  # fmt: skip
        given = [str(tmp_path / "out") if a == "OUT" else a for a in args]
        code, output = invoke([*given, "--json", str(path)])
        assert code == 2 and f"--json: {path}" in output and why in output, output
    assert user.read_text() == "the user's"
    assert json.loads((run / "config.json").read_text()) == {"train": True}
    assert not (run / "new.json").exists() and not (tmp_path / "out").exists()


def test_deeply_nested_or_huge_inputs_are_one_line_before_any_work(tmp_path):
    """JSON nested past Python's recursion (a run's marker, config.json, plans.json), YAML whose aliases
    expand to billions of values or hold themselves, and integers beyond any setting's range: each is one
    line naming the file or setting, before a run is claimed or anything is computed."""
    from warpcut.io import read_json

    deep = "[" * 100_000 + "]" * 100_000
    run = tmp_path / "run"
    with claim_run_dir(run, command="evaluate"):
        write_json(run / "config.json", {})
        write_json(run / "plans.json", {})
    (run / "plans.json").write_text(deep)
    with pytest.raises(ValueError, match=r"plans.json: nests deeper than 32 levels"):
        read_json(run / "plans.json")
    (run / "plans.json").write_text('{"a": ' * 900 + "1" + "}" * 900)  # parses, but nothing could walk it
    with pytest.raises(ValueError, match=r"plans.json: nests deeper than 32 levels"):
        read_json(run / "plans.json")
    (run / "config.json").write_text(deep)
    code, output = invoke(["evaluate", "--contours", "circle-small", "--out", str(run), "--resume"])
    assert code == 2 and "config.json: nests deeper than 32 levels" in output, output
    (run / RUN_MARKER).write_text('{"format": "warpcut-run", "files": ' + deep + "}")
    code, output = invoke(["evaluate", "--contours", "circle-small", "--out", str(run), "--resume"])
    assert code == 2 and f"its {RUN_MARKER} is damaged" in output, output
    aliases = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"] + [
        f"a{k}: &a{k} [{', '.join([f'*a{k - 1}'] * 10)}]" for k in range(1, 9)
    ]
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text("train:\n  es:\n" + "".join(f"    {line}\n" for line in aliases))  # 8 levels of 10
    itself = tmp_path / "itself.yaml"
    itself.write_text("train: &a [*a]\n")
    start = time.perf_counter()
    for args, said in [
        (["--config", str(bomb)], "expands to more than 100,000 values"),
        (["--config", str(itself)], "holds itself"),
        (["--set", "train.actor_hidden_dims=" + "[" * 50 + "]" * 50], "--set train.actor_hidden_dims: nests"),
        (["--set", "train.iterations=" + "9" * 23], "train.iterations: " + "9" * 23 + " is beyond"),
        (["--set", "seed=2147483648"], "seed: 2147483648 is beyond any setting's range"),
        (["--iterations", "99999999999999999999999"], "--iterations: train.iterations: 9999"),
    ]:
        for then in (["--print-config"], ["--out", str(tmp_path / "out")]):
            code, output = invoke(["train", "--contour", "circle-small", *args, *then])
            assert code == 2 and said in output and "Traceback" not in output, output
    assert time.perf_counter() - start < 30 and not (tmp_path / "out").exists()


def test_train_refuses_an_existing_run_and_stops_on_sigterm_with_a_checkpoint(tmp_path):
    run = tmp_path / "run"
    args = ["train", "--contour", "circle-small", *TINY_FLAGS, "--set", "eval_trials=1",
            "--set", "train.validation_trials=0", "--no-progress", "--set", "plots=false",
            "--out", str(run)]  # fmt: skip
    proc = subprocess.Popen(
        [sys.executable, "-m", "warpcut", *args, "--iterations", "5000"],
        stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT,
    )  # fmt: skip
    deadline = time.monotonic() + 90
    while not any(run.glob("events.out.tfevents.*")) and time.monotonic() < deadline:
        time.sleep(0.2)
    time.sleep(1.0)
    code, output = invoke([*args, "--iterations", "2"])  # a second process on the same run
    assert code == 2 and f"in use by warpcut process {proc.pid}" in output
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert (
        f"terminated (SIGTERM): checkpoint saved in {run}; continue with 'warpcut train --resume {run}'"
        in err
    )
    summary = json.loads((run / "summary.json").read_text())
    assert summary["status"] == "interrupted" and (run / "latest.pt").is_file()

    code, output = invoke([*args, "--iterations", "2"])
    assert code == 2 and "holds a run of 'warpcut train'" in output
    code, output = invoke(["train", "--resume", str(run), "--set", "train.es.sigma=0.5"])
    assert code == 2 and "train.es.sigma" in output and "keeps its settings" in output
    code, output = invoke(["train", "--resume", str(run), "--iterations", str(summary["iterations"] + 1),
                           "--no-progress"])  # fmt: skip
    assert code == 0, output
    assert json.loads((run / "summary.json").read_text())["status"] == "completed"


@pytest.mark.parametrize(
    "code, reason",
    [
        (errno.ENOSPC, "the disk is full"),
        (errno.EDQUOT, "the disk quota is exceeded"),
        (errno.EFBIG, "ulimit -f"),
        (errno.EROFS, "read-only"),
        (errno.EACCES, "permission denied"),
        (errno.EIO, "an I/O error"),
    ],
)
def test_a_failed_write_never_replaces_a_good_file(tmp_path, monkeypatch, code, reason):
    """Every OS error on write (not only a full disk) is one line naming the file and why, and the file it
    would have replaced stays as it was, with no temporary file beside it."""
    from warpcut.io import WriteFailed, write_atomic

    path = write_json(tmp_path / "results.json", {"good": True})

    def refused(fd):
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(os, "fsync", refused)
    with pytest.raises(
        WriteFailed, match=rf"results.json: not written, .*{re.escape(reason)}.*; its previous version"
    ):
        write_json(path, {"good": False})
    monkeypatch.undo()
    assert json.loads(path.read_text()) == {"good": True}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.json"]  # no temporary file left
    (tmp_path / "x.json").mkdir()
    with pytest.raises(ValueError, match="x.json: is a directory, not a file"):
        write_atomic(tmp_path / "x.json", b"{}")


def test_a_directory_as_the_json_output_is_one_line(tmp_path):
    (tmp_path / "x.json").mkdir()
    code, output = invoke(["simulate", "--contour", "circle-small", "--json", str(tmp_path / "x.json")])
    assert code == 2 and "is a directory" in output and len(output.strip().splitlines()) == 1


def _limited(limit_bytes: int):
    """A ``preexec_fn`` that caps the size of any file the process writes (``ulimit -f``): a larger write
    fails with EFBIG (Python ignores SIGXFSZ)."""

    def limit():
        import resource

        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

    return limit


def test_a_file_size_limit_is_one_line_and_the_run_resumes(tmp_path):
    """``ulimit -f`` below a checkpoint's size: training stops with one line naming the file and the
    limit, keeps what it wrote whole, and resumes (without the limit) to the end; ``evaluate --json``
    past the limit is one line too."""
    run = tmp_path / "run"
    args = [sys.executable, "-m", "warpcut", "train", "--contour", "circle-small", "--iterations", "2",
            "--no-progress", "--set", "train.num_envs=64", "--set", "eval_trials=1", "--set", "plots=false",
            "--out", str(run)]  # fmt: skip
    done = subprocess.run(args, capture_output=True, text=True, timeout=300, preexec_fn=_limited(20_000))
    assert done.returncode == 2, done.stderr
    error = done.stderr.strip().splitlines()
    assert len(error) == 1 and "Traceback" not in done.stderr, done.stderr
    assert "not written, the file is larger than this process may write (ulimit -f)" in error[0]
    assert f"resume from {run}" in error[0] or "start again" in error[0]
    assert not list(run.glob(".*.tmp"))
    for path in run.glob("*.json"):
        json.loads(path.read_text())  # what was written is whole
    again = subprocess.run([*args[:3], "train", "--resume", str(run), "--no-progress"],
                           capture_output=True, text=True, timeout=300)  # fmt: skip
    assert again.returncode == 0, again.stderr
    assert json.loads((run / "summary.json").read_text())["status"] == "completed"

    out = tmp_path / "table.json"
    done = subprocess.run(
        [sys.executable, "-m", "warpcut", "evaluate", "--contours", "circle-small", "--methods", "none",
         "--trials", "1", "--set", "plots=false", "--out", str(tmp_path / "table"), "--json", str(out)],
        capture_output=True, text=True, timeout=300, preexec_fn=_limited(600),
    )  # fmt: skip
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "ulimit -f" in done.stderr


@pytest.mark.parametrize("pinch", ["nan,50", "50,inf", "-inf,-inf"])
def test_a_non_finite_pinch_is_refused(pinch):
    code, output = invoke(["simulate", "--contour", "circle-small", "--pinch", pinch])
    assert code == 2 and "--pinch" in output and "finite" in output


@pytest.mark.parametrize("when", ["before its first checkpoint", "after its first checkpoint"])
def test_a_run_killed_before_its_summary_resumes_with_its_own_settings(tmp_path, when):
    """``kill -9`` (no handler runs, no summary.json): ``train --resume RUN`` with no other option trains
    the run's own number of iterations, not the learner's default."""
    run = tmp_path / "run"
    kill = "os.kill(os.getpid(), signal.SIGKILL)"
    patch = (
        f"agents.training.train = lambda *a, **k: {kill}"
        if when == "before its first checkpoint"
        else "save = agents.runner.Runner.save\n"
        f"agents.runner.Runner.save = lambda self, *a, **k: (save(self, *a, **k), {kill})"
    )
    script = (
        "import os, signal, sys\nimport agents.runner, agents.training\n"
        f"{patch}\n"
        "from agents.cli import main\n"
        "sys.argv = ['warpcut', 'train', '--contour', 'circle-small', '--iterations', '3', '--no-progress',"
        " '--set', 'train.num_envs=64', '--set', 'eval_trials=1', '--set', 'plots=false',"
        f" '--out', {str(run)!r}]\n"
        "main()\n"
    )
    killed = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    assert not (run / "summary.json").exists() and (run / "config.json").is_file()
    code, output = invoke(["train", "--resume", str(run), "--no-progress"])
    assert code == 0, output
    assert ("saved no checkpoint" in output) == (when == "before its first checkpoint")
    assert json.loads((run / "summary.json").read_text())["iterations"] == 3


@pytest.mark.parametrize(
    "args, job",
    [
        (["simulate", "--contour", "circle-small", "--policy", "none"], "SimulateJob(policy=['none'])"),
        (["run", "--policy", "fixed"], "RunJob(policy='fixed')"),
        (["evaluate", "--methods", "none,fixed"], "EvaluateJob(methods=['none', 'fixed'])"),
        (["optimize", "--contour", "circle-small", "--estimator", "es"], "OptimizeJob()"),
        (["train", "--contour", "circle-small"], "TrainJob()"),
        (["robustness", "--contour", "circle-small", "--methods", "none,fixed"], "RobustnessJob()"),
    ],
)
def test_every_setting_an_invocation_would_ignore_is_refused(args, job):
    """The rule is general, not a list of cases: each key the job says it would not use
    (``unused_keys``), given on the command line at any value (its default too), is refused on one line
    that names it, before any work."""
    from agents import jobs
    from agents.config_io import flatten

    job = eval(job, vars(jobs))
    plain = flatten(to_plain(job))
    unused = job.unused_keys()
    assert unused or args[0] == "robustness", args  # each command has something it can ignore
    checked = 0
    for key in unused:
        for leaf in [k for k in plain if k == key or k.startswith(f"{key}.")][:4]:
            code, output = invoke([*args, "--set", f"{leaf}={json.dumps(plain[leaf])}", "--print-config"])
            assert code == 2 and f"{leaf}: " in output and "drop it" in output, (leaf, output)
            assert len(output.strip().splitlines()) == 1
            checked += 1
    assert checked >= len(unused)


def test_an_unwritable_working_folder_is_named_before_any_work(monkeypatch):
    """The default outputs go under the working folder: where it cannot be written (here /proc, where no
    file can be made) the command says so on one line before simulating, not after."""
    monkeypatch.chdir("/proc")
    for args in (
        ["simulate", "--contour", "circle-small", "--trials", "1"],
        ["simulate", "--contour", "circle-small", "--trials", "1", "--record", "1", "--set", "plots=false"],
        ["evaluate", "--contours", "circle-small", "--methods", "none", "--trials", "1"],
    ):
        code, output = invoke(args)
        assert code == 2 and "the working folder /proc" in output, (args, output)
        assert len(output.strip().splitlines()) == 1 and "error (vertices)" not in output


def test_a_batch_the_user_never_sized_is_named_as_what_it_is(monkeypatch, tmp_path):
    """A batch a pipeline makes itself (the planner's candidates x orders) that does not fit in memory is
    named as what it is, with the setting that shrinks it, not as num_envs, a count nobody gave."""
    monkeypatch.setenv("WARPCUT_MEMORY_LIMIT_GB", "0.003")
    for args in (
        ["plan", "--contour", "fls-circle"],
        ["evaluate", "--contours", "circle-small", "--methods", "none,fixed", "--out", str(tmp_path / "e")],
    ):
        code, output = invoke(args)
        error = output.strip().splitlines()[-1]  # after evaluate's progress lines
        assert code == 2 and "the planner's batch (pinch candidates x segment orders)" in error, output
        assert "num_envs" not in error and "--candidates" in error


def test_export_never_replaces_a_file_warpcut_did_not_write(tmp_path):
    """``warpcut export`` writes into a folder it marks (or the run's own): a user's folder, or a user's
    ``policy.onnx`` placed in a run, is never overwritten; exporting again into its own folder is."""
    run = tmp_path / "run"
    code, output = invoke(["train", "--contour", "circle-small", "--iterations", "1", "--no-progress",
                           "--set", "train.num_envs=64", "--set", "eval_trials=1", "--set", "plots=false",
                           "--out", str(run)])  # fmt: skip
    assert code == 0, output
    mine = tmp_path / "deploy"
    mine.mkdir()
    (mine / "policy.onnx").write_bytes(b"the user's own model")
    code, output = invoke(["export", str(run), "--out", str(mine)])
    assert code == 2 and "holds files warpcut did not write" in output
    assert (mine / "policy.onnx").read_bytes() == b"the user's own model"
    (run / "exported").mkdir()
    (run / "exported" / "policy.onnx").write_bytes(b"put here by hand")
    code, output = invoke(["export", str(run)])
    assert code == 2 and "warpcut did not write it" in output
    assert (run / "exported" / "policy.onnx").read_bytes() == b"put here by hand"
    fresh = tmp_path / "fresh"
    for _ in range(2):  # its own folder: marked, and exported into again
        code, output = invoke(["export", str(run), "--out", str(fresh)])
        assert code == 0, output
        (fresh / ".policy.onnx.tmp").write_text("the user's")  # a name like a temporary file's: kept
    assert {"policy.pt", "policy.onnx"} <= set(read_run_marker(fresh)["files"])
    assert (fresh / ".policy.onnx.tmp").read_text() == "the user's"
    other = tmp_path / "other"  # another run: never written into, even where its folder is new
    with claim_run_dir(other, command="evaluate"):
        write_json(other / "results.json", {})
    code, output = invoke(["export", str(run), "--out", str(other / "deploy")])
    assert code == 2 and "not the one exported from, so warpcut never writes there" in output, output
    assert sorted(p.name for p in other.iterdir()) == [RUN_MARKER, "results.json"]


@pytest.mark.parametrize("mode", ["resume", "overwrite", "reuse"])
def test_a_run_never_writes_or_deletes_through_a_link_out_of_it(tmp_path, mode):
    """A folder of a run replaced by a link to the user's files (and a marker that lists them): resuming,
    overwriting or writing into the run again is refused in one line naming the link, and nothing outside
    is created, replaced or deleted."""
    import shutil

    out = tmp_path / "run"
    with claim_run_dir(out, command="evaluate"):
        write_json(out / "policies" / "c" / "results.json", {"run": True})
    outside = tmp_path / "project"
    outside.mkdir()
    (outside / "results.json").write_text("the user's")
    shutil.rmtree(out / "policies" / "c")
    (out / "policies" / "c").symlink_to(outside)
    marker = read_run_marker(out)
    marker["files"].append("../project/config.json")
    (out / RUN_MARKER).write_text(json.dumps(marker))
    with pytest.raises(ValueError, match=r"policies/c: a link to .*project, out of the run directory"):
        with claim_run_dir(out, command="evaluate", **{mode: True}):
            write_json(out / "policies" / "c" / "results.json", {"run": False})
    assert [p.name for p in outside.iterdir()] == ["results.json"]
    assert (outside / "results.json").read_text() == "the user's"
    code, output = invoke(["evaluate", "--contours", "circle-small", "--methods", "none", "--out", str(out),
                           f"--{mode}" if mode != "reuse" else "--resume"])  # fmt: skip
    assert code == 2 and "a link to" in output and "remove the link" in output, output
    assert [p.name for p in outside.iterdir()] == ["results.json"]


def test_overwrite_deletes_only_warpcuts_own_temporary_files(tmp_path):
    """Files a user put beside a run's files under names like theirs (``.config.json.orig``, an editor's
    ``.summary.json.swp``) are kept by ``--overwrite``; the temporary files warpcut's writers leave when
    killed (a form only they use) go."""
    from warpcut.io import temp_file

    out = tmp_path / "run"
    with claim_run_dir(out, command="train"):
        for name in ("config.json", "summary.json", "best.pt", "model_0.pt", "env_0.mp4"):
            write_json(out / name, {})
    users = [".config.json.orig", ".best.pt.bak", ".summary.json.swp", ".model_0.notes.mp4", ".env_0.x.mp4",
             ".config.json.tmp", ".best.pt.abcdefgh.tmp"]  # fmt: skip
    for name in users:
        (out / name).write_text("the user's")
    leftovers = [temp_file(out / "config.json")[1], temp_file(out / "env_0.mp4", ".mp4")[1]]
    with claim_run_dir(out, command="train", overwrite=True):
        pass
    assert sorted(p.name for p in out.iterdir() if p.name != RUN_MARKER) == sorted(users)
    assert not any(Path(p).exists() for p in leftovers)


def test_a_link_made_during_a_run_is_never_written_through(tmp_path):
    """A link out of the run made while it runs: every writer (JSON, checkpoints, recordings, videos) lists
    its file first, and refuses, naming the link, before it creates anything outside."""
    from warpcut.io import note_written

    out, outside = tmp_path / "run", tmp_path / "project"
    outside.mkdir()
    with claim_run_dir(out, command="train"):
        write_json(out / "config.json", {})
        (out / "late").symlink_to(outside)
        for path in (out / "late" / "summary.json", out / "late" / "deeper" / "best.pt"):
            with pytest.raises(ValueError, match="leads out of the run directory"):
                write_json(path, {})
        (out / "file-link.json").symlink_to(outside / "x.json")
        with pytest.raises(ValueError, match="exists, and warpcut did not write it"):
            note_written(out / "file-link.json")
    assert not list(outside.iterdir())
    assert all(not f.startswith("..") for f in read_run_marker(out)["files"])


def test_implicit_outputs_go_only_into_a_folder_warpcut_marks(tmp_path, monkeypatch):
    """simulate's figures, recording and meshes have names the user did not choose: they go into a run folder
    of their own (marked) or a new or empty one, never among a user's files (a user's recording.rrd or mesh
    is never replaced); --json names its own file, which may sit among the user's."""
    monkeypatch.chdir(tmp_path)
    user = tmp_path / "results"
    user.mkdir()
    (user / "recording.rrd").write_text("the user's recording")
    args = ["simulate", "--contour", "circle-small", "--policy", "none", "--trials", "1"]
    code, output = invoke([*args, "--json", str(user / "x.json"), "--record", "1"])
    assert code == 0, output
    (recording,) = (tmp_path / "logs").glob("simulate-*/recording.rrd")
    assert "recording.rrd" in read_run_marker(recording.parent)["files"]
    assert sorted(p.name for p in user.iterdir()) == ["recording.rrd", "x.json"]  # the one file named
    code, output = invoke([*args, "--set", f"export_mesh={user}", "--set", "plots=false"])
    assert code == 2 and "holds files warpcut did not write" in output and "export_mesh" in output
    assert (user / "recording.rrd").read_text() == "the user's recording"


def test_a_run_never_replaces_a_file_its_marker_does_not_list(tmp_path):
    """A marked folder with files the marker does not list (put there by hand, or a marker that lost its
    list): --overwrite keeps them and the run stops before replacing one, in one line."""
    out = tmp_path / "run"
    with claim_run_dir(out, command="train"):
        write_json(out / "summary.json", {"run": True})
    marker = read_run_marker(out)
    (out / RUN_MARKER).write_text(json.dumps({**marker, "files": "not a list"}))
    code, output = invoke(["train", "--contour", "circle-small", "--iterations", "1", "--no-progress",
                           "--set", "train.num_envs=64", "--out", str(out), "--overwrite"])  # fmt: skip
    assert code == 2 and "summary.json: exists, and warpcut did not write it" in output, output
    assert json.loads((out / "summary.json").read_text()) == {"run": True}


def test_a_resume_stays_in_its_run_and_says_what_it_cannot_continue(tmp_path):
    run, other = tmp_path / "a", tmp_path / "b"
    with claim_run_dir(run, command="train"):
        write_json(run / "config.json", {})
    code, output = invoke(["train", "--resume", str(run), "--out", str(other)])
    assert code == 2 and "a resumed run continues in its own directory" in output and not other.exists()
    bare = tmp_path / "killed"  # a run killed before it saved its settings: only its marker
    with claim_run_dir(bare, command="train", argv=["warpcut", "train", "--contour", "wave-1"]):
        write_json(bare / "options.json", {})
    (bare / "options.json").unlink()
    code, output = invoke(["train", "--resume", str(bare)])
    assert code == 2 and "stopped before it saved its settings" in output
    assert "warpcut train --contour wave-1" in output
    with claim_run_dir(tmp_path / "outer", command="run"):  # a policy inside another command's run
        write_json(tmp_path / "outer" / "rl" / "candidate-0" / "config.json", {})
    code, output = invoke(["train", "--resume", str(tmp_path / "outer" / "rl" / "candidate-0")])
    assert code == 2 and "is part of the run of 'warpcut run' in" in output and "--resume" in output


def test_a_refusal_names_the_option_that_gave_the_path(tmp_path, monkeypatch):
    """A checkpoint outside any run given to ``train --resume``, a file given as ``export_mesh``: the error
    names the option the path came from, never ``--out``; a refused export leaves no folder behind."""
    checkpoint = tmp_path / "f.pt"
    checkpoint.write_bytes(b"not a run's")
    code, output = invoke(["train", "--resume", str(checkpoint)])
    assert code == 2 and "--resume" in output and "not a checkpoint of a warpcut run" in output, output
    assert "--out" not in output
    code, output = invoke(["simulate", "--contour", "circle-small", "--set", f"export_mesh={checkpoint}"])
    assert code == 2 and "is a file, not a run directory; choose another export_mesh" in output, output
    run = tmp_path / "run"
    settings = [*TINY_FLAGS, "--set", "eval_trials=1", "--set", "plots=false", "--out", str(run)]
    code, output = invoke(["train", "--contour", "circle-small", "--iterations", "1", *settings])
    assert code == 0 and "improvement" in output and "±" not in output, output  # no CI of one trial
    import agents.export
    import warpcut.io

    def refused(path, **kwargs):
        raise ValueError(f"{path}: in use by another warpcut process")

    for module in (agents.export, warpcut.io):
        monkeypatch.setattr(module, "note_written", refused)
    for given in ([], ["--out", str(tmp_path / "new" / "deeper")]):
        code, output = invoke(["export", str(run), *given])
        assert code == 2 and "in use" in output, output
    assert not (run / "exported").exists() and not (tmp_path / "new").exists()


def test_print_config_refuses_the_options_it_would_ignore():
    code, output = invoke(["evaluate", "--print-config", "--json", "x.json", "--device", "cpu"])
    assert code == 2 and "--device, --json: --print-config prints the settings and exits" in output
    code, output = invoke(["run", "--print-config", "--set", "trials=3"])
    assert code == 0 and "trials: 3" in output


def test_export_of_a_run_stopped_before_it_chose_a_candidate(tmp_path):
    """A ``warpcut run`` stopped while its candidates trained (no results.json): export finds each
    candidate's policy so far and says the run is unfinished."""
    from agents.training import train_contour

    out = tmp_path / "run"
    with claim_run_dir(out, command="run"):
        train_contour(TrainJob(contour="circle-small", sim=SMALL, train=TINY, eval_trials=1),
                      out / "rl" / "candidate-0", progress=False)  # fmt: skip
    code, output = invoke(["export", str(out)])
    assert code == 0 and "unfinished, no candidate chosen" in output, output
    assert (out / "rl" / "candidate-0" / "exported" / "policy.onnx").is_file()


def test_a_signal_raised_inside_a_finalizer_is_sent_again():
    """Python drops an exception raised inside a ``__del__`` (it runs wherever memory is freed, as a Warp
    array's does): while a command runs, its hook sends the signal again, so that SIGTERM still stops the
    command at its next step instead of being lost."""
    from agents.cli.errors import Terminated, _redeliver, _stop_on_signals

    class Finalized:
        def __del__(self):
            raise Terminated(signal.SIGTERM)

    handlers, hook = _stop_on_signals(), sys.unraisablehook
    sys.unraisablehook = _redeliver
    try:
        with pytest.raises(Terminated):
            Finalized()  # freed at once: its exception is dropped, the signal sent again
            for _ in range(200):  # the handler runs at the next check
                time.sleep(0.01)
    finally:
        sys.unraisablehook = hook
        for signum, handler in handlers.items():
            signal.signal(signum, handler)
