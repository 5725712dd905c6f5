"""Warp, imported with warpcut's settings: Warp prints a banner and a line per module load; keep the
CLI's output to our own unless ``WARPCUT_VERBOSE`` is set. Every warpcut module that uses Warp imports
it from here (``from warpcut._warp import wp``), so that ``import warpcut`` itself stays light: the
recorder process and the CLI's start-up do not pay for Warp."""

import os

import warp as wp

if not os.environ.get("WARPCUT_VERBOSE"):
    wp.config.log_level = wp.LOG_WARNING

__all__ = ["wp"]
