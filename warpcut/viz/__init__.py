"""Seeing what happened: rerun recordings of cutting episodes and the figures of a run.

Recording (a step callback of :meth:`warpcut.task.CuttingTask.run` writes one ``.rrd`` file):

* :mod:`~warpcut.viz.recorder`: :class:`Recorder`, the public facade, and the step callback it makes per
  episode, which copies the recorded envs' state;
* :mod:`~warpcut.viz.frames`: what the step callback copies (a frame per step, a setup per episode);
* :mod:`~warpcut.viz.transport`: how the copies reach the writer (a recorder process, a worker thread or
  the step callback itself) and a frame's wire format on the pipe to the process;
* :mod:`~warpcut.viz.process`: the recorder process, its start-up and the pipes to it (standard library
  only, so that the CLI can start it before importing anything slow);
* :mod:`~warpcut.viz.server`: the server that runs in the recorder process;
* :mod:`~warpcut.viz.rerun_writer`: the rerun encoding of a batch of frames, and the file;
* :mod:`~warpcut.viz.columns`: rerun component columns built from numpy buffers;
* :mod:`~warpcut.viz.colours`: vertex colours (strain, height) and the fixed colours;
* :mod:`~warpcut.viz.readback`: what a recording holds, read back (``warpcut replay``).

Figures: :mod:`~warpcut.viz.plots` (the cut regions of each method, a plan's pinch candidates).

The names below load their module on first use, so that ``import warpcut.viz`` imports neither rerun nor
pyarrow nor matplotlib.
"""

from warpcut._lazy import lazy_attributes

_LAZY = {
    "Recorder": "warpcut.viz.recorder",
    "RecordingError": "warpcut.viz.process",
    "start_recorder_process": "warpcut.viz.process",
    "COLOUR_FIELDS": "warpcut.viz.colours",
    "RecordingSummary": "warpcut.viz.readback",
    "read_summary": "warpcut.viz.readback",
    "FinalCut": "warpcut.viz.plots",
    "FinalCuts": "warpcut.viz.plots",
    "plot_pinch_candidates": "warpcut.viz.plots",
    "plot_regions": "warpcut.viz.plots",
}

__all__ = sorted(_LAZY)


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY)
