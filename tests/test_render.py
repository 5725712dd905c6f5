"""Rendering: the envs' ``render_mode``, gymnasium's ``RecordVideo``, the video step callback and
``--video`` (small sheets, short cuts)."""

import warnings

import gymnasium as gym
import imageio_ffmpeg
import numpy as np
import pytest
from click.testing import CliRunner
from gymnasium.utils.env_checker import check_env
from gymnasium.wrappers import RecordVideo
from gymnasium.wrappers.vector import RecordVideo as VectorRecordVideo

from agents.cli import main
from agents.cli.video import with_videos
from envs import ENV_ID, PatternCutEnv, PatternCutVecEnv
from tests.cli_runner import simulate_folder
from warpcut.contours import load_contour
from warpcut.sim.config import SimConfig
from warpcut.task import CuttingTask
from warpcut.viz import render
from warpcut.viz.colours import CUTTING_RGB
from warpcut.viz.render import BACKGROUND_RGB, CONTOUR_RGB, GRASP_RGB, TaskRenderer
from warpcut.viz.video import VideoRecorder

SMALL = {"contour": "circle-small", "resolution": 9, "device": "cpu"}
"""A 9 x 9 sheet and a 94 mm contour: 48 steps per episode."""
STEPS = 48
HOLD = np.zeros(3, dtype=np.float32)
"""The env's default action (continuous x-y-z moves): hold still."""


def pixels_of(image: np.ndarray, rgb) -> int:
    return int(np.all(image == np.array(rgb, dtype=np.uint8), axis=-1).sum())


def frames_in(path, size=(256, 256)) -> int:
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    assert meta["size"] == size
    return sum(1 for _ in reader)


def test_rgb_array_shows_the_sheet_contour_grasp_and_the_cut_so_far():
    env = gym.make(ENV_ID, render_mode="rgb_array", **SMALL)
    assert env.metadata["render_fps"] == 31  # one frame per 2 updates of 16 ms: simulated time
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)  # the render check included
    env.reset(seed=0)
    first = env.render()
    assert first.shape == (256, 256, 3) and first.dtype == np.uint8
    assert pixels_of(first, CONTOUR_RGB) > 50 and pixels_of(first, GRASP_RGB) > 50
    assert pixels_of(first, CUTTING_RGB) < 60  # only the tip's dot
    for _ in range(STEPS // 2):
        env.step(np.array([1.0, 0.0, 0.0], dtype=np.float32))  # +x, a step's longest move
    half = env.render()
    assert pixels_of(half, CUTTING_RGB) > pixels_of(first, CUTTING_RGB) + 30  # the path cut so far
    assert pixels_of(half, BACKGROUND_RGB) > pixels_of(first, BACKGROUND_RGB)  # the cut opens the mesh
    other = PatternCutEnv(
        render_mode="rgb_array", render_size=(160, 96), render_view="three-quarter", **SMALL
    )
    other.reset(seed=0)
    assert other.render().shape == (96, 160, 3)


@pytest.mark.usefixtures("unbounded_noise")
def test_renderer_options_and_diverged_sheets():
    task = CuttingTask(SimConfig(resolution=9, noise_std=[0.0, 1e30]), load_contour("circle-small"), 2)
    task.reset()
    task.step()
    assert task.diverged().tolist() == [False, True]
    images = TaskRenderer(task, envs=2, size=64, colour_by="height").render()
    assert images.shape == (2, 64, 64, 3)
    assert pixels_of(images[1], BACKGROUND_RGB) > 0.9 * 64 * 64  # drawn as a blank sheet saying so
    assert TaskRenderer(task, envs=[1]).render().shape == (1, 256, 256, 3)
    for kwargs, message in [
        ({"envs": 3}, "envs: draw 1 to 2"),
        ({"size": 8}, "size: the image width"),
        ({"size": "big"}, "size: give N or"),
        ({"view": "side"}, "view: choose one of"),
        ({"colour_by": "mood"}, "colour_by: choose one of"),
    ]:
        with pytest.raises(ValueError, match=message):
            TaskRenderer(task, **kwargs)


def test_no_render_mode_costs_nothing_and_render_warns(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("a renderer was built without a render mode")

    monkeypatch.setattr(render, "TaskRenderer", refuse)
    env = PatternCutEnv(**SMALL)
    env.reset(seed=0)
    env.step(HOLD)
    with pytest.warns(UserWarning, match="without a render_mode"):
        assert env.render() is None


def test_human_mode_needs_a_display(monkeypatch):
    monkeypatch.setattr(render, "display_available", lambda: False)
    with pytest.raises(ValueError, match="render_mode: 'human' needs a display"):
        gym.make(ENV_ID, render_mode="human", **SMALL)
    for kwargs, message in [
        ({"render_mode": "ansi"}, "render_mode: choose one of"),
        ({"render_mode": "rgb_array", "render_size": 0}, "render_size: the image width"),
        ({"render_mode": "rgb_array", "render_view": "side"}, "render_view: choose one of"),
    ]:
        with pytest.raises(ValueError, match=message):
            PatternCutEnv(**kwargs, **SMALL)
    # Where there is a display, every reset and step shows the frame in the window.
    shown = []

    class Window:
        def __init__(self, title):
            pass

        def show(self, image, fps):
            shown.append((image.shape, fps))

        def close(self):
            shown.append("closed")

    monkeypatch.setattr(render, "check_human_rendering", lambda: None)
    monkeypatch.setattr(render, "Window", Window)
    env = PatternCutEnv(render_mode="human", **SMALL)
    env.reset(seed=0)
    env.step(HOLD)
    assert env.render() is None
    env.close()
    assert shown == [((256, 256, 3), 31)] * 3 + ["closed"]


def test_record_video_writes_an_mp4_of_each_episode(tmp_path):
    env = RecordVideo(
        gym.make(ENV_ID, render_mode="rgb_array", **SMALL),
        str(tmp_path / "videos"),
        episode_trigger=lambda episode: True,
        disable_logger=True,
    )
    env.reset(seed=0)
    terminated = False
    while not terminated:
        _, _, terminated, _, _ = env.step(HOLD)
    env.close()
    (video,) = (tmp_path / "videos").glob("*.mp4")
    assert video.name == "rl-video-episode-0.mp4" and frames_in(video) >= STEPS


def test_the_vector_env_renders_its_first_envs(tmp_path):
    vec = PatternCutVecEnv(3, render_mode="rgb_array", render_envs=2, **SMALL)
    vec.reset(seed=0)
    frames = vec.render()
    assert len(frames) == 2 and all(f.shape == (256, 256, 3) for f in frames)
    assert not np.array_equal(frames[0], frames[1])  # each env's own fiducials
    every = PatternCutVecEnv(2, render_mode="rgb_array", render_size=64, **SMALL)
    every.reset(seed=0)
    assert [f.shape for f in every.render()] == [(64, 64, 3)] * 2
    filmed = VectorRecordVideo(
        PatternCutVecEnv(2, autoreset_mode="next_step", render_mode="rgb_array", render_size=64, **SMALL),
        str(tmp_path / "videos"),
        episode_trigger=lambda episode: episode == 0,
    )
    filmed.reset(seed=0)
    for _ in range(STEPS + 1):
        filmed.step(np.zeros((2, 3), dtype=np.float32))
    filmed.close()
    assert frames_in(tmp_path / "videos" / "rl-video-episode-0.mp4", (128, 64)) >= STEPS  # two envs tiled
    with pytest.raises(ValueError, match="render_mode: choose one of \\['rgb_array'\\]"):
        PatternCutVecEnv(2, render_mode="human", **SMALL)
    with pytest.raises(ValueError, match="render_envs"):
        PatternCutVecEnv(2, render_mode="rgb_array", render_envs=0, **SMALL)


def test_the_video_recorder_writes_one_mp4_per_env_and_episode(tmp_path):
    contour, config = load_contour("circle-small"), SimConfig(resolution=9)
    task = CuttingTask(config, contour, 3, pinch_points=[70.0, 30.0], allow_infeasible_pinch=True)
    with VideoRecorder(tmp_path, envs=2) as videos:
        film = videos.step_callback("fixed")
        task.run(None, on_step=film)
        task.run(None, on_step=film)  # a second episode: its own files
        with pytest.raises(ValueError, match="already has videos"):
            videos.step_callback("fixed")
        cut_short = videos.step_callback("none")
        task.reset()
        cut_short(task, None)
        for _ in range(5):
            task.step()
            cut_short(task, None)
    names = [p.name for p in videos.written]
    assert names == [f"fixed-env_{k}{s}.mp4" for s in ("", "-2") for k in (0, 1)] + [
        "none-env_0.mp4",
        "none-env_1.mp4",
    ]
    assert frames_in(tmp_path / "fixed-env_1-2.mp4") == STEPS + 1
    assert frames_in(tmp_path / "none-env_0.mp4") == 6  # closed mid-episode: the frames so far
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names)  # no temporary files left
    with pytest.raises(ValueError, match="closed"):
        videos.step_callback("analytic")
    with pytest.raises(ValueError, match="envs: must be a positive integer"):
        VideoRecorder(tmp_path, envs=0)


def test_with_videos_adds_the_first_contours_films_to_the_other_callbacks():
    seen = []

    class Recorder:
        def step_callback(self, method):
            return lambda task, moves: seen.append(("film", method, task))

    def others(method, first_contour):
        return lambda task, moves: seen.append(("other", method, first_contour))

    combined = with_videos(others, Recorder())
    combined("rl", 0)("task", None)
    combined("rl", 1)("task", None)  # another contour's batch: not filmed
    with_videos(None, Recorder())("none", 0)("task", None)
    assert seen == [("other", "rl", 0), ("film", "rl", "task"), ("other", "rl", 1), ("film", "none", "task")]
    assert with_videos(others, None) is others


def test_simulate_video_writes_mp4s_beside_the_recording(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = ["simulate", "--contour", "circle-small", "--policy", "none,fixed", "--set", "sim.resolution=9"]
    args += ["--trials", "2", "--device", "cpu", "--set", "plots=false", "--json", str(tmp_path / "r.json")]
    result = CliRunner().invoke(main, [*args, "--video", "2"], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    folder = simulate_folder(tmp_path)  # a run folder of their own, not beside --json's file
    videos = sorted(p.name for p in folder.glob("*.mp4"))
    assert videos == ["fixed-env_0.mp4", "fixed-env_1.mp4", "none-env_0.mp4", "none-env_1.mp4"]
    assert f"wrote {folder / 'none-env_1.mp4'}" in result.output
    assert frames_in(folder / "fixed-env_1.mp4") == STEPS + 1
    bad = CliRunner().invoke(main, [*args, "--video", "0"])
    assert bad.exit_code == 2 and "--video" in bad.output
    assert "--video N" in CliRunner().invoke(main, ["simulate", "--help"]).output
    for command in (["evaluate"], ["train", "--contour", "circle-small"]):  # a key of their jobs
        printed = CliRunner().invoke(main, [*command, "--set", "video=2", "--print-config"])
        assert printed.exit_code == 0 and "\nvideo: 2\n" in printed.output, printed.output
