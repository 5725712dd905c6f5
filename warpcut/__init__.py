"""warpcut: batched, differentiable simulation of tensioning for surgical pattern cutting."""

import os

import warp as wp

# Warp prints a banner and a line per module load; keep the CLI's output to our own unless asked.
if not os.environ.get("WARPCUT_VERBOSE"):
    wp.config.log_level = wp.LOG_WARNING

from warpcut.config import ConfigError, SheetGrid, SimConfig
from warpcut.simulator import Simulator

__all__ = ["ConfigError", "SheetGrid", "SimConfig", "Simulator"]
__version__ = "0.1.0"
