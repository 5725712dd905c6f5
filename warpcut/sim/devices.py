"""Which Warp device a simulator runs on: ``WARPCUT_DEVICE``, else a GPU where Warp sees one, else the CPU
(:func:`default_device`); a device name checked against what Warp sees (:func:`resolve_device`)."""

from __future__ import annotations

import os

from warpcut.sim._warp import init, wp


def default_device() -> str:
    """``WARPCUT_DEVICE`` if set, else ``cuda`` when Warp sees a GPU, else ``cpu``."""
    env = os.environ.get("WARPCUT_DEVICE")
    if env:
        return env
    return "cuda" if wp.is_cuda_available() else "cpu"


def resolve_device(device: str | None) -> str:
    """Check a device name against what Warp sees; raise ValueError naming the fix."""
    init()
    device = device or default_device()
    names = [str(d) for d in wp.get_devices()]
    if device == "cuda" and not wp.is_cuda_available():
        raise ValueError("device: 'cuda' requested but no CUDA GPU is available; use --device cpu")
    if device != "cuda" and device not in names:
        raise ValueError(f"device: unknown device {device!r}; available: {', '.join(names)}")
    return device
