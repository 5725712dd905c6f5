"""The physics: a batch of spring-mass gauze sheets, cut by scissors and pulled by a grasp.

Package map:

- ``config``: :class:`SimConfig` (every parameter, validated; :class:`ConfigError`), :class:`SheetGrid`
  (the rest layout of the vertices) and the constants (units, fixtures, scores, spring families, the
  cutting arm's footprint, the ranges and divergence bounds); :class:`SimulationDiverged`. Plain NumPy.
- ``memory``: the memory a batch needs, checked before it is allocated. Plain Python.
- ``springs``: the springs grouped into colours (sets that share no vertex), in sweep order. Plain NumPy.
- ``material``: material points on the sheet, and their world positions by bilinear interpolation.
  Plain NumPy.
- ``simulator``: :class:`Simulator`, the batch on one device (settling, grasp, scissors, stepping); it
  inherits its cut-path tracing (``tracing``) and its read-back (``reads``).
- ``devices``: the Warp device a simulator runs on (``WARPCUT_DEVICE``, a GPU, else the CPU), checked.
- ``kernels``: the ``colours`` backend's Warp kernels (one thread per vertex; GPUs, ``wp.Tape``) and the
  functions every backend shares (process noise, locating the tip in the deformed mesh).
- ``kernels_simd``: the ``simd`` backend's kernels (the default on CPU: blocks of 8 envs in SIMD lanes);
  ``simd``: its packed batch (the model every env shares, the packed state those kernels step).
- ``reference``: the NumPy implementation of one sheet, the oracle the tests compare against.
- ``_warp``: Warp, imported quietly; every module that uses Warp imports it from there, and launches
  through its ``launch`` (a module Warp cannot load, e.g. from a corrupt kernel cache, raises
  ``KernelCacheError``, one line naming the cache to delete).

Importing this package, or ``config``, ``springs`` and ``material``, does not load Warp:
:class:`Simulator` is loaded on first use.
"""

from warpcut._lazy import lazy_attributes
from warpcut.sim.config import (
    ARM_LENGTH_MM,
    ARM_RADIUS_MM,
    AUTHORS_CUT_RADIUS_MM,
    AUTHORS_UNITS_PER_MM,
    FIXTURES,
    GRAVITY_MM_S2,
    PHYSICAL_PARAMETERS,
    SCORES,
    SPRING_FAMILIES,
    ConfigError,
    SheetGrid,
    SimConfig,
    SimulationDiverged,
)

__all__ = [
    "ARM_LENGTH_MM",
    "ARM_RADIUS_MM",
    "AUTHORS_CUT_RADIUS_MM",
    "AUTHORS_UNITS_PER_MM",
    "FIXTURES",
    "GRAVITY_MM_S2",
    "PHYSICAL_PARAMETERS",
    "SCORES",
    "SPRING_FAMILIES",
    "ConfigError",
    "SheetGrid",
    "SimConfig",
    "SimulationDiverged",
    "Simulator",
]


__getattr__, __dir__ = lazy_attributes(__name__, {"Simulator": "warpcut.sim.simulator"})
