"""Gymnasium registration of ``warpcut/PatternCut-v0`` that a script's own ``envs`` package cannot hide.

warpcut's environments live in the top-level package ``envs``. A script whose own ``envs`` package comes
first on ``sys.path`` (its folder, a notebook's working directory) takes that name, and ``import envs``
gives the script's package, not warpcut's. This module finds warpcut's by where it is installed (beside
``warpcut``) instead of by name, and registers its environments::

    import gymnasium as gym
    import warpcut.gym  # noqa: F401  (or the id "warpcut.gym:warpcut/PatternCut-v0")

    env = gym.make("warpcut/PatternCut-v0", contour="fls-circle")

It is also the ``gymnasium.envs`` entry point of the ``warpcut`` distribution (``pyproject.toml``), for
tools that load that group. Where the name ``envs`` is warpcut's (or free), it is ``import envs``. Where a
script's own package holds it, warpcut's package is loaded from its folder under the name
:data:`ENVS_ALIAS` (its modules import each other relatively, so they load under any name), and the
registration's entry points name those modules: ``gym.make`` builds warpcut's env and the script keeps its
``envs``.

The one module of ``warpcut`` that refers to a layer above it (the house rule: imports point down), and
only by location: nothing in ``warpcut`` imports it, and it imports neither gymnasium nor torch itself.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

ENVS_DIR = Path(__file__).resolve().parent.parent / "envs"
"""Where warpcut's ``envs`` package is installed: beside the ``warpcut`` package."""

ENVS_ALIAS = "_warpcut_envs"
"""The name warpcut's ``envs`` package is loaded under when a script's own package holds ``envs``."""


def _holder_of_envs() -> Path | None:
    """The folder of the package the name ``envs`` gives (imported or not; None: no such package)."""
    loaded = sys.modules.get("envs")
    if loaded is not None:
        origin = getattr(loaded, "__file__", None)
    else:
        try:
            spec = importlib.util.find_spec("envs")
        except (ImportError, ValueError):
            spec = None
        origin = None if spec is None else spec.origin
    return None if origin is None else Path(origin).resolve().parent


def env_package() -> ModuleType:
    """warpcut's ``envs`` package: ``import envs`` where that name is warpcut's, else the package loaded
    from :data:`ENVS_DIR` as :data:`ENVS_ALIAS` (once)."""
    if not (ENVS_DIR / "__init__.py").is_file():
        raise ImportError(f"warpcut's envs package is not beside warpcut ({ENVS_DIR}); reinstall warpcut")
    if _holder_of_envs() == ENVS_DIR:
        return importlib.import_module("envs")
    if ENVS_ALIAS in sys.modules:
        return sys.modules[ENVS_ALIAS]
    spec = importlib.util.spec_from_file_location(
        ENVS_ALIAS, ENVS_DIR / "__init__.py", submodule_search_locations=[str(ENVS_DIR)]
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[ENVS_ALIAS] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[ENVS_ALIAS]
        raise
    return module


def register_envs() -> None:
    """Register ``warpcut/PatternCut-v0`` from warpcut's ``envs`` package (:func:`env_package`); once."""
    env_package().register_envs()


register_envs()
