"""Warp against the NumPy reference, through a whole cut with tensioning."""

import numpy as np
import pytest

from warpcut import SimConfig
from warpcut.contours import load_contour
from warpcut.sim.reference import ReferenceSheet
from warpcut.task import CuttingTask

POSITION_TOLERANCE_MM = 1e-2
"""Both run in float32 and evaluate the kernels' expressions in the same order: over this cut they agree
bit for bit (measured: a gap of 0). The tolerance leaves room for a platform whose rounding differs (a
fused multiply-add), which a cut amplifies: the cut sheet's flaps are sensitive to a perturbation (a
1e-4 mm nudge grows to millimetres on some contours, with plain sweeps as with Chebyshev ones; before the
reference followed the kernels' order of operations, rounding alone drifted 3e-2 mm here)."""


@pytest.mark.parametrize("chebyshev_rho", [SimConfig.chebyshev_rho, 0.0])
@pytest.mark.parametrize("backend", ["simd", "colours"])
def test_warp_matches_numpy_reference_through_a_full_cut(device, backend, chebyshev_rho):
    if backend == "simd" and device != "cpu":
        pytest.skip("the simd backend runs on the CPU only")
    config = SimConfig(resolution=17, noise_std=0.0, chebyshev_rho=chebyshev_rho)
    contour = load_contour("fls-circle")
    task = CuttingTask(  # the centroid, under the arm: the grasp holds the piece as the reference's does
        config, contour, pinch_points=contour.centroid, device=device, backend=backend,
        allow_infeasible_pinch=True,
    )  # fmt: skip
    task.reset()
    ref = ReferenceSheet(config, task.sim.settled_positions()[0], pinch_point=contour.centroid)
    worst = 0.0
    moved = 0.0
    while not task.done:
        k = task.step_index  # a scripted pull that sweeps the grasp around, clipped like any action
        action = np.array([[1.5 * np.cos(k / 9), np.sin(k / 6), 0.3 * np.sin(k / 4)]])
        tips = [task.tip_positions(task.update_index + k)[0] for k in range(config.updates_per_step)]
        task.step(action)
        ref.move_grasp(action[0])
        for tip in tips:
            ref.update(tip)
        np.testing.assert_array_equal(task.sim.alive_mask()[0], ref.alive)
        worst = max(worst, float(np.abs(task.sim.positions()[0] - ref.x).max()))
        moved = max(moved, float(np.linalg.norm(task.sim.displacements()[0])))
    assert worst < POSITION_TOLERANCE_MM
    assert moved > 2.0  # the comparison covered real tensioning
    assert 0 < (~ref.alive).sum() < ref.alive.size  # ...and real cutting
