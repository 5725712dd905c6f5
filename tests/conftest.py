"""Shared test set-up: every device Warp sees (CPU always; CUDA when a GPU is present)."""

from __future__ import annotations

import pytest
import warp as wp

wp.config.log_level = wp.LOG_WARNING
wp.init()

DEVICES = ["cpu"] + (["cuda"] if wp.is_cuda_available() else [])


@pytest.fixture(params=DEVICES)
def device(request) -> str:
    """Run the test once per available Warp device."""
    return request.param
