"""Recordings (.rrd), plots and ``warpcut replay``: small sheets, short runs."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner

from agents.cli import main
from agents.evaluation import compare_policies
from tests.cli_runner import simulate_folder
from warpcut.contours import load_contour
from warpcut.sim.config import SheetGrid, SimConfig
from warpcut.sim.simulator import Simulator
from warpcut.sim.springs import colour_springs
from warpcut.task import CuttingTask
from warpcut.viz import process, rerun_writer
from warpcut.viz.colours import COLOUR_FIELDS, STRAIN_FULL_SCALE, VISIBLE_RGBA, ramp_rgba, vertex_strain
from warpcut.viz.process import PROCESS_NICE, RecordingError
from warpcut.viz.readback import read_summary
from warpcut.viz.recorder import Recorder

RESOLUTION = 9
ENV_ENTITIES = (
    "sheet",
    "contour",
    "tip",
    "cut_path",
    "path",
    "fiducials",
    "path_error_vertices",
    "separated_error_vertices",
)


def invoke(args):
    result = CliRunner().invoke(main, args, standalone_mode=True, catch_exceptions=False)
    return result.exit_code, result.stdout


def num_steps(contour: str, resolution: int = RESOLUTION) -> int:
    return CuttingTask(SimConfig(resolution=resolution), load_contour(contour), device="cpu").num_steps


@pytest.fixture(autouse=True)
def ctrl_c_interrupts():
    """Ctrl-C raises KeyboardInterrupt here, as in a terminal, even when the suite was started with SIGINT
    ignored (a background job of a non-interactive shell is: these tests failed under one)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """One ``simulate --record 2`` run (two trials, two methods) with plots, shared by the tests."""
    out = tmp_path_factory.mktemp("simulate")
    with pytest.MonkeyPatch.context() as patch:  # the figures and recording go into logs/simulate-... here
        patch.chdir(out)
        code, stdout = _simulate_recorded(out)
    assert code == 0, stdout
    return simulate_folder(out), stdout


def _simulate_recorded(out):
    return invoke(
        [
            "simulate",
            "--contour",
            "fls-circle",
            "--policy",
            "none,analytic",
            "--pinch",
            "50,45",
            "--set",
            "allow_infeasible_pinch=true",  # under the arm: the grasp holds the piece being cut
            "--set",
            f"sim.resolution={RESOLUTION}",
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
            "--set",
            f"sim.resolution={RESOLUTION}",
            "--device",
            "cpu",
            "--set",
            "plots=false",
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
        "--set",
        "candidates=3",
    ]
    code, stdout = invoke(
        [*args, "--out", str(tmp_path / "run"), "--set", "record=1", "--set", "colour_by=height"]
    )
    assert code == 0, stdout
    for name in ("improvement.png", "improvement.svg", "recording.rrd", "results.json"):
        assert (tmp_path / "run" / name).stat().st_size > 0, name
    entities = read_summary(tmp_path / "run" / "recording.rrd").entity_paths
    assert "/analytic/env_0/sheet" in entities and "/none/env_0/sheet" in entities
    (info,) = read_columns(tmp_path / "run" / "recording.rrd")[("/none/env_0/info", "TextDocument:text")][0][
        1
    ]
    assert "vertex colours: height" in info

    code, stdout = invoke([*args, "--out", str(tmp_path / "bare"), "--set", "plots=false"])
    assert code == 0, stdout
    written = sorted(p.name for p in (tmp_path / "bare").iterdir())
    assert written == [".warpcut-run.json", "config.json", "plans.json", "results.json", "results.md"]


def test_recording_does_not_change_the_results(tmp_path):
    contour = load_contour("circle-small")
    config = SimConfig(resolution=RESOLUTION, noise_std=0.02)
    kwargs = dict(methods=["none", "analytic"], trials=2, config=config, device="cpu", seed=3)
    plain = compare_policies(contour, **kwargs)
    with Recorder(tmp_path / "r.rrd", envs=2) as recorder:
        recorded = compare_policies(
            contour, **kwargs, step_callbacks=lambda method, first: recorder.step_callback(method)
        )
    assert json.dumps(recorded) == json.dumps(plain)


@pytest.mark.parametrize("background", ["process", "thread", False])
def test_interrupted_run_leaves_a_readable_recording(tmp_path, background):
    task = CuttingTask(SimConfig(resolution=RESOLUTION), load_contour("fls-circle"), device="cpu")
    stop_at = 5

    def policy(task):
        if task.step_index == stop_at:
            raise KeyboardInterrupt
        return None

    path = tmp_path / "recording.rrd"
    with pytest.raises(KeyboardInterrupt), Recorder(path, background=background) as recorder:
        task.run(policy, on_step=recorder.step_callback("fixed"))
    summary = read_summary(path)
    assert summary.frames == stop_at + 1 and summary.last_step == stop_at
    assert "/fixed/env_0/sheet" in summary.entity_paths
    assert sorted(p.name for p in tmp_path.iterdir()) == ["recording.rrd"]


def test_every_kth_step_keeps_the_first_and_last(tmp_path):
    task = CuttingTask(SimConfig(resolution=RESOLUTION), load_contour("circle-small"), device="cpu")
    with Recorder(tmp_path / "r.rrd", every=4) as recorder:
        task.run(None, on_step=recorder.step_callback("none"))
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
    ("viewer", "opened"),
    [
        # rerun's viewer, where DISPLAY is set but no X server answers, says so and ends with status 0.
        (
            "print('Error: winit EventLoopError: Failed to open connection to X server', file=sys.stderr)",
            False,
        ),
        ("sys.exit(3)", False),
        ("time.sleep(4)", True),  # a window opened: it runs on (here for 4 s)
    ],
)
def test_replay_says_when_the_viewer_cannot_open_a_window(simulated, monkeypatch, capfd, viewer, opened):
    from agents.cli import replay

    out, _ = simulated
    monkeypatch.setenv("DISPLAY", ":99")
    monkeypatch.setattr(replay, "VIEWER", [sys.executable, "-c", f"import sys, time; {viewer}"])
    monkeypatch.setattr(replay, "VIEWER_START_S", 1.0)
    with pytest.raises(SystemExit) as exit_info:
        main.main(args=["replay", str(out / "recording.rrd")], prog_name="warpcut")
    captured = capfd.readouterr()
    if opened:
        assert exit_info.value.code == 0 and "opened" in captured.out and not captured.err
    else:
        assert exit_info.value.code == 1
        reason = "Failed to open connection to X server" if "winit" in viewer else "exit code 3"
        assert captured.err.startswith(f"error: the rerun viewer ended at once ({reason})"), captured.err
        assert "/analytic/env_1/sheet" in captured.out and "--web" in captured.out


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


@pytest.fixture(scope="module")
def tiny_recording(tmp_path_factory):
    """A recording of one point at two steps, written with rerun directly (no simulation)."""
    import rerun as rr

    path = tmp_path_factory.mktemp("tiny") / "tiny.rrd"
    stream = rr.RecordingStream("warpcut")
    stream.save(path)
    for step in (0, 1):
        stream.set_time("step", sequence=step)
        stream.log("/point", rr.Points3D([[0.0, 0.0, float(step)]]))
    stream.flush()
    stream.disconnect()
    return path


# A stand-in for rerun's `rerun` command: a wrapper (as rerun_cli is) that starts a server process which,
# like a stubborn one, ignores SIGINT; it notes its arguments and the server's pid.
FAKE_VIEWER = """
import json, os, signal, subprocess, sys
stubborn = "import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); time.sleep(120)"
server = subprocess.Popen([sys.executable, "-c", stubborn])
with open(os.environ["FAKE_VIEWER_NOTE"] + ".tmp", "w") as note:
    json.dump({"argv": sys.argv[1:], "server": server.pid}, note)
os.replace(os.environ["FAKE_VIEWER_NOTE"] + ".tmp", os.environ["FAKE_VIEWER_NOTE"])
sys.exit(server.wait())
"""


def replay_web(path, viewer: list[str] | None, env: dict | None = None) -> subprocess.Popen:
    """``warpcut replay PATH --web`` in a new process, with ``viewer`` as rerun's command (None: rerun's)."""
    driver = textwrap.dedent(
        f"""
        import signal, sys
        signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C as a terminal gives it
        from agents.cli import main, replay
        if {viewer!r} is not None:
            replay.VIEWER = {viewer!r}
        replay.VIEWER_STOP_S = 1.0
        main.main(args=["replay", {str(path)!r}, "--web"], prog_name="warpcut")
        """
    )
    return subprocess.Popen(
        [sys.executable, "-c", driver],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, **(env or {})},
    )


def running(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie, ended but not reaped, does not)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
def test_replay_web_prints_the_recording_url_and_stops_the_server_on_a_signal(
    tmp_path, tiny_recording, signum
):
    from agents.cli.replay import web_url

    note = tmp_path / "viewer.json"
    command = replay_web(
        tiny_recording, [sys.executable, "-c", FAKE_VIEWER], env={"FAKE_VIEWER_NOTE": str(note)}
    )
    deadline = time.monotonic() + 60
    while not note.exists():
        assert command.poll() is None and time.monotonic() < deadline, command.communicate()
        time.sleep(0.05)
    started = json.loads(note.read_text())
    assert running(started["server"])
    command.send_signal(signum)  # to the command alone, as `kill` or a job scheduler sends it
    stdout, stderr = command.communicate(timeout=30)
    assert command.returncode == 128 + signum if signum != signal.SIGINT else 130, stderr
    assert "terminated" in stderr or "interrupted" in stderr
    deadline = time.monotonic() + 10
    while running(started["server"]) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not running(started["server"]), "the viewer's server outlived replay --web"
    # The address that opens the recording, not rerun's Welcome page; and what rerun was asked to do.
    url = "http://127.0.0.1:9090/?url=rerun%2Bhttp%3A%2F%2Flocalhost%3A9876%2Fproxy"
    assert web_url() == url and f"open {url}" in stdout
    assert started["argv"] == [
        "--web-viewer", "--bind", "127.0.0.1", "--server-memory-limit", "1GiB", str(tiny_recording)
    ]  # fmt: skip


def _port_open(port: int) -> bool:
    import socket

    with socket.socket() as probe:
        probe.settimeout(0.5)
        return probe.connect_ex(("127.0.0.1", port)) == 0


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_replay_web_serves_with_rerun_and_frees_its_ports(tiny_recording):
    """rerun's own viewer: the page at the printed address answers, and SIGTERM frees both ports."""
    import urllib.request

    from agents.cli.replay import GRPC_PORT, WEB_PORT, web_url

    if _port_open(WEB_PORT) or _port_open(GRPC_PORT):
        pytest.skip(f"port {WEB_PORT} or {GRPC_PORT} is in use here")
    command = replay_web(tiny_recording, None)
    try:
        deadline = time.monotonic() + 60
        while not (_port_open(WEB_PORT) and _port_open(GRPC_PORT)):
            assert command.poll() is None and time.monotonic() < deadline, command.communicate()
            time.sleep(0.1)
        with urllib.request.urlopen(web_url(), timeout=10) as page:
            assert page.status == 200 and b"<html" in page.read(4096).lower()
    finally:
        command.send_signal(signal.SIGTERM)
        stdout, stderr = command.communicate(timeout=30)
    assert command.returncode == 128 + signal.SIGTERM, stderr
    assert f"open {web_url()}" in stdout
    deadline = time.monotonic() + 10
    while (_port_open(WEB_PORT) or _port_open(GRPC_PORT)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _port_open(WEB_PORT) and not _port_open(GRPC_PORT), "rerun's server outlived replay --web"


def read_columns(path) -> dict[tuple[str, str], list]:
    """Every (entity, component) of a recording as its (step, value) pairs sorted by step; static data
    under step None."""
    from rerun.chunk import RrdReader

    reader = RrdReader(path)
    columns: dict[tuple[str, str], list] = {}
    for chunk in reader.stream(store=reader.recordings()[0]):
        if chunk.entity_path.startswith("/__"):
            continue
        batch = chunk.to_record_batch()
        steps = batch.column("step").to_pylist() if "step" in batch.schema.names else [None] * batch.num_rows
        for name in batch.schema.names:
            if name in ("rerun.controls.RowId", "step", "sim_time"):
                continue
            columns.setdefault((chunk.entity_path, name), []).extend(
                zip(steps, batch.column(name).to_pylist(), strict=True)
            )
    return {
        key: sorted(values, key=lambda sv: -1 if sv[0] is None else sv[0]) for key, values in columns.items()
    }


@pytest.mark.parametrize("backend", ["simd", "colours"])
def test_read_envs_reads_only_the_asked_envs_and_the_same_values(backend):
    sim = Simulator(SimConfig(resolution=RESOLUTION, noise_std=0.05), 11, device="cpu", backend=backend)
    sim.reset(np.full((11, 2), 50.0))
    envs = [10, 0, 8]
    read = sim.state_reader(envs)  # made once, used after every update (as a recorder's step callback does)
    out = np.empty((3, sim.grid.num_vertices, 4), dtype=np.float32)
    for _ in range(3):
        state = read()  # before any update and between updates: the packed state is the current one
        assert read(out) is out and np.array_equal(out, state)
        positions, alive = sim.read_envs(envs)
        assert positions.dtype == np.float32 and alive.dtype == bool
        assert np.array_equal(positions, sim.positions()[envs])
        assert np.array_equal(alive, sim.alive_mask()[envs])
        assert np.array_equal(state[..., :3], positions) and np.array_equal(
            state[..., 3], alive.astype(np.float32)
        )
        assert np.array_equal(read(), state)  # positions() made the unpacked state current: the same values
        sim.set_tip(np.tile([50.0, 50.0, 0.0, 1.0], (11, 1)))
        sim.update()
    assert not alive.all()  # the scissors removed vertices: the masks were compared where it matters
    with pytest.raises(ValueError, match="envs"):
        sim.read_envs([11])
    with pytest.raises(ValueError, match="envs"):
        sim.state_reader([-1])
    with pytest.raises(ValueError, match="out: expected a float32 array of shape"):
        read(np.empty((3, sim.grid.num_vertices, 3), dtype=np.float32))


def test_read_envs_leaves_the_simulation_bit_identical():
    def run(read: bool) -> np.ndarray:
        sim = Simulator(SimConfig(resolution=RESOLUTION, noise_std=0.05), 9, device="cpu", seed=2)
        sim.reset(np.full((9, 2), 40.0))
        for _ in range(4):
            sim.update()
            if read:
                sim.read_envs([0, 8])
        return sim.positions()

    assert np.array_equal(run(True), run(False))


def test_colour_by_is_validated(tmp_path):
    with pytest.raises(ValueError, match="colour_by"):
        Recorder(tmp_path / "r.rrd", colour_by="stress")
    with pytest.raises(ValueError, match="every"):
        Recorder(tmp_path / "r.rrd", every=0)
    assert not list(tmp_path.iterdir())


def test_vertex_strain_is_the_mean_over_live_springs():
    for config in (
        SimConfig(resolution=RESOLUTION),
        SimConfig(resolution=7, springs=("structural", "bending")),
    ):
        grid = SheetGrid.from_config(config)
        rng = np.random.default_rng(0)
        rest = np.column_stack([grid.material, np.zeros(grid.num_vertices)])
        positions = rest[None] + rng.normal(0.0, 0.3, (3, grid.num_vertices, 3))
        alive = rng.random((3, grid.num_vertices)) > 0.2
        expected = np.zeros((3, grid.num_vertices))
        count = np.zeros((3, grid.num_vertices))
        for a, b, length in colour_springs(grid, config.springs):
            for f in range(3):
                live = alive[f, a] & alive[f, b]
                strain = np.abs(np.linalg.norm(positions[f, a] - positions[f, b], axis=1) / length - 1) * live
                for ends in (a, b):
                    np.add.at(expected[f], ends, strain)
                    np.add.at(count[f], ends, live)
        expected /= np.maximum(count, 1)
        got = vertex_strain(positions, alive, grid, config.springs)
        assert got.shape == expected.shape and np.allclose(got, expected, atol=1e-5)
        assert np.all(got[count == 0] == 0.0)
    # A sheet at rest is unstrained.
    assert np.all(
        vertex_strain(rest[None], np.ones((1, grid.num_vertices), bool), grid, config.springs) < 1e-6
    )


@pytest.mark.parametrize("colour_by", ["strain", "height"])
def test_vertex_colours_follow_the_chosen_field(tmp_path, colour_by):
    config = SimConfig(resolution=RESOLUTION)
    task = CuttingTask(
        config, load_contour("circle-small"), device="cpu", pinch_points=np.array([50.0, 50.0]),
        allow_infeasible_pinch=True,
    )  # fmt: skip
    with Recorder(tmp_path / "r.rrd", colour_by=colour_by) as recorder:
        task.run(lambda t: np.array([[0.5, 0.0, 0.0]]), on_step=recorder.step_callback("fixed"))
    columns = read_columns(tmp_path / "r.rrd")
    colours = columns[("/fixed/env_0/sheet", "Mesh3D:vertex_colors")]
    positions = columns[("/fixed/env_0/sheet", "Mesh3D:vertex_positions")]
    assert [s for s, _ in colours] == list(range(task.num_steps + 1))
    last = np.array(positions[-1][1], dtype=np.float32)[None]
    alive = task.sim.alive_mask()
    if colour_by == "strain":
        expected = ramp_rgba(vertex_strain(last, alive, task.grid, config.springs), 0.0, STRAIN_FULL_SCALE)
    else:
        first = np.array(positions[0][1])[:, 2]
        expected = ramp_rgba(last[..., 2], first.min(), max(first.max(), first.min() + 1.0))
    assert np.array_equal(np.array(colours[-1][1], dtype=np.uint32), expected[0])
    (info,) = columns[("/fixed/env_0/info", "TextDocument:text")][0][1]
    assert f"vertex colours: {colour_by}" in info


@pytest.mark.parametrize("colour_by", ["strain", "height"])
def test_the_grasp_is_a_disc_and_the_colours_have_a_legend(tmp_path, colour_by):
    """The grasp: a solid disc of the grasp radius on the grasped vertices, every frame; the colour bar
    (the ramp, low to high) and its meaning, once; the height ramp's ends in the env's info."""
    from warpcut.viz.colours import GRASP_RGB, ramp_image
    from warpcut.viz.rerun_writer import GRASP_DISC_MM

    config = SimConfig(resolution=RESOLUTION)
    task = CuttingTask(
        config, load_contour("circle-small"), device="cpu", pinch_points=np.array([50.0, 50.0]),
        allow_infeasible_pinch=True,
    )  # fmt: skip
    with Recorder(tmp_path / "r.rrd", colour_by=colour_by, background=False) as recorder:
        task.run(lambda t: np.array([[0.5, 0.0, 0.0]]), on_step=recorder.step_callback("fixed"))
    columns = read_columns(tmp_path / "r.rrd")
    disc = "/fixed/env_0/grasp/disc"
    assert columns[(disc, "Cylinders3D:radii")] == [(None, [pytest.approx(config.grasp_radius)])]
    assert columns[(disc, "Cylinders3D:lengths")] == [(None, [GRASP_DISC_MM])]
    (colour,) = columns[(disc, "Cylinders3D:colors")][0][1]
    assert colour == (GRASP_RGB[0] << 24) | (GRASP_RGB[1] << 16) | (GRASP_RGB[2] << 8) | 0xFF
    assert columns[(disc, "Cylinders3D:fill_mode")][0][1] == [3]  # rerun's FillMode.Solid
    centres = columns[(disc, "Cylinders3D:centers")]
    held = columns[("/fixed/env_0/grasp/vertices", "Points3D:positions")]
    assert [s for s, _ in centres] == [s for s, _ in held] == list(range(task.num_steps + 1))
    for (_, (centre,)), (_, vertices) in zip(centres, held, strict=True):
        np.testing.assert_allclose(centre, np.mean(vertices, axis=0), atol=1e-4)
    assert not np.allclose(centres[0][1], centres[-1][1])  # the disc moves with the grasp
    (bar,) = columns[("/legend/colour_bar", "Image:buffer")][0][1]
    assert np.array_equal(np.array(bar, dtype=np.uint8), ramp_image().ravel())
    (legend,) = columns[("/legend/colour_scale", "TextDocument:text")][0][1]
    assert f"Sheet colour: {colour_by}" in legend and "magenta disc" in legend
    assert ("0%" in legend and "5%" in legend) == (colour_by == "strain")
    infos = [text for _, (text,) in columns[("/fixed/env_0/info", "TextDocument:text")]]
    assert any("from z = " in text for text in infos) == (colour_by == "height")


def test_the_recorded_error_is_the_score(tmp_path):
    task = CuttingTask(
        SimConfig(resolution=RESOLUTION),
        load_contour("fls-circle"),
        device="cpu",
        pinch_points=np.array([50.0, 50.0]),
        allow_infeasible_pinch=True,
    )
    with Recorder(tmp_path / "r.rrd") as recorder:
        score = task.run(lambda t: np.array([[0.3, 0.2, 0.0]]), on_step=recorder.step_callback("fixed"))
    columns = read_columns(tmp_path / "r.rrd")
    errors = columns[("/fixed/env_0/separated_error_vertices", "Scalars:scalars")]
    assert [s for s, _ in errors] == list(range(task.num_steps + 1))
    assert errors[-1][1] == [score.separated_error_vertices[0]]
    assert errors[0][1] == [float(score.intended.sum())]  # uncut: nothing separated yet
    path_errors = columns[("/fixed/env_0/path_error_vertices", "Scalars:scalars")]
    assert [s for s, _ in path_errors] == list(range(task.num_steps + 1))
    assert path_errors[-1][1][0] == pytest.approx(score.path_error_vertices[0])
    area = task.contours[0].area_mm2 / task.grid.vertex_area_mm2
    assert path_errors[0][1][0] == pytest.approx(area)  # nothing cut: the path encloses nothing
    strips = columns[("/fixed/env_0/path", "LineStrips3D:strips")]
    last = np.array(strips[-1][1][0])  # every mapped point, in material coordinates on the rest plane
    np.testing.assert_allclose(np.sort(last[:, 0]), np.sort(score.cut_paths[0][:, 0]), atol=1e-4)
    assert np.all(last[:, 2] == 0.0)
    assert ("/fixed/env_0/material_contour", "LineStrips3D:strips") in columns


def test_process_thread_and_inline_recordings_hold_the_same(tmp_path):
    task = CuttingTask(
        SimConfig(resolution=RESOLUTION, noise_std=0.02),
        load_contour("fls-circle"),
        num_envs=3,
        pinch_points=np.array([50.0, 45.0]),
        device="cpu",
        allow_infeasible_pinch=True,
    )
    modes = ("process", "thread", False)
    for background in modes:
        with Recorder(tmp_path / f"{background}.rrd", envs=2, background=background) as recorder:
            task.run(lambda t: np.full((3, 3), 0.2), on_step=recorder.step_callback("fixed"))
            task.run(None, on_step=recorder.step_callback("none"))
    inline = read_columns(tmp_path / "False.rrd")
    assert ("/fixed/env_1/grasp/displacement", "Arrows3D:vectors") in inline
    assert len(inline[("/none/env_0/sheet", "Mesh3D:vertex_positions")]) == task.num_steps + 1
    for background in modes[:-1]:
        assert read_columns(tmp_path / f"{background}.rrd") == inline, background
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(f"{b}.rrd" for b in modes)


def test_the_recorder_process_is_reused(tmp_path):
    task = CuttingTask(SimConfig(resolution=RESOLUTION), load_contour("circle-small"), device="cpu")
    pids = []
    for k in range(2):
        with Recorder(tmp_path / f"{k}.rrd", background="process") as recorder:
            pids.append(recorder._sink.child.process.pid)
            task.run(None, on_step=recorder.step_callback("none"))
        assert read_summary(tmp_path / f"{k}.rrd").frames == task.num_steps + 1
    assert pids[0] == pids[1]


def test_a_failure_in_the_recorder_process_names_the_recording(tmp_path):
    task = CuttingTask(SimConfig(resolution=RESOLUTION), load_contour("circle-small"), device="cpu")
    # The stepping process copies this trajectory as it is; drawing it fails in the recorder process.
    task.trajectories = [SimpleNamespace(tip=np.zeros(4))]
    path = tmp_path / "r.rrd"
    with pytest.raises(RecordingError, match="IndexError: too many indices") as failure:
        with Recorder(path, background="process") as recorder:
            failed = recorder._sink.child.process
            task.run(None, on_step=recorder.step_callback("none"))
    assert str(path) in str(failure.value) and "recorder process failed" in str(failure.value)
    assert read_summary(path).frames == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.rrd"]
    with Recorder(tmp_path / "next.rrd", background="process") as recorder:
        assert recorder._sink.child.process is not failed  # not reused after a failure


def test_a_dead_recorder_process_is_an_error_not_a_hang(tmp_path):
    task = CuttingTask(SimConfig(resolution=RESOLUTION), load_contour("fls-circle"), device="cpu")
    path = tmp_path / "r.rrd"
    with pytest.raises(RecordingError, match="ended unexpectedly") as failure:
        with Recorder(path, background="process") as recorder:
            child = recorder._sink.child.process

            def policy(task):
                if task.step_index == 3:
                    child.kill()
                    child.wait()
                return None

            task.run(policy, on_step=recorder.step_callback("none"))
    assert str(path) in str(failure.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.rrd"]


def test_ctrl_c_reaches_only_the_stepping_process(tmp_path):
    task = CuttingTask(SimConfig(resolution=RESOLUTION), load_contour("fls-circle"), device="cpu")
    with Recorder(tmp_path / "warm.rrd", background="process") as recorder:
        child = recorder._sink.child.process  # started and ready
        task.run(None, on_step=recorder.step_callback("none"))
    stop_at = 5

    def policy(task):
        if task.step_index == stop_at:
            os.kill(child.pid, signal.SIGINT)  # as a terminal would if it ran in the same group
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5.0)  # interrupted at once
        return None

    path = tmp_path / "recording.rrd"
    with pytest.raises(KeyboardInterrupt), Recorder(path, background="process") as recorder:
        assert recorder._sink.child.process is child
        task.run(policy, on_step=recorder.step_callback("fixed"))
    summary = read_summary(path)
    assert summary.frames == stop_at + 1 and summary.last_step == stop_at
    assert "/fixed/env_0/sheet" in summary.entity_paths
    assert child.poll() is None, "the recorder process did not ignore Ctrl-C"


def test_the_recorder_process_finishes_the_file_when_the_stepping_process_dies(tmp_path):
    """Also: recording through the process does not import rerun into the stepping process."""
    script = textwrap.dedent(
        f"""
        import os, sys
        from warpcut.sim.config import SimConfig
        from warpcut.contours import load_contour
        from warpcut.viz.recorder import Recorder
        from warpcut.task import CuttingTask

        task = CuttingTask(SimConfig(resolution={RESOLUTION}), load_contour("circle-small"), device="cpu")
        with Recorder(sys.argv[1] + "/closed.rrd", background="process") as recorder:
            task.run(None, on_step=recorder.step_callback("none"))
        assert "rerun" not in sys.modules, "the stepping process imported rerun"
        recorder = Recorder(sys.argv[1] + "/dead.rrd", background="process")
        task.run(None, on_step=recorder.step_callback("none"))
        os._exit(3)  # dies without closing the recorder
        """
    )
    done = subprocess.run([sys.executable, "-c", script, str(tmp_path)], timeout=120, capture_output=True)
    assert done.returncode == 3, done.stderr.decode()[-2000:]
    assert read_summary(tmp_path / "closed.rrd").frames == num_steps("circle-small") + 1
    deadline = time.monotonic() + 30.0
    while not (tmp_path / "dead.rrd").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert read_summary(tmp_path / "dead.rrd").frames == num_steps("circle-small") + 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["closed.rrd", "dead.rrd"]


def test_a_stepping_process_that_dies_before_recording_leaves_an_earlier_file_alone(tmp_path):
    script = textwrap.dedent(
        """
        import os, sys
        from warpcut.viz.recorder import Recorder

        recorder = Recorder(sys.argv[1] + "/recording.rrd", background="process")
        recorder.step_callback("none")  # made, never called
        os._exit(3)  # dies without closing the recorder
        """
    )
    (tmp_path / "recording.rrd").write_bytes(b"earlier")
    done = subprocess.run([sys.executable, "-c", script, str(tmp_path)], timeout=120, capture_output=True)
    assert done.returncode == 3, done.stderr.decode()[-2000:]
    deadline = time.monotonic() + 30.0
    while len(list(tmp_path.iterdir())) > 1 and time.monotonic() < deadline:  # the process discards its file
        time.sleep(0.05)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["recording.rrd"]
    assert (tmp_path / "recording.rrd").read_bytes() == b"earlier"


@pytest.mark.parametrize("background", ["thread", False])
def test_a_failure_on_the_worker_surfaces_and_the_file_remains(tmp_path, monkeypatch, background):
    def fail(*args, **kwargs):
        raise RuntimeError("boom")

    monkeypatch.setattr(rerun_writer.RerunWriter, "_send_env", fail)
    task = CuttingTask(SimConfig(resolution=RESOLUTION), load_contour("circle-small"), device="cpu")
    path = tmp_path / "r.rrd"
    with pytest.raises(RuntimeError, match="boom"), Recorder(path, background=background) as recorder:
        task.run(None, on_step=recorder.step_callback("none"))
    assert read_summary(path).frames == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.rrd"]


def test_columns_are_the_rerun_archetypes_columns():
    """The writer builds its columns from arrow arrays; they must be what rerun's archetypes build."""
    import rerun as rr

    from warpcut.viz.colours import CUTTING_RGB, CUTTING_RGBA, TRAVEL_RGB, TRAVEL_RGBA
    from warpcut.viz.columns import (
        column,
        cut_path_strips,
        cutting_runs,
        float64_array,
        strip_array,
        triangle_array,
        uint32_array,
        vec3_array,
    )

    rng = np.random.default_rng(0)
    points = rng.normal(size=(2, 5, 3)).astype(np.float32)
    colours = rng.integers(0, 2**32, size=(2, 5), dtype=np.uint32)
    faces = np.array([[0, 1, 2], [2, 3, 4], [1, 2, 3]], dtype=np.uint32)
    scalars = rng.normal(size=(2, 3))
    cutting = np.array([True, False, True, False, False])
    tip = np.column_stack([rng.normal(size=(12, 3)), [0, 1, 1, 1, 0, 0, 1, 1, 1, 1, 0, 1]])
    runs, updates = cutting_runs(tip), np.array([0, 3, 5, 9, 12])
    strips, counts = cut_path_strips(tip, runs, updates)
    cut_so_far = [
        [tip[a : min(b, u), :3] for a, b in runs if min(b, u) - a >= 2] for u in updates
    ]  # what the scissors have cut after each update (runs of two points at least)
    pairs = [
        (
            rr.Mesh3D.columns(
                vertex_positions=points.reshape(-1, 3), vertex_colors=colours.ravel()
            ).partition([5, 5]),
            [
                column("Mesh3D:vertex_positions", vec3_array(points), [5, 5]),
                column("Mesh3D:vertex_colors", uint32_array(colours), [5, 5]),
            ],
        ),
        (
            rr.Mesh3D.columns(triangle_indices=faces).partition([1, 2]),
            [column("Mesh3D:triangle_indices", triangle_array(faces), [1, 2])],
        ),
        (
            rr.Scalars.columns(scalars=scalars[:, 0]),
            [column("Scalars:scalars", float64_array(scalars[:, 0]))],
        ),
        (
            rr.Scalars.columns(scalars=scalars).partition([3, 3]),
            [column("Scalars:scalars", float64_array(scalars), [3, 3])],
        ),
        (rr.LineStrips3D.columns(strips=points), [column("LineStrips3D:strips", strip_array(points))]),
        (
            rr.LineStrips3D.columns(strips=[s for frame in cut_so_far for s in frame]).partition(
                [len(frame) for frame in cut_so_far]
            ),
            [column("LineStrips3D:strips", strips, counts)],
        ),
        (
            rr.Points3D.columns(
                positions=points[0], colors=np.where(cutting[:, None], CUTTING_RGB, TRAVEL_RGB)
            ),
            [
                column("Points3D:positions", vec3_array(points[0])),
                column("Points3D:colors", uint32_array(np.where(cutting, CUTTING_RGBA, TRAVEL_RGBA))),
            ],
        ),
        (
            rr.Points3D.columns(positions=points.reshape(-1, 3)).partition([5, 5]),
            [column("Points3D:positions", vec3_array(points), [5, 5])],
        ),
        (
            rr.Arrows3D.columns(origins=points[0], vectors=points[1]),
            [
                column("Arrows3D:origins", vec3_array(points[0])),
                column("Arrows3D:vectors", vec3_array(points[1])),
            ],
        ),
    ]
    for theirs, ours in pairs:
        theirs = {c.component_descriptor().component: c for c in theirs}
        assert sorted(theirs) == sorted(c.component_descriptor().component for c in ours)
        for built in ours:
            reference = theirs[built.component_descriptor().component]
            assert built.component_descriptor() == reference.component_descriptor()
            assert built.as_arrow_array().equals(reference.as_arrow_array()), reference.component_descriptor()


def test_simulate_says_when_fewer_envs_ran_than_record_asks(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = [
        "simulate",
        "--contour",
        "circle-small",
        "--policy",
        "none",
        "--trials",
        "1",
        "--set",
        "plots=false",
    ]
    args += ["--set", f"sim.resolution={RESOLUTION}", "--device", "cpu", "--json", str(tmp_path / "r.json")]
    result = CliRunner().invoke(main, [*args, "--record", "2"], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    assert "warning: --record 2: fewer envs ran, all of them recorded (none: 1)" in result.stderr
    recording = simulate_folder(tmp_path) / "recording.rrd"
    assert f"wrote {recording}" in result.stdout
    entities = read_summary(recording).entity_paths
    assert "/none/env_0/sheet" in entities and not any(e.startswith("/none/env_1") for e in entities)


def test_cli_colour_choices_are_the_recorders():
    args = ["simulate", "--contour", "circle-small"]
    result = CliRunner().invoke(main, [*args, "--record", "--set", "colour_by=rainbow"])
    choices = ", ".join(COLOUR_FIELDS)
    assert result.exit_code == 2 and f"colour_by: choose one of {choices} (got 'rainbow')" in result.output
    result = CliRunner().invoke(main, [*args, "--set", "colour_by=height"])
    assert result.exit_code == 2 and "colour_by: colours a recording, and record is off" in result.output


def test_recorded_fiducials_are_where_the_env_tracks_them_and_hidden_when_it_cannot_see_them(tmp_path):
    from envs.pattern_cut import PatternCut, PatternCutOptions
    from warpcut.fiducials import sample_fiducials

    scene = PatternCut(
        PatternCutOptions(
            resolution=RESOLUTION,
            device="cpu",
            num_fiducials=40,
            pinch_point=(50.0, 45.0),
            allow_infeasible_pinch=True,
        ),
        num_envs=2,
    )
    world, seen = [], []
    with Recorder(tmp_path / "env.rrd", envs=2, background=False) as recorder:
        callback = recorder.step_callback("env")
        scene.reset(np.random.default_rng(3), resample_fiducials=True)
        for step in range(scene.task.num_steps + 1):
            if step:
                scene.step(np.zeros((2, 3)))  # hold still
            callback(scene.task, None)
            world.append(scene.fiducials.world(scene.task.sim.positions()))
            seen.append(scene.fiducials.visible.copy())
    columns = read_columns(tmp_path / "env.rrd")
    visible_rgba = int(VISIBLE_RGBA)
    for env in (0, 1):
        positions = columns[(f"/env/env_{env}/fiducials", "Points3D:positions")]
        colours = columns[(f"/env/env_{env}/fiducials", "Points3D:colors")]
        assert [s for s, _ in positions] == list(range(scene.task.num_steps + 1))
        for step, (_, points), (_, rgba) in zip(range(len(positions)), positions, colours, strict=True):
            np.testing.assert_allclose(points, world[step][env], atol=1e-3)
            assert [c == visible_rgba for c in rgba] == seen[step][env].tolist()
    hidden = ~np.array(seen)
    assert hidden.any() and not hidden.all()  # the scissors hid some of the 40 fiducials, not all

    # A task without an env's fiducials (a baseline): the recording draws them as an env would.
    task = CuttingTask(SimConfig(resolution=RESOLUTION), load_contour("fls-circle"), device="cpu")
    with Recorder(tmp_path / "task.rrd", background=False) as recorder:
        task.run(None, on_step=recorder.step_callback("none"))
    first = read_columns(tmp_path / "task.rrd")[("/none/env_0/fiducials", "Points3D:positions")][0][1]
    expected = sample_fiducials(
        np.random.default_rng(0), 12, task.contours, np.full((1, 2), np.nan), task.config
    )
    settled = CuttingTask(SimConfig(resolution=RESOLUTION), load_contour("fls-circle"), device="cpu")
    settled.reset()
    from warpcut.task import material_to_world

    np.testing.assert_allclose(
        first, material_to_world(expected[0], settled.sim.positions()[0], task.grid), atol=1e-3
    )


@pytest.mark.parametrize("background", ["process", "thread", False])
def test_a_recorder_that_recorded_nothing_leaves_an_earlier_file_alone(tmp_path, background):
    # E.g. `train --resume DIR --record` interrupted during training, before its recorded evaluation.
    task = CuttingTask(SimConfig(resolution=RESOLUTION), load_contour("circle-small"), device="cpu")
    path = tmp_path / "recording.rrd"
    with Recorder(path, background=background) as recorder:
        task.run(None, on_step=recorder.step_callback("none"))
    assert recorder.written and recorder.close() == path
    before = path.read_bytes()
    with pytest.raises(KeyboardInterrupt), Recorder(path, background=background) as recorder:
        recorder.step_callback("rl")  # made, never called
        raise KeyboardInterrupt
    assert not recorder.written and recorder.close() is None
    assert path.read_bytes() == before

    # Interrupted while the episode starts (here: copying what its frames are drawn with).
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    task.sim.state_reader = interrupted
    with pytest.raises(KeyboardInterrupt), Recorder(path, background=background) as recorder:
        task.run(None, on_step=recorder.step_callback("rl"))
    assert not recorder.written and recorder.recorded_envs == {}
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["recording.rrd"]  # no temporary file left


def test_a_started_recorder_process_is_taken_by_the_next_recorder(tmp_path):
    if process.default_background() != "process":
        pytest.skip("recorders use no process here (not POSIX, or one core)")
    assert process.start_recorder_process()
    waiting = [c for c in process.RecorderProcess._idle if c.process.poll() is None]
    assert waiting
    assert process.start_recorder_process()  # one is waiting already: no second one
    assert [c for c in process.RecorderProcess._idle if c.process.poll() is None] == waiting
    recorder = Recorder(tmp_path / "r.rrd")
    assert recorder._sink.child is waiting[-1]
    assert recorder.close() is None  # nothing recorded: no file
    # It has imported what it needs (at the caller's priority) and serves at a lower one.
    pid = recorder._sink.child.process.pid
    expected = min(os.getpriority(os.PRIO_PROCESS, 0) + PROCESS_NICE, 19)  # 19: the lowest there is
    assert os.getpriority(os.PRIO_PROCESS, pid) == expected


def test_the_cli_starts_the_recorder_process_before_importing_anything_slow():
    # The CLI starts the recorder process first thing (warpcut.viz.process): its start-up overlaps
    # the command's only if starting it needs none of what the process itself imports.
    code = "import json, sys, warpcut.viz.process; print(json.dumps(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    loaded = set(json.loads(out))
    assert "warpcut.viz.process" in loaded
    assert not loaded & {"warpcut.viz.recorder", "warpcut.viz.transport", "warpcut.viz.rerun_writer"}
    assert not {m.split(".")[0] for m in loaded} & {"scipy", "rerun", "pyarrow", "shapely", "warp", "torch"}


def test_the_recorder_process_and_the_cli_start_without_warp():
    # Warp is slow to import: the recorder process (warpcut.viz.process and the writer it serves with) and
    # the CLI's start-up, which starts that process, do without it until a simulator is made.
    code = "import sys, agents.cli, warpcut.viz.process, warpcut.viz.recorder; print('warp' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


@pytest.mark.skipif(not hasattr(os, "killpg"), reason="process groups")
def test_a_signal_while_the_viewer_starts_still_stops_it(tmp_path, tiny_recording, monkeypatch):
    """Ctrl-C arriving inside ``Popen``, after the viewer started but before ``replay --web`` holds its
    process (a race a slow machine hit): the interrupt is held back until the viewer can be stopped, then
    raised, and the viewer's server does not outlive the command."""
    from agents.cli import replay

    note = tmp_path / "viewer.json"
    monkeypatch.setenv("FAKE_VIEWER_NOTE", str(note))
    monkeypatch.setattr(replay, "VIEWER_STOP_S", 0.5)
    popen = subprocess.Popen

    def started_then_interrupted(*args, **kwargs):
        process = popen(*args, **kwargs)
        deadline = time.monotonic() + 60
        while not note.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        os.kill(os.getpid(), signal.SIGINT)  # handled at the next bytecode: still inside Popen
        time.sleep(0.2)
        return process

    monkeypatch.setattr(replay.subprocess, "Popen", started_then_interrupted)
    try:
        with pytest.raises(KeyboardInterrupt):
            replay.serve_web(tiny_recording, [sys.executable, "-c", FAKE_VIEWER])
        server = json.loads(note.read_text())["server"]
        deadline = time.monotonic() + 10
        while running(server) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not running(server), "the viewer's server outlived replay --web"
    finally:
        if note.exists() and running(server := json.loads(note.read_text())["server"]):
            os.kill(server, signal.SIGKILL)
