"""warpcut: batched, differentiable simulation of tensioning for surgical pattern cutting."""

from warpcut.sim.config import ConfigError, SheetGrid, SimConfig

__all__ = ["ConfigError", "SheetGrid", "SimConfig", "Simulator"]
__version__ = "0.1.0"


def __getattr__(name: str):
    # Warp loads on first use of the simulator, not on ``import warpcut`` (~0.4 s): the CLI's start-up and
    # the recorder process (warpcut.viz.recording) do without it.
    if name == "Simulator":
        from warpcut.sim.simulator import Simulator

        return Simulator
    raise AttributeError(f"module 'warpcut' has no attribute {name!r}")
