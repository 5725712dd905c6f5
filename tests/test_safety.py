"""Nothing a user made is lost. Run directories (claimed, locked, resumed), file names derived from
contour names, outputs that would overwrite inputs, recordings cut short, and SIGTERM/SIGHUP."""

import dataclasses
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
from warpcut.io import LOCK_FILE, claim_run_dir, safe_name, write_json
from warpcut.sim.config import SimConfig
from warpcut.viz.process import RecordingError, place_file

SMALL = SimConfig(resolution=13)
ROOT = Path(__file__).resolve().parents[1]
TINY = TrainConfig(num_envs=4, iterations=2, validation_trials=0, es=EsConfig(population=4))
"""es on 4 envs for 2 iterations (one whole cut each), no validation: a policy in a few seconds."""
TINY_FLAGS = ["--set", "train.num_envs=4", "--set", "train.es.population=4", "--set", "sim.resolution=13"]


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
    assert code == 2 and "already holds a run" in output and "--resume" in output and "--overwrite" in output
    assert (out / "results.json").read_bytes() == before
    (out / "stale.txt").write_text("from the earlier run")
    code, output = invoke([*args, "--overwrite"])
    assert code == 0, output
    assert not (out / "stale.txt").exists() and (out / "results.json").is_file()
    code, output = invoke([*args, "--resume", "--overwrite"])
    assert code == 2 and "give one" in output

    mine = tmp_path / "mine"  # a directory warpcut did not write: --overwrite does not empty it
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work")
    code, output = invoke([*args[:-1], str(mine), "--overwrite"])
    assert code == 2 and "does not look like one" in output and (mine / "thesis.tex").is_file()
    code, output = invoke(["evaluate", "--resume", "--contours", "circle-small"])
    assert code == 2 and "--out" in output


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
        (["evaluate", "--set", "train.num_envs=96"], "e.g. train.es.population=48"),
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
    assert code != 0 and "lies off the 100 x 100 mm sheet" in output
    assert not (run / "options.json").exists()  # the env refused the options before the run was written


def test_a_run_directory_is_locked_while_a_process_writes_it(tmp_path):
    out = tmp_path / "run"
    holder = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(f"""
            import sys, time
            from warpcut.io import claim_run_dir
            with claim_run_dir({str(out)!r}):
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
    finally:
        holder.kill()
        holder.wait()
    with claim_run_dir(out, resume=True) as claimed:  # the lock died with its process
        assert (claimed / LOCK_FILE).is_file()
        with claim_run_dir(out):  # a claim inside this process's own claim passes
            pass


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
                "--trials", "2", "--set", "plots=false", "--record", "2",
                "--json", sys.argv[1] + "/results.json"]
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
    with pytest.raises(ValueError, match="already holds a run"):
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
    assert code == 2 and "already holds a run" in output
    code, output = invoke(["train", "--resume", str(run), "--set", "train.es.sigma=0.5"])
    assert code == 2 and "train.es.sigma" in output and "keeps its settings" in output
    code, output = invoke(["train", "--resume", str(run), "--iterations", str(summary["iterations"] + 1),
                           "--no-progress"])  # fmt: skip
    assert code == 0, output
    assert json.loads((run / "summary.json").read_text())["status"] == "completed"


def test_a_failed_write_never_replaces_a_good_file(tmp_path, monkeypatch):
    import errno

    from warpcut.io import DiskFull, write_atomic

    path = write_json(tmp_path / "results.json", {"good": True})

    def no_space(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", no_space)
    with pytest.raises(DiskFull, match=r"results.json: not written, the disk is full; its previous version"):
        write_json(path, {"good": False})
    monkeypatch.undo()
    assert json.loads(path.read_text()) == {"good": True}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.json"]  # no temporary file left
    (tmp_path / "x.json").mkdir()
    with pytest.raises(ValueError, match="x.json: is a directory, not a file"):
        write_atomic(tmp_path / "x.json", b"{}")
    code, output = invoke(["simulate", "--contour", "circle-small", "--json", str(tmp_path / "x.json")])
    assert code == 2 and "is a directory" in output and len(output.strip().splitlines()) == 1


@pytest.mark.parametrize("pinch", ["nan,50", "50,inf", "-inf,-inf"])
def test_a_non_finite_pinch_is_refused(pinch):
    code, output = invoke(["simulate", "--contour", "circle-small", "--pinch", pinch])
    assert code == 2 and "--pinch" in output and "finite" in output
