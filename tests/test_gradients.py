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


# ------------------------------------------------------------------ differentiable cutting rollouts
# A small, smooth case: circle-small on a 13 x 13 sheet without noise, a random plan of moves. Its path
# surrogate is differentiable around this plan (no cut or tip-search decision flips within the steps used),
# so central differences check the tape.


def _small_rollout(device, num_envs=1, noise_std=0.0, **kwargs):
    from warpcut import CuttingTask, load_contour
    from warpcut.gradients import DifferentiableRollout

    config = SimConfig(resolution=13, noise_std=noise_std)
    contour = load_contour("circle-small")
    task = CuttingTask(config, [contour] * num_envs, pinch_points=[[68.8, 38.9]] * num_envs, device=device)
    rollout = DifferentiableRollout(task, **kwargs)
    plan = np.random.default_rng(1).uniform(-0.3, 0.3, (num_envs, task.num_steps, 3)).astype(np.float32)
    return rollout, plan


def test_plan_gradient_matches_finite_differences(device):
    rollout, plan = _small_rollout(device)
    forward, grads = rollout.value_and_grad(plan)
    assert forward.mapped[0] > 40 and np.isfinite(forward.surrogate[0])
    steps = [0, 6, 13, 20, 26, 33]
    tape, fd = [], []
    eps = 1e-2
    for t in steps:
        for axis in range(3):
            values = []
            for sign in (1.0, -1.0):
                shifted = plan.copy()
                shifted[0, t, axis] += sign * eps
                values.append(rollout.forward(shifted).surrogate[0])
            fd.append((values[0] - values[1]) / (2 * eps))
            tape.append(grads.actions[0, t, axis])
    assert np.max(np.abs(tape)) > 0.3  # the moves checked matter
    np.testing.assert_allclose(tape, fd, rtol=0.05, atol=0.01)
    # Moves after the last cutting update change nothing.
    assert np.all(grads.actions[0, -1] == 0.0)


def test_pinch_gradient_matches_finite_differences(device):
    rollout, plan = _small_rollout(device)
    _, grads = rollout.value_and_grad(plan)
    eps = 1e-2
    fd = []
    for axis in range(2):
        values = []
        for sign in (1.0, -1.0):
            shift = np.zeros((1, 2))
            shift[0, axis] = sign * eps
            values.append(rollout.forward(plan, pinch_shift=shift).surrogate[0])
        fd.append((values[0] - values[1]) / (2 * eps))
    assert np.max(np.abs(grads.pinch[0])) > 0.1
    np.testing.assert_allclose(grads.pinch[0], fd, rtol=0.05, atol=0.01)


def test_replay_threads_and_capture_agree_bit_for_bit():
    """The backward pass is the same numbers however it is replayed: one thread or two (each env's noise
    stream follows it into its slice of the batch), recorded into a graph or launched kernel by kernel."""
    results = []
    for kwargs in ({"threads": 1, "capture": False}, {"threads": 2, "capture": True}):
        rollout, plan = _small_rollout("cpu", num_envs=3, noise_std=0.03, **kwargs)
        forward, grads = rollout.value_and_grad(plan, seed=5)
        results.append((forward.surrogate, grads.actions, grads.pinch))
    for a, b in zip(*results, strict=True):
        np.testing.assert_array_equal(a, b)
    assert len(set(np.round(results[0][0], 6))) == 3  # the envs' noise differs


def test_surrogate_is_the_mean_squared_path_deviation():
    from warpcut.gradients import path_surrogate

    rollout, plan = _small_rollout("cpu")
    forward = rollout.forward(plan)
    task = rollout.task
    path, target = task.cut_path(), task.target_points()
    mapped = (path[0, :, 2] == 1.0) & np.all(np.isfinite(target[0]), axis=1)
    expected = np.mean(np.sum((path[0, mapped, :2] - target[0, mapped]) ** 2, axis=1))
    assert forward.mapped[0] == mapped.sum()
    np.testing.assert_allclose(forward.surrogate[0], expected, rtol=1e-9)
    value, count = path_surrogate(np.zeros((1, 4, 3)), np.zeros((1, 4, 2)))  # nothing mapped
    assert np.isnan(value[0]) and count[0] == 0


def test_differentiable_rollout_refuses_bad_input():
    import pytest

    from warpcut import CuttingTask, load_contour
    from warpcut.gradients import DifferentiableRollout

    rollout, plan = _small_rollout("cpu")
    with pytest.raises(ValueError, match="actions: expected"):
        rollout.forward(plan[:, :-1])
    with pytest.raises(ValueError, match="actions: contains NaN"):
        rollout.forward(np.full_like(plan, np.nan))
    with pytest.raises(ValueError, match="pinch_shift"):
        rollout.forward(plan, pinch_shift=np.zeros(3))
    with pytest.raises(ValueError, match="reset: False"):
        rollout.task.step()
        rollout.forward(plan, reset=False)
    untraced = CuttingTask(
        SimConfig(resolution=13, score="separated"), load_contour("circle-small"), trace_path=False
    )
    with pytest.raises(ValueError, match="trace_path=True"):
        DifferentiableRollout(untraced)


def test_rollout_memory_grows_with_the_checkpoints_only():
    from warpcut.gradients import rollout_memory

    short = rollout_memory(64, 625, 40, 2, 7)
    long = rollout_memory(64, 625, 80, 2, 7)
    assert long["tape"] == short["tape"]
    assert long["checkpoints"] == 2 * short["checkpoints"]
    assert long["total"] < 2**30  # a default-length B = 64 rollout: well under a GiB


def test_the_usage_guides_gradient_example_runs(capsys):
    """The usage guide's gradient block runs as written (fls-circle, 4 envs, three gradient steps)."""
    import re
    from pathlib import Path

    guide = (Path(__file__).resolve().parents[1] / "docs" / "usage.md").read_text()
    block = next(b for b in re.findall(r"```python\n(.*?)```", guide, re.S) if "DifferentiableRollout" in b)
    exec(compile(block, "docs/usage.md", "exec"), {})
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.split()[0] for line in lines] == ["0", "1", "2"]
    assert all(np.isfinite(float(line.split()[1])) for line in lines)
