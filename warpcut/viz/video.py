"""MP4 videos of cutting episodes: a :class:`VideoRecorder` makes step callbacks (``on_step(task, moves)``,
:data:`warpcut.task.StepCallback`) that draw the first envs of a task after its reset and every step
(:class:`~warpcut.viz.render.TaskRenderer`) and stream each env's frames to its own MP4 file
(``FOLDER/METHOD-env_K.mp4``; a second episode through the same callback adds ``-2``, ...), encoded by
ffmpeg (the binary that imageio-ffmpeg ships) in its own process::

    with VideoRecorder("videos", envs=2) as videos:
        task.run(policy, on_step=videos.step_callback("fixed"))
    videos.written  # [videos/fixed-env_0.mp4, videos/fixed-env_1.mp4]

A video plays at the simulated time (one frame per step, :func:`~warpcut.viz.render.step_fps`). Each file
is written beside its target under a temporary name and moved into place when its episode ends or the
recorder closes (also when an exception or Ctrl-C ends the run: the file holds the frames so far).
Drawing costs a few milliseconds per env and step in the stepping loop; the encoding runs in ffmpeg.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from warpcut.io import note_written, safe_name, temp_file
from warpcut.viz.render import RENDER_COLOURS, TaskRenderer, check_render_settings, step_fps

if TYPE_CHECKING:
    from warpcut.task import CuttingTask, StepCallback


class VideoRecorder:
    """Writes MP4 videos of the first ``envs`` envs of every episode its step callbacks see.

    Args:
        folder: Where the videos go (created).
        envs: How many envs (the first ones) of each task to film; fewer where a task has fewer.
        fps: Frames per second; default: the task's simulated time (:func:`~warpcut.viz.render.step_fps`).
        size: Image size in pixels, ``N`` or ``(width, height)`` (even numbers encode without resizing).
        view: The camera, ``"top"`` or ``"three-quarter"``.
        colour_by: The sheet's colours, ``"strain"`` or ``"height"``.

    Raises:
        ValueError: naming the argument out of range, or ``video`` where ffmpeg is not available.
    """

    def __init__(
        self,
        folder: str | os.PathLike,
        envs: int = 1,
        fps: float | None = None,
        size: int | tuple[int, int] = 256,
        view: str = "top",
        colour_by: str = "strain",
    ):
        if isinstance(envs, bool) or not isinstance(envs, int | np.integer) or envs < 1:
            raise ValueError(f"envs: must be a positive integer (got {envs!r})")
        if fps is not None and not (isinstance(fps, int | float) and np.isfinite(fps) and fps > 0):
            raise ValueError(f"fps: must be a positive number of frames per second or None (got {fps!r})")
        check_render_settings(size, view)
        if colour_by not in RENDER_COLOURS:
            raise ValueError(f"colour_by: choose one of {RENDER_COLOURS} (got {colour_by!r})")
        _ffmpeg()  # fail now, not at the first frame
        self.folder = Path(folder)
        self.envs, self.fps = int(envs), fps
        self._render = {"size": size, "view": view, "colour_by": colour_by}
        self._episodes: dict[str, _Episode] = {}
        self.written: list[Path] = []
        """The videos finished so far, in order."""
        self.closed = False

    def step_callback(self, method: str) -> StepCallback:
        """A new step callback filming the episodes of ``method`` (its videos: ``METHOD-env_K.mp4``).

        Raises:
            ValueError: ``method`` already has a callback, or the recorder is closed.
        """
        if self.closed:
            raise ValueError(f"step_callback: the video recorder of {self.folder} is closed")
        if method in self._episodes:
            raise ValueError(f"step_callback: method {method!r} already has videos in {self.folder}")
        episode = _Episode(self, method)
        self._episodes[method] = episode
        return episode

    def close(self) -> list[Path]:
        """Finish every video still open (an episode cut short); return :attr:`written`."""
        if not self.closed:
            self.closed = True
            for episode in self._episodes.values():
                episode.finish()
        return self.written

    def __enter__(self) -> VideoRecorder:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


class _Episode:
    """One method's step callback: a renderer per task, one ffmpeg writer per filmed env."""

    def __init__(self, recorder: VideoRecorder, method: str):
        self.recorder, self.method = recorder, method
        self.task: CuttingTask | None = None
        self.renderer: TaskRenderer | None = None
        self.writers: list[_Writer] = []
        self.episodes = 0

    def __call__(self, task: CuttingTask, moves: np.ndarray | None) -> None:
        if task is not self.task or task.step_index == 0 or not self.writers:  # a new episode
            self._start(task)
        for writer, frame in zip(self.writers, self.renderer.render(), strict=True):
            writer.write(frame)
        if task.done:
            self.finish()

    def _start(self, task: CuttingTask) -> None:
        self.finish()
        recorder = self.recorder
        if task is not self.task:
            envs = min(recorder.envs, task.num_envs)
            self.renderer = TaskRenderer(task, envs=envs, **recorder._render)
            self.task = task
        self.episodes += 1
        suffix = "" if self.episodes == 1 else f"-{self.episodes}"
        fps = recorder.fps or step_fps(task.config)
        size = (self.renderer.width, self.renderer.height)
        name = safe_name(self.method)
        self.writers = [
            _Writer(recorder.folder / f"{name}-env_{k}{suffix}.mp4", size, fps)
            for k in range(len(self.renderer.envs))
        ]

    def finish(self) -> None:
        """Finish the open videos and move them into place (all of them, also where one fails)."""
        writers, self.writers = self.writers, []
        errors = []
        for writer in writers:
            try:
                writer.close()
            except Exception as error:  # ffmpeg failed (e.g. a full disk): the file holds what it wrote
                errors.append(error)
            self.recorder.written.append(writer.path)
        if errors:
            raise errors[0]


class _Writer:
    """One MP4 file, encoded by ffmpeg as the frames arrive, under a temporary name until closed."""

    def __init__(self, path: Path, size: tuple[int, int], fps: float):
        import imageio_ffmpeg

        self.path = path
        note_written(path)  # a run directory's file
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = temp_file(path, ".mp4")
        os.close(fd)
        self.tmp = Path(tmp)
        self._frames = imageio_ffmpeg.write_frames(
            str(self.tmp), size, fps=fps, codec="libx264", quality=6, macro_block_size=2,
            ffmpeg_log_level="error", output_params=["-movflags", "+faststart"],
        )  # fmt: skip
        self._frames.send(None)

    def write(self, frame: np.ndarray) -> None:
        self._frames.send(np.ascontiguousarray(frame))

    def close(self) -> None:
        """Let ffmpeg finish the file (it runs in its own process group: Ctrl-C leaves it to finish), then
        move it into place, also where ffmpeg failed."""
        try:
            self._frames.close()
        finally:
            os.replace(self.tmp, self.path)


def _ffmpeg() -> str:
    """The ffmpeg binary that writes the videos; ``ValueError`` naming ``video`` where there is none."""
    try:
        import imageio_ffmpeg

        return imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError) as error:
        raise ValueError(
            f"video: writing MP4s needs ffmpeg ({error}); pip install imageio-ffmpeg (moviepy brings it)"
        ) from None
