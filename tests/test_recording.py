"""Recordings (.rrd), plots and ``warpcut replay``: small sheets, short runs."""

import json
import sys

import pytest
from click.testing import CliRunner

from agents.evaluation import compare_policies
from warpcut.cli import main
from warpcut.config import SimConfig
from warpcut.contours import load_contour
from warpcut.recording import Recorder, read_summary
from warpcut.task import CuttingTask

RESOLUTION = 9
ENV_ENTITIES = ("sheet", "contour", "tip", "cut_path", "error_vertices")


def invoke(args):
    result = CliRunner().invoke(main, args, standalone_mode=True, catch_exceptions=False)
    return result.exit_code, result.stdout


def num_steps(contour: str, resolution: int = RESOLUTION) -> int:
    return CuttingTask(SimConfig(resolution=resolution), load_contour(contour), device="cpu").num_steps


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """One ``simulate --record 2`` run (two trials, two methods) with plots, shared by the tests."""
    out = tmp_path_factory.mktemp("simulate")
    code, stdout = invoke(
        [
            "simulate",
            "--contour",
            "fls-circle",
            "--policy",
            "none,analytic",
            "--pinch",
            "50,45",
            "--resolution",
            str(RESOLUTION),
            "--trials",
            "2",
            "--device",
            "cpu",
            "--json",
            str(out / "results.json"),
            "--record",
            "2",
        ]
    )
    assert code == 0, stdout
    return out, stdout


def test_simulate_record_reads_back_per_method(simulated):
    out, stdout = simulated
    path = out / "recording.rrd"
    assert f"wrote {path}" in stdout
    summary = read_summary(path)
    steps = num_steps("fls-circle")
    assert summary.frames == steps + 1
    assert (summary.first_step, summary.last_step) == (0, steps)
    assert summary.duration_s == pytest.approx(steps * 2 * 0.016, rel=1e-3)
    for method in ("none", "analytic"):
        for env in (0, 1):
            for entity in ENV_ENTITIES:
                assert f"/{method}/env_{env}/{entity}" in summary.entity_paths
    assert "/analytic/env_0/grasp/disc" in summary.entity_paths
    assert "/analytic/env_0/grasp/displacement" in summary.entity_paths
    assert "/none/env_0/grasp/disc" not in summary.entity_paths
    assert not list(out.glob(".*.tmp")), "the temporary file was left behind"


def test_simulate_plots_are_written(simulated):
    out, _ = simulated
    png, svg = out / "regions.png", out / "regions.svg"
    assert png.read_bytes().startswith(b"\x89PNG\r\n\x1a\n") and png.stat().st_size > 1000
    assert "<svg" in svg.read_text()[:1000]


def test_no_plots_writes_none(tmp_path):
    code, stdout = invoke(
        [
            "simulate",
            "--contour",
            "circle-small",
            "--policy",
            "none",
            "--resolution",
            str(RESOLUTION),
            "--device",
            "cpu",
            "--no-plots",
            "--json",
            str(tmp_path / "results.json"),
        ]
    )
    assert code == 0, stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.json"]


def test_evaluate_writes_the_comparison_plot_and_recording(tmp_path):
    args = [
        "evaluate",
        "--contours",
        "circle-small",
        "--methods",
        "none,analytic",
        "--trials",
        "1",
        "--candidates",
        "3",
    ]
    code, stdout = invoke([*args, "--out", str(tmp_path / "run"), "--record"])
    assert code == 0, stdout
    for name in ("improvement.png", "improvement.svg", "recording.rrd", "results.json"):
        assert (tmp_path / "run" / name).stat().st_size > 0, name
    entities = read_summary(tmp_path / "run" / "recording.rrd").entity_paths
    assert "/analytic/env_0/sheet" in entities and "/none/env_0/sheet" in entities

    code, stdout = invoke([*args, "--out", str(tmp_path / "bare"), "--no-plots"])
    assert code == 0, stdout
    assert sorted(p.name for p in (tmp_path / "bare").iterdir()) == ["plans.json", "results.json"]


def test_recording_does_not_change_the_results(tmp_path):
    contour = load_contour("circle-small")
    config = SimConfig(resolution=RESOLUTION, noise_std=0.02)
    kwargs = dict(methods=["none", "analytic"], trials=2, config=config, device="cpu", seed=3)
    plain = compare_policies(contour, **kwargs)
    with Recorder(tmp_path / "r.rrd", envs=2) as recorder:
        recorded = compare_policies(contour, **kwargs, on_step=recorder.on_step)
    assert json.dumps(recorded) == json.dumps(plain)


def test_interrupted_run_leaves_a_readable_recording(tmp_path):
    task = CuttingTask(SimConfig(resolution=RESOLUTION), load_contour("fls-circle"), device="cpu")
    stop_at = 5

    def policy(task):
        if task.step_index == stop_at:
            raise KeyboardInterrupt
        return None

    path = tmp_path / "recording.rrd"
    with pytest.raises(KeyboardInterrupt), Recorder(path) as recorder:
        task.run(policy, on_step=recorder.on_step("fixed"))
    summary = read_summary(path)
    assert summary.frames == stop_at + 1 and summary.last_step == stop_at
    assert "/fixed/env_0/sheet" in summary.entity_paths
    assert sorted(p.name for p in tmp_path.iterdir()) == ["recording.rrd"]


def test_every_kth_step_keeps_the_first_and_last(tmp_path):
    task = CuttingTask(SimConfig(resolution=RESOLUTION), load_contour("circle-small"), device="cpu")
    with Recorder(tmp_path / "r.rrd", every=4) as recorder:
        task.run(None, on_step=recorder.on_step("none"))
    summary = read_summary(tmp_path / "r.rrd")
    assert summary.frames == len(set(range(0, task.num_steps, 4)) | {task.num_steps})
    assert summary.last_step == task.num_steps


@pytest.mark.skipif(sys.platform in ("darwin", "win32"), reason="a display is assumed there")
def test_replay_without_a_display_prints_how_and_a_summary(simulated, monkeypatch):
    out, _ = simulated
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    code, stdout = invoke(["replay", str(out / "recording.rrd")])
    assert code == 0, stdout
    assert "no display" in stdout and "--web" in stdout
    assert f"{num_steps('fls-circle') + 1} frames" in stdout
    assert "/analytic/env_1/sheet" in stdout


@pytest.mark.parametrize(
    ("content", "message"), [(None, "no such recording"), (b"not a recording", "not a readable rerun")]
)
def test_replay_of_a_missing_or_bad_file_exits_2_with_one_line(tmp_path, capfd, content, message):
    path = tmp_path / "x.rrd"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(SystemExit) as exit_info:
        main.main(args=["replay", str(path)], prog_name="warpcut")
    assert exit_info.value.code == 2
    err = [line for line in capfd.readouterr().err.strip().splitlines() if "Warp CUDA warning" not in line]
    assert len(err) == 1 and err[0].startswith("error: ") and message in err[0], err
