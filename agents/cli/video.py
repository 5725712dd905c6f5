"""``--video N`` of ``warpcut simulate``, ``evaluate`` and ``train``: MP4 videos of the first N envs of each
method's episode (:class:`warpcut.viz.video.VideoRecorder`), written into the directory where ``--record``
writes ``recording.rrd``, one file per env: ``METHOD-env_K.mp4``."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path

import click

from agents.cli.options import Setting
from agents.cli.outputs import echo_written

video_option = click.option(
    "--video",
    "video_envs",
    cls=Setting,
    key="video",
    type=click.IntRange(min=1),
    default=None,
    metavar="N",
    help="Write MP4 videos (top view, sheet coloured by strain) of the first N envs of each method, one "
    "per env (METHOD-env_K.mp4), where --record writes its recording.",
)


@contextlib.contextmanager
def videos(out: Path, video_envs: int | None) -> Iterator:
    """A :class:`~warpcut.viz.video.VideoRecorder` into ``out`` (None without ``--video``); it says which
    videos it wrote when the block ends without an error (and finishes them either way)."""
    if video_envs is None:
        yield None
        return
    from warpcut.viz.video import VideoRecorder

    with VideoRecorder(out, envs=video_envs) as recorder:
        yield recorder
    echo_written(recorder.written)


def with_videos(step_callbacks: Callable | None, recorder) -> Callable | None:
    """``step_callbacks`` (what :func:`agents.cli.outputs.step_callbacks` returns: ``(method, first_contour)
    -> on_step`` or None) plus ``recorder``'s step callback for the batches that start at the first
    contour (they film its first envs, as ``--record`` records them)."""
    if recorder is None:
        return step_callbacks
    films: dict[str, Callable] = {}

    def for_batch(method: str, first_contour: int):
        other = step_callbacks(method, first_contour) if step_callbacks is not None else None
        if first_contour != 0:
            return other
        if method not in films:
            films[method] = recorder.step_callback(method)
        film = films[method]
        if other is None:
            return film

        def on_step(task, moves) -> None:
            other(task, moves)
            film(task, moves)

        return on_step

    return for_batch
