"""warpcut: batched, differentiable simulation of tensioning for surgical pattern cutting.

The names a script needs::

    from warpcut import SimConfig, CuttingTask, load_contour, plan_cut

    contour = load_contour("fls-circle")
    plan = plan_cut(contour, SimConfig())
    task = CuttingTask(SimConfig(), [contour] * 8, pinch_points=[plan.chosen["pinch"]] * 8)
    score = task.run(None)  # hold the grasp still: fixed tensioning
    print(score.error_vertices)

``import warpcut`` loads neither Warp (it loads on first use of the simulator) nor torch, gymnasium or
rsl-rl, which only ``envs`` and ``agents`` use. The package map is in ``docs/architecture.md``.
"""

from warpcut._lazy import lazy_attributes
from warpcut.sim.config import ConfigError, SheetGrid, SimConfig

__version__ = "0.1.0"

_LAZY = {
    "Simulator": "warpcut.sim.simulator",
    "CuttingTask": "warpcut.task",
    "Contour": "warpcut.contours",
    "load_contour": "warpcut.contours",
    "plan_cut": "warpcut.planning",
    "Score": "warpcut.scoring",
    "paired_improvement": "warpcut.stats",
    "ci95": "warpcut.stats",
}

__all__ = ["ConfigError", "SheetGrid", "SimConfig", *_LAZY]

# Loaded on first use, so that ``import warpcut`` (the CLI's start-up, the recorder process) stays fast.
__getattr__, __dir__ = lazy_attributes(__name__, _LAZY)
