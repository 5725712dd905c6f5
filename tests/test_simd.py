"""The SIMD prototype (``warpcut/sim/kernels_simd.py``) against the fused backend.

The SIMD kernels evaluate the fused kernel's float expressions lane by lane in the same order, so the
comparison is exact (bit for bit), which is stronger than the 1e-3 mm asked of a new backend.
"""

import numpy as np
import pytest
import warp as wp

from warpcut import SimConfig, Simulator
from warpcut.sim.kernels import fused_update_kernel
from warpcut.sim.kernels_simd import SimdModel, SimdState, simd_kernels, simd_update

PINCHES = np.array([[50.0, 50.0], [np.nan, np.nan], [30.0, 60.0], [60.0, 40.0], [45.0, 45.0]])


class SimdDriver:
    """Steps a copy of ``sim``'s batch with the SIMD kernels, as a ``backend="simd"`` would."""

    def __init__(self, sim: Simulator, lanes: int, relax: str):
        self.sim, self.relax = sim, relax
        n = sim.grid.num_vertices
        self.model = SimdModel.from_arrays(
            n,
            sim.config.iterations,
            sim._spring_a,
            sim._spring_b,
            sim._spring_rest,
            sim._colour_start,
            int(sim.config.first_order_z),
            sim.config.cut_radius,
            sim.config.cut_height,
        )
        self.state = SimdState(sim.num_envs, n, lanes, sim.device)
        self.state.load(sim.x, sim.x_prev, sim.alive, sim.pin, sim.anchor)
        p = sim._wp_params
        self.state.load_params(p["damping"], p["dt"], p["gravity"], p["noise_std"], p["elasticity"])

    def update(self) -> None:
        self.state.load_controls(self.sim.displacement, self.sim.tip)
        self.state.step(
            self.model, self.sim._noise_seed(), relax=self.relax, first_stream=self.sim.first_noise_stream
        )
        self.sim.update_count += 1

    def store(self) -> None:
        self.state.store(self.sim.x, self.sim.x_prev, self.sim.alive)


def run_cut(config: SimConfig, simd: tuple[int, str] | None, updates: int = 30):
    """A cut across the sheet with the grasps pulling: fused (``simd=None``) or SIMD ``(lanes, relax)``."""
    b = len(PINCHES)
    sim = Simulator(config, b, device="cpu", seed=3, backend="fused", threads=1)
    sim.reset(PINCHES)
    z = sim.settled_positions()[0, 6 * 13 + 10, 2]
    driver = SimdDriver(sim, *simd) if simd else None
    for k in range(updates):
        sim.move_grasp(np.tile([[0.7, -0.4, 0.1]], (b, 1)))
        sim.set_tip(np.tile([[80.0 - 1.5 * k, 50.0, z, 1.0]], (b, 1)))
        (driver or sim).update()
    if driver:
        driver.store()
    return sim.positions(), sim.x_prev.numpy(), sim.alive_mask()


@pytest.mark.parametrize(
    ("lanes", "relax", "noise"),
    [(8, "warp", 0.0), (8, "native", 0.0), (8, "native", 0.05), (8, "warp", 0.05), (4, "native", 0.0)],
)
def test_simd_matches_fused_through_a_cut(lanes, relax, noise):
    # 5 envs: one padded block for L = 8, two blocks for L = 4; per-env gravity gives each lane its own
    # parameters; env 1 has no grasp.
    config = SimConfig(resolution=13, noise_std=noise, gravity=[521.0, 900.0, 521.0, 300.0, 700.0])
    positions, prev, alive = run_cut(config, None)
    simd_positions, simd_prev, simd_alive = run_cut(config, (lanes, relax))
    assert (~alive).sum() > 0  # the comparison covered real cutting
    np.testing.assert_array_equal(simd_alive, alive)
    np.testing.assert_allclose(simd_positions, positions, rtol=0, atol=1e-3)
    np.testing.assert_array_equal(simd_positions, positions)  # in fact bit for bit
    np.testing.assert_array_equal(simd_prev, prev)


def test_block_ranges_step_independently():
    config = SimConfig(resolution=9, noise_std=0.02)
    sim = Simulator(config, 12, device="cpu", backend="fused", threads=1)
    sim.reset(np.tile([[50.0, 50.0]], (12, 1)))
    whole, parts = SimdDriver(sim, 8, "native"), SimdDriver(sim, 8, "native")
    assert whole.state.blocks == 2
    for _ in range(3):
        whole.state.step(whole.model, 5)
        parts.state.step(parts.model, 5, block_offset=1, block_count=1)
        parts.state.step(parts.model, 5, block_offset=0, block_count=1)
    np.testing.assert_array_equal(parts.state.vert.numpy(), whole.state.vert.numpy())


def fused_arguments(sim: Simulator, seed: int) -> list:
    """``fused_update_kernel``'s arguments for ``sim``, without ``env_offset`` (the whole batch)."""
    p = sim._wp_params
    return [
        sim.grid.num_vertices,
        sim.config.iterations,
        sim._spring_a,
        sim._spring_b,
        sim._spring_rest,
        sim._colour_start,
        p["damping"],
        p["dt"],
        p["gravity"],
        p["noise_std"],
        p["elasticity"],
        int(sim.config.first_order_z),
        seed,
        sim.first_noise_stream,
        sim.config.cut_radius,
        sim.config.cut_height,
        sim.pin,
        sim.anchor,
        sim.displacement,
        sim.tip,
        sim.x,
        sim.x_prev,
        sim.alive,
    ]


def test_simd_update_matches_one_fused_launch():
    config = SimConfig(resolution=11, first_order_z=True, elasticity=[1.0, 0.8, 0.6], noise_std=0.01)
    sims = [Simulator(config, 3, device="cpu", backend="fused", threads=1) for _ in range(2)]
    for sim in sims:
        sim.reset(PINCHES[:3])
        z = sim.settled_positions()[0, 5 * 11 + 5, 2]
        sim.move_grasp(np.tile([[1.0, 0.5, -0.5]], (3, 1)))
        sim.set_tip(np.tile([[50.0, 50.0, z, 1.0]], (3, 1)))
    fused, simd = sims
    args = fused_arguments(fused, seed=11)
    wp.launch(fused_update_kernel, dim=3, inputs=[args[0], 0, *args[1:]], device="cpu")
    simd_update(*fused_arguments(simd, seed=11))
    assert (~fused.alive_mask()).any()
    np.testing.assert_array_equal(simd.alive_mask(), fused.alive_mask())
    np.testing.assert_array_equal(simd.positions(), fused.positions())
    np.testing.assert_array_equal(simd.x_prev.numpy(), fused.x_prev.numpy())


def test_bad_arguments_are_reported():
    with pytest.raises(ValueError, match="lanes: choose a power of two"):
        simd_kernels(3)
    sim = Simulator(SimConfig(resolution=7), 2, device="cpu", backend="fused")
    driver = SimdDriver(sim, 8, "warp")
    with pytest.raises(ValueError, match="relax: choose one of"):
        driver.state.step(driver.model, 0, relax="magic")
    mixed = wp.array(np.arange(len(sim._spring_rest.numpy()), dtype=np.float32), device="cpu")
    with pytest.raises(ValueError, match="spring_rest: colour 0 mixes rest lengths"):
        SimdModel.from_arrays(49, 5, sim._spring_a, sim._spring_b, mixed, sim._colour_start, 0, 1.0, 1.0)
