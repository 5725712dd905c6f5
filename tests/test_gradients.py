"""wp.Tape gradients of a taped rollout against central finite differences."""

import numpy as np
import warp as wp

from warpcut import SimConfig, Simulator


@wp.kernel
def mean_height_kernel(x: wp.array(dtype=wp.vec3), scale: float, loss: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(loss, 0, x[i][2] * scale)


def mean_height_after(sim: Simulator, displacement: wp.array, updates: int, tape: wp.Tape | None = None):
    sim.reset(np.array([[40.0, 55.0]]))
    sim.displacement = displacement
    loss = wp.zeros(1, dtype=float, device=sim.device, requires_grad=True)

    def rollout():
        for _ in range(updates):
            sim.update(tape_mode=True)
        wp.launch(
            mean_height_kernel,
            dim=sim.x.shape[0],
            inputs=[sim.x, 1.0 / sim.x.shape[0]],
            outputs=[loss],
            device=sim.device,
        )

    if tape is None:
        rollout()
    else:
        with tape:
            rollout()
    return loss


def test_tape_gradient_matches_finite_differences(device):
    sim = Simulator(SimConfig(resolution=11, sweeps=10), 1, device=device)
    base = np.array([2.0, -1.5, 3.0], dtype=np.float32)
    updates = 8
    displacement = wp.array([base], dtype=wp.vec3, device=device, requires_grad=True)
    tape = wp.Tape()
    loss = mean_height_after(sim, displacement, updates, tape)
    tape.backward(loss)
    grad = displacement.grad.numpy()[0]

    eps = 0.05
    fd = np.zeros(3)
    for axis in range(3):
        values = []
        for sign in (1.0, -1.0):
            shifted = base.copy()
            shifted[axis] += sign * eps
            u = wp.array([shifted], dtype=wp.vec3, device=device)
            values.append(mean_height_after(sim, u, updates).numpy()[0])
        fd[axis] = (values[0] - values[1]) / (2 * eps)
    assert np.abs(grad[2]) > 1e-3  # lifting the grasp lifts the sheet: a gradient worth checking
    np.testing.assert_allclose(grad, fd, rtol=0.05, atol=2e-4)
