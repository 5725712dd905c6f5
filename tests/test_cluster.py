"""Fanning work out over Ray (``--ray``, :mod:`agents.cluster`, :mod:`agents.shards`): on a local cluster of
two workers, the same rows and policies as in one process, a worker killed mid-unit retried, an env actor
killed mid-episode made again where it was, Ctrl-C then ``--resume``; and without ``--ray``, no Ray."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from agents.cluster import RayCluster, Serial, executor, parse_address, same_results
from agents.config import TrainConfig
from agents.es.config import EsConfig
from agents.jobs import EvaluateJob, RobustnessJob
from agents.pipelines import evaluate_table, robustness
from warpcut.sim.config import SimConfig

pytestmark = pytest.mark.usefixtures("one_torch_thread")

SMALL = SimConfig(resolution=13)


@pytest.fixture(scope="module")
def cluster():
    """A local Ray instance of two workers for the module (each test's units run on it)."""
    pytest.importorskip("ray")
    from ray import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # this module's units, for the workers
    ray_cluster = RayCluster("local", 2, "cpu", lambda _: None)
    yield ray_cluster
    ray_cluster.close()


def _job(**changes) -> EvaluateJob:
    settings = dict(
        contours=["fls-circle", "kidney", "wave-1"], methods=["none", "fixed", "analytic", "rl"], trials=3,
        sim=SMALL, candidates=4,
        train=TrainConfig(algo="es", num_envs=16, iterations=3, es=EsConfig(population=8)),
    )  # fmt: skip
    return EvaluateJob(**(settings | changes))


def _rows(report_or_path) -> list[dict]:
    table = (
        report_or_path.table
        if hasattr(report_or_path, "table")
        else json.loads(Path(report_or_path).read_text())
    )
    return [same_results(row) for row in table["rows"]]


def _weights(run: Path) -> dict[str, torch.Tensor]:
    return torch.load(run / "best.pt", weights_only=False)["actor_state_dict"]


def test_parse_address_takes_local_auto_and_host_port_and_names_a_bad_one():
    assert parse_address(None) == (None, None)
    assert parse_address("local") == ("local", None) and parse_address("local:3") == ("local", 3)
    assert parse_address("auto") == ("auto", None)
    assert parse_address("10.0.0.2:6379") == ("10.0.0.2:6379", None)
    for bad in ("local:0", "local:x", "nowhere", "host:99999", ":6379"):
        with pytest.raises(ValueError, match=r"^--ray: .*HOST:PORT"):
            parse_address(bad)
    assert parse_address("[::1]:6379") == ("[::1]:6379", None)  # IPv6, in brackets as in a URL
    with pytest.raises(ValueError, match=r"an IPv6 address goes in brackets, \[HOST\]:PORT"):
        parse_address("::1:6379")


def test_an_ipv6_address_is_reached_as_one(monkeypatch):
    """``[::1]:6379`` is tried as the IPv6 host ``::1``, not looked up as a name (said to be unknown)."""
    import socket

    from agents import cluster

    tried = []

    def connect(address, timeout):
        tried.append(address)
        raise ConnectionRefusedError(111, "Connection refused")

    monkeypatch.setattr(socket, "create_connection", connect)
    with pytest.raises(
        ValueError, match=r"--ray \[::1\]:6379: no Ray cluster answers there \(Connection refused\)"
    ):
        cluster._check_reachable("[::1]:6379")
    assert tried == [("::1", 6379)]


def test_without_ray_the_command_never_imports_ray(tmp_path):
    code = (
        "import sys; from agents.cli import main\n"
        "try:\n"
        f"    main(['evaluate', '--contours', 'fls-circle', '--methods', 'none,fixed', '--trials', '2', "
        f"'--set', 'plan=false', '--set', 'plots=false', '--set', 'sim.resolution=13', '--out', "
        f"{str(tmp_path / 'e')!r}])\n"
        "except SystemExit as stop:\n"
        "    assert stop.code == 0, stop.code\n"
        "assert 'ray' not in sys.modules, 'ray imported'\n"
        "print('no ray')\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and "no ray" in done.stdout, done.stderr[-2000:]


def test_an_address_nobody_answers_at_is_one_line_naming_it(tmp_path):
    pytest.importorskip("ray")
    done = subprocess.run(
        [sys.executable, "-m", "warpcut", "robustness", "--contour", "fls-circle", "--study", "noise",
         "--ray", "127.0.0.1:9", "--out", str(tmp_path / "r")],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert (
        lines[0].startswith("error: --ray 127.0.0.1:9: no Ray cluster answers there")
        and "ray start" in lines[0]
    )


def test_ray_where_nothing_fans_out_or_at_a_bad_address_is_refused_in_one_line(tmp_path, capfd):
    from cli_runner import refused

    out = ["--out", str(tmp_path / "o")]
    assert "--policy fixed trains nothing to fan out" in refused(
        ["run", "--policy", "fixed", "--ray", "local", *out], capfd
    )
    line = refused(
        ["evaluate", "--methods", "none,fixed", "--set", "plan=false", "--ray", "local", *out], capfd
    )
    assert "nothing to fan out" in line
    assert "'here' is not an address" in refused(
        ["robustness", "--contour", "kidney", "--ray", "here", *out], capfd
    )
    assert not (tmp_path / "o").exists()


def test_evaluate_gives_the_same_rows_and_policies_on_two_workers(tmp_path, cluster):
    """none, fixed, analytic and the default learner: rows and trained policies bit for bit; each row
    says where its units ran; the run directory holds the same files and its marker lists them."""
    serial = evaluate_table(_job(), tmp_path / "serial")
    fanned = evaluate_table(_job(), tmp_path / "ray", cluster=cluster)
    assert _rows(fanned) == _rows(serial)
    assert fanned.table["mean"] == serial.table["mean"]
    here = f"{os.uname().nodename}:{os.getpid()}"
    assert all(set(r["ran_on"].values()) == {here} for r in serial.table["rows"])
    workers = {r["ran_on"]["rl"] for r in fanned.table["rows"]} | {
        r["ran_on"]["planning"] for r in fanned.table["rows"]
    }
    assert here not in workers and all(r["ran_on"]["evaluation"] == here for r in fanned.table["rows"])
    for name in ("fls-circle", "kidney", "wave-1"):
        a, b = _weights(tmp_path / "serial/policies" / name), _weights(tmp_path / "ray/policies" / name)
        assert all(torch.equal(a[k], b[k]) for k in a), name

    def files(root: Path) -> set[str]:
        names = {str(p.relative_to(root)) for p in root.rglob("*") if p.is_file()}
        return {n.split("events.out")[0] + "events" if "events.out" in n else n for n in names}

    assert files(tmp_path / "ray") == files(tmp_path / "serial")
    marker = json.loads((tmp_path / "ray/.warpcut-run.json").read_text())
    assert {f for f in files(tmp_path / "ray") if f.startswith("policies/")} <= {
        n.split("events.out")[0] + "events" if "events.out" in n else n for n in marker["files"]
    }


def test_robustness_gives_the_same_report_on_two_workers(tmp_path, cluster):
    job = RobustnessJob(
        contour="kidney", study=["noise"], values=[0.0, 0.06], trials=3, sim=SMALL, plots=False
    )
    (serial,) = robustness(job, tmp_path / "serial")
    (fanned,) = robustness(job, tmp_path / "ray", cluster=cluster)
    differ = {k for k in serial if serial[k] != fanned[k]}
    assert differ == {"ran_on", "seconds"}, differ
    assert set(fanned["ran_on"]) == {"none", "fixed", "analytic"}


def _dies_on_its_first_try(marker: Path) -> int:
    """A unit whose worker is killed (SIGKILL) the first time it runs it."""
    tries = marker.with_suffix(".tries")
    count = int(tries.read_text()) + 1 if tries.exists() else 1
    tries.write_text(str(count))
    if count == 1:
        os.kill(os.getpid(), signal.SIGKILL)
    return count


def test_a_unit_whose_worker_dies_is_retried_and_the_run_completes(tmp_path, cluster):
    made = cluster.map(_dies_on_its_first_try, [tmp_path / "a", tmp_path / "b"])
    assert [unit.value for unit in made] == [2, 2]


def _slow_unit(k: int) -> int:
    import time

    time.sleep(0.2 if k == 0 else 60)
    return k


def test_ctrl_c_cancels_the_units_still_running(cluster):
    def interrupt(k, unit):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        cluster.map(_slow_unit, [0, 1, 2], done=interrupt)
    # the cluster is free again at once: the 60-second units were cancelled
    assert [unit.value for unit in cluster.map(_slow_unit, [0])] == [0]


def test_an_interrupted_fanned_out_evaluate_resumes_to_the_same_rows(tmp_path, cluster):
    """Ctrl-C once the first policy is trained: that policy is in the run directory, and --resume (here
    in one process) keeps it and gives the rows of a run never stopped."""
    job = _job(contours=["fls-circle", "kidney"], methods=["fixed", "rl"])
    whole = evaluate_table(job, tmp_path / "whole")

    def stop(stage: str, done: int, total: int) -> None:
        if stage == "training rl" and done == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        evaluate_table(job, tmp_path / "stopped", cluster=cluster, stages=stop)
    trained = [p.parent.name for p in (tmp_path / "stopped/policies").glob("*/summary.json")]
    assert len(trained) == 1
    resumed = evaluate_table(job, tmp_path / "stopped", resume=True)
    assert _rows(resumed) == _rows(whole)


def test_the_sharded_env_steps_as_the_whole_batch_even_when_an_actor_dies(cluster):
    """Parts of whole es policies (3 contours each) on two actors: observations, rewards, dones and
    episode costs as one env of the whole batch gives them, through an episode end; an actor killed
    mid-episode is made again where it was."""
    import ray

    from agents.shards import ShardedEnv
    from agents.training import training_env
    from envs.options import PatternCutOptions
    from envs.rsl import EPISODE_COST_KEY

    contours = ["fls-circle", "kidney", "wave-1"] * 4
    options = PatternCutOptions(contour=contours, sim_config=SMALL, lookahead=8, randomize=("gravity",))
    whole = training_env(options, TrainConfig(num_envs=12), seed=5)
    parts = ShardedEnv(options, 12, cluster, group=3, seed=5)
    for env in (whole, parts):
        env.common_sheets = 4
        env.seed(7)
    assert torch.equal(whole.get_observations()["policy"], parts.get_observations()["policy"])
    rng, ended = np.random.default_rng(0), 0
    for step in range(whole.max_episode_length + 2):
        if step == 5:
            ray.kill(parts.shards[1])
        actions = torch.as_tensor(rng.uniform(-1, 1, (12, 3)), dtype=torch.float32)
        a, b = whole.step(actions), parts.step(actions)
        for x, y in zip(a[:3], b[:3], strict=True):
            assert torch.equal(
                x["policy"] if hasattr(x, "keys") else x, y["policy"] if hasattr(y, "keys") else y
            )
        assert (EPISODE_COST_KEY in a[3]) == (EPISODE_COST_KEY in b[3])
        if EPISODE_COST_KEY in a[3]:
            ended += 1
            assert torch.equal(a[3][EPISODE_COST_KEY], b[3][EPISODE_COST_KEY])
            assert all(torch.equal(a[3]["log"][k], b[3]["log"][k]) for k in a[3]["log"])
    assert ended == 1 and parts.revived == 1
    parts.close()


def test_serial_is_what_every_pipeline_ran_before():
    with executor(None) as units:
        assert isinstance(units, Serial) and units.address is None
        assert [unit.value for unit in units.map(abs, [-1, 2])] == [1, 2]


def test_warpcut_cpu_threads_caps_the_simulators_threads_and_names_a_bad_value(monkeypatch):
    from warpcut.cores import CORES_VARIABLE, cpu_cores
    from warpcut.sim.simulator import Simulator

    monkeypatch.setenv(CORES_VARIABLE, "1")
    assert cpu_cores() == 1 and Simulator(SMALL, 64, device="cpu").threads == 1
    monkeypatch.setenv(CORES_VARIABLE, "two")
    with pytest.raises(ValueError, match=rf"^{CORES_VARIABLE}: must be a positive integer"):
        cpu_cores()
    monkeypatch.delenv(CORES_VARIABLE)
    assert cpu_cores() == len(os.sched_getaffinity(0))


def _unit_threads(_: int) -> tuple[int, int]:
    from warpcut.cores import cpu_cores

    return torch.get_num_threads(), cpu_cores()


def test_a_unit_runs_torch_on_the_drivers_threads_and_the_simulator_on_its_cpu(cluster):
    """torch's forward pass can differ in the last bit with its thread count (a trained es policy on
    ellipse-tilted, 10 envs, 1 thread against 2: one move of one env at one step), so a unit runs torch on
    the driver's threads, and its results are a serial run's; the simulator steps on the unit's CPU."""
    threads = torch.get_num_threads()
    try:
        for count in (2, 1):
            torch.set_num_threads(count)
            assert [unit.value for unit in cluster.map(_unit_threads, [0, 1])] == [(count, 1)] * 2
    finally:
        torch.set_num_threads(threads)


def test_sigterm_stops_a_fanned_out_evaluate_and_its_ray_instance(tmp_path):
    """The command line end to end: SIGTERM while the policies train on a local cluster ends the command
    with the interrupted message (no traceback) and stops its Ray instance (resuming after an interruption:
    test_an_interrupted_fanned_out_evaluate_resumes_to_the_same_rows)."""
    import time

    pytest.importorskip("ray")
    out = tmp_path / "e"
    args = [sys.executable, "-m", "warpcut", "evaluate", "--contours", "fls-circle,kidney",
            "--methods", "fixed,rl", "--trials", "2", "--set", "sim.resolution=13", "--set", "candidates=4",
            "--set", "train.iterations=10", "--set", "train.num_envs=16", "--set", "train.algo=es",
            "--set", "train.es.population=8",
            "--set", "plots=false", "--out", str(out)]  # fmt: skip

    def raylets() -> set[str]:
        return set(subprocess.run(["pgrep", "-f", "raylet"], capture_output=True, text=True).stdout.split())

    before = raylets()  # another instance (this module's) stays
    env = {k: v for k, v in os.environ.items() if k != "RAY_AUTH_MODE"}  # as a user's shell has it
    proc = subprocess.Popen(
        [*args, "--ray", "local:2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
    )
    deadline = time.monotonic() + 120
    while not (out / "plans.json").is_file() and time.monotonic() < deadline:
        time.sleep(0.2)
    time.sleep(1)  # the policies are training on the workers
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, err[-2000:]
    assert "Traceback" not in err and "terminated (SIGTERM)" in err and "--resume" in err, err[-2000:]
    assert "Token authentication" not in err  # Ray's notice of its own default: not the command's news
    time.sleep(1)
    assert raylets() <= before, "the command's Ray instance outlived it"
    assert (out / "plans.json").is_file() and (out / ".warpcut-run.json").is_file()  # resumable


def test_a_ray_that_does_not_start_is_one_line(monkeypatch):
    """A head that fails to start, or refuses the driver's token, is said in one line, not Ray's traceback."""
    ray = pytest.importorskip("ray")

    def fail(**_):
        raise RuntimeError("Failed to start GCS.  Last 0 lines of error files:\n\nmore")

    monkeypatch.setattr(ray, "init", fail)
    with pytest.raises(
        ValueError, match=r"^--ray local: Ray did not start \(RuntimeError: Failed to start GCS"
    ) as e:
        RayCluster("local", 2, "cpu", lambda _: None)
    assert "\n" not in str(e.value)
