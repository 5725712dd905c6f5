"""Shared test set-up: every device Warp sees (CPU always; CUDA when a GPU is present)."""

from __future__ import annotations

import os

import pytest
import warp as wp
from hypothesis import settings

# Hypothesis profiles, chosen by HYPOTHESIS_PROFILE: "ci" (the default: few examples, the same ones every run)
# or "long" for a real fuzzing session: HYPOTHESIS_PROFILE=long pytest tests/test_fuzz_contours.py
settings.register_profile("ci", max_examples=25, deadline=None, derandomize=True, database=None)
settings.register_profile("long", max_examples=1000, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

wp.config.log_level = wp.LOG_WARNING
wp.init()

DEVICES = ["cpu"] + (["cuda"] if wp.is_cuda_available() else [])


@pytest.fixture(params=DEVICES)
def device(request) -> str:
    """Run the test once per available Warp device."""
    return request.param


@pytest.fixture(scope="module")
def one_torch_thread():
    """Tiny MLPs gain nothing from threads, and threads slow to a crawl on a busy 2-core machine (use it
    per module: ``pytestmark = pytest.mark.usefixtures("one_torch_thread")``)."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
