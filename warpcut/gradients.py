"""Differentiable cutting rollouts: the path score's smooth surrogate and its gradient through ``wp.Tape``.

The path score (:mod:`warpcut.scoring`) is the symmetric difference between the intended region and the
region the cut path encloses: piecewise constant in the vertices where the path is traced, so it has no
useful gradient. Its *increment* does: at every cutting update, the distance in material coordinates
between where the scissors cut (the tip mapped through the deformed mesh, :meth:`Simulator.trace_path`)
and where they meant to cut (:meth:`CuttingTask.target_points`). The **surrogate** is its square, averaged
over the mapped cutting updates of the episode (mm^2, one value per env); it is differentiable in the
vertex positions, hence in everything that moves them: the grasp's moves and the pinch point.

What the backward pass holds fixed (the gradient is that of the piecewise-smooth function around the
forward pass, as in any differentiable simulator with contact or fracture):

- **topology**: which vertices the scissors cut, and when (the replay cuts the same ones);
- **the tip search**: the triangle that carries the tip at each update (the surrogate differentiates the
  barycentric map inside it);
- **the grasped set**: the pinch point's gradient moves the grasp's hold on the material, each grasped
  vertex's anchor by the settled sheet's deformation gradient times the shift, the grasped vertices
  staying the same ones (``pinch_shift`` of :meth:`DifferentiableRollout.forward` runs that model
  forward, so finite differences can check it);
- **clipping**: a move clipped to ``max_step_mm`` per axis has no gradient along that axis; the grasp's
  displacement cap is differentiated (a rescaling).

Memory: the forward pass runs the fast path (any backend) and keeps one checkpoint of the state per env
step; the backward pass replays one step at a time on the ``colours`` backend under its own tape (bit for
bit the same updates), from the last step to the first, carrying the adjoint of the state between steps.
The tape holds ``updates_per_step`` updates at a time, so memory grows with the checkpoints only
(:func:`rollout_memory`).
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from warpcut.cores import cpu_cores
from warpcut.scoring import Score
from warpcut.sim import kernels
from warpcut.sim._warp import launch, wp
from warpcut.sim.simulator import Simulator
from warpcut.task import CuttingTask

__all__ = ["DifferentiableRollout", "Gradients", "Rollout", "path_surrogate", "rollout_memory"]

Policy = Callable[[CuttingTask], "np.ndarray | None"]
"""``policy(task) -> (B, 3)`` grasp moves (mm) for the task's next step, or None for none."""


@dataclass
class Rollout:
    """One forward pass, with what the backward pass replays."""

    actions: np.ndarray
    """(B, T, 3) float32 grasp moves as given (mm; the simulator clips them), one per env step."""
    surrogate: np.ndarray
    """(B,) the path surrogate (mm^2): mean squared material distance over the mapped cutting updates
    (NaN where none was mapped, or the env diverged; such an env's gradients are 0)."""
    score: Score
    """The episode's score under the task's ``config.score``."""
    mapped: np.ndarray
    """(B,) int: cutting updates whose tip was mapped (the surrogate's terms)."""
    pinch_shift: np.ndarray
    """(B, 2) the shift of the grasp's hold on the material (mm; zero: the pinch point as planned)."""
    seed: int
    """The process-noise seed of the episode."""
    states: list[dict]
    """Per env step, the simulator state before its move (:meth:`Simulator.state`)."""
    path: np.ndarray
    """(B, horizon, 3) the traced cut path (:attr:`Simulator.path`)."""


@dataclass
class Gradients:
    """Gradients of the sum over envs of :attr:`Rollout.surrogate` (each env's only depends on its own)."""

    actions: np.ndarray
    """(B, T, 3) with respect to each step's grasp move (mm^2 per mm); zero for envs without a grasp."""
    pinch: np.ndarray
    """(B, 2) with respect to the pinch point (material mm), the grasped set held fixed."""


def path_surrogate(path: np.ndarray, targets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The surrogate of a traced path (B, H, 3) against the (B, H, 2) material targets: ``(value, count)``,
    the (B,) mean squared distance (mm^2) over the updates whose tip was mapped and meant to cut, and their
    (B,) count (value NaN where there are none)."""
    targets = targets[:, : path.shape[1]]
    mapped = (path[..., 2] == float(kernels.PATH_MAPPED)) & np.all(np.isfinite(targets), axis=-1)
    delta = np.where(mapped[..., None], path[..., :2] - np.nan_to_num(targets), 0.0)
    count = mapped.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        value = np.where(count > 0, np.sum(delta * delta, axis=(1, 2)) / count, np.nan)
    return value, count


def rollout_memory(num_envs: int, num_vertices: int, steps: int, updates_per_step: int, sweeps: int) -> dict:
    """Bytes a differentiable rollout holds: ``checkpoints`` (one state per step) and ``tape`` (one step's
    replay: every kernel's output and its gradient), and their ``total``."""
    state = num_envs * num_vertices * (3 * 4 * 2 + 4) + num_envs * 3 * 4
    per_update = (2 + 8 * sweeps + sweeps) * num_envs * num_vertices * 3 * 4 * 2
    checkpoints, tape = steps * state, updates_per_step * per_update
    return {"checkpoints": checkpoints, "tape": tape, "total": checkpoints + tape}


class DifferentiableRollout:
    """Rollouts of a :class:`CuttingTask` with the gradient of the path surrogate.

    Args:
        task: The task (its batch, contours, pinch points, seed and backend); it runs the forward passes.
        capture: Record one step's replay (forward and backward) into a Warp graph once and launch it for
            every step (no per-kernel launch overhead); False: launch its kernels one by one (the same
            results bit for bit).
        threads: CPU threads replaying disjoint slices of the batch (default: the number of cores, at most
            one per env); one on a GPU.

    Each env's surrogate depends on its own inputs only, so one backward pass gives every env's gradient.
    """

    def __init__(self, task: CuttingTask, capture: bool = True, threads: int | None = None):
        if task.sim.path is None:
            raise ValueError("task: the cut path is not traced; make the CuttingTask with trace_path=True")
        self.task = task
        sim = task.sim
        task.reset()
        self._pin = sim.pin.numpy().copy()
        self._anchor = sim.anchor.numpy().copy()
        self._jacobian = _deformation_gradient(sim.settled_positions(), task.grid.nx, task.grid.ny, task.grid)
        self.capture = capture
        cpu = wp.get_device(sim.device).is_cpu
        count = max(1, min(threads or cpu_cores(), task.num_envs)) if cpu else 1
        self._parts = [(int(p[0]), int(p[-1]) + 1) for p in np.array_split(np.arange(task.num_envs), count)]
        self._steps: list[_StepTape] | None = None

    @property
    def num_steps(self) -> int:
        return self.task.num_steps

    def forward(
        self,
        actions: np.ndarray | Policy | None,
        pinch_shift: np.ndarray | None = None,
        seed: int | None = None,
        reset: bool = True,
    ) -> Rollout:
        """Run an episode, keeping what :meth:`backward` needs.

        Args:
            actions: (B, T, 3) or (T, 3) grasp moves per step (mm), a policy called before every step
                (:data:`Policy`, e.g. a torch policy's wrapper), or None (hold still).
            pinch_shift: (B, 2) shift of the grasp's hold on the material (mm), the grasped set kept:
                the model the pinch point's gradient differentiates (default: none).
            seed: Process-noise seed of the episode (default: the task's current one).
            reset: Reset the task first; False: the caller just did (e.g. an env that also places its
                fiducials), and ``seed`` must be None.
        """
        task = self.task
        b, steps = task.num_envs, task.num_steps
        plan = None if actions is None or callable(actions) else self._plan_array(actions)
        shift = self._shift_array(pinch_shift)
        if reset:
            task.reset(seed=seed)
        elif seed is not None or task.update_index != 0:
            raise ValueError("reset: False needs a task just reset (update_index 0) and seed None")
        if np.any(shift):
            task.sim.anchor.assign(self._shifted_anchor(shift))
        states, applied = [], np.zeros((b, steps, 3), dtype=np.float32)
        for t in range(steps):
            states.append(task.sim.state())
            if plan is not None:
                move = plan[:, t]
            else:
                move = actions(task) if callable(actions) else None
                move = np.zeros((b, 3), np.float32) if move is None else np.asarray(move, np.float32)
                if move.shape != (b, 3) or not np.all(np.isfinite(move)):
                    raise ValueError(
                        f"actions: the policy returned {move.shape} moves at step {t}; give finite (B, 3) = "
                        f"({b}, 3) grasp moves in mm"
                    )
            applied[:, t] = move
            task.step(applied[:, t])
        path = task.cut_path().copy()
        surrogate, mapped = path_surrogate(path, task.target_points())
        score = task.score()
        diverged = np.zeros(b, bool) if score.diverged is None else np.asarray(score.diverged, bool)
        surrogate[diverged] = np.nan  # a diverged env's path means nothing; its gradient is 0
        mapped[diverged] = 0
        return Rollout(applied, surrogate, score, mapped, shift, task.sim.seed, states, path)

    def backward(self, rollout: Rollout, window: int | None = None) -> Gradients:
        """The gradients of ``rollout.surrogate.sum()``, replaying the episode one step at a time.

        Args:
            rollout: A :meth:`forward` pass of this rollout.
            window: Truncate the gradient to windows of this many steps: a move then only answers for the
                surrogate's terms up to the end of its window (truncated backpropagation through time;
                lower variance on chaotic sheets, some bias). None: the whole episode's gradient.
        """
        if window is not None and (not isinstance(window, int) or window < 1):
            raise ValueError(f"window: must be a positive number of steps or None (got {window!r})")
        task = self.task
        if self._steps is None:
            self._steps = [_StepTape(self, lo, hi, self.capture) for lo, hi in self._parts]
        grasped = np.any(self._pin.reshape(task.num_envs, -1) == int(kernels.PIN_GRASP), axis=1)
        actions = np.where(grasped[:, None, None], rollout.actions, 0.0).astype(np.float32)
        with np.errstate(divide="ignore"):
            weight = np.where(rollout.mapped > 0, 1.0 / rollout.mapped, 0.0)
        for step in self._steps:
            step.begin(rollout.seed, rollout.pinch_shift, weight)
        grad = np.zeros(actions.shape)
        # Threads live for one backward pass only: idle pools left behind by rollouts that are kept (or not
        # yet collected) would outlive them in the process, where they take signals meant for the main thread.
        pool = ThreadPoolExecutor(len(self._steps)) if len(self._steps) > 1 else None
        try:
            self._replay(rollout, window, actions, grad, pool)
        finally:
            if pool is not None:
                pool.shutdown()
        pinch = np.concatenate([step.shift.grad.numpy() for step in self._steps]).astype(np.float64)
        diverged = rollout.mapped == 0  # diverged, or nothing mapped: no surrogate, no gradient
        grad[diverged], pinch[diverged] = 0.0, 0.0
        return Gradients(grad, pinch)

    def _replay(self, rollout: Rollout, window, actions: np.ndarray, grad: np.ndarray, pool) -> None:
        """The backward pass's walk over the steps, last to first (:meth:`backward`)."""
        task = self.task
        ups, horizon = task.config.updates_per_step, task.horizon_updates
        path = np.zeros((task.num_envs, ups, 3), np.float32)
        target = np.full((task.num_envs, ups, 2), np.nan, np.float32)
        for t in reversed(range(len(rollout.states))):
            if window is not None and (t + 1) % window == 0:
                for step in self._steps:
                    step.cut_adjoint()
            updates = range(t * ups, (t + 1) * ups)
            path[:] = (0.0, 0.0, float(kernels.PATH_IDLE))
            target[:] = np.nan
            traced = [u for u in updates if u < horizon]
            path[:, : len(traced)] = rollout.path[:, traced]
            target[:, : len(traced)] = task.target_points()[:, traced]
            tips = np.stack([task.tip_positions(u) for u in updates], axis=1)
            state = rollout.states[t]

            def run(step: _StepTape, t=t, tips=tips, state=state) -> np.ndarray:
                return step.run(t * ups, state, actions[:, t], tips, path, target)

            parts = map(run, self._steps) if pool is None else pool.map(run, self._steps)
            grad[:, t] = np.concatenate(list(parts))

    def value_and_grad(
        self,
        actions: np.ndarray | Policy | None,
        pinch_shift: np.ndarray | None = None,
        seed: int | None = None,
        window: int | None = None,
    ) -> tuple[Rollout, Gradients]:
        """:meth:`forward`, then :meth:`backward`."""
        rollout = self.forward(actions, pinch_shift, seed)
        return rollout, self.backward(rollout, window)

    # ------------------------------------------------------------------ helpers
    def _plan_array(self, actions: np.ndarray) -> np.ndarray:
        b, steps = self.task.num_envs, self.task.num_steps
        plan = np.asarray(actions, dtype=np.float32)
        if plan.shape == (steps, 3):
            plan = np.broadcast_to(plan, (b, steps, 3))
        if plan.shape != (b, steps, 3):
            raise ValueError(
                f"actions: expected ({b}, {steps}, 3) or ({steps}, 3) grasp moves in mm (one per env step), "
                f"got shape {plan.shape}"
            )
        if not np.all(np.isfinite(plan)):
            raise ValueError("actions: contains NaN or infinite values; give finite moves in mm")
        return plan

    def _shift_array(self, pinch_shift: np.ndarray | None) -> np.ndarray:
        b = self.task.num_envs
        if pinch_shift is None:
            return np.zeros((b, 2), dtype=np.float32)
        shift = np.asarray(pinch_shift, dtype=np.float32)
        shift = np.broadcast_to(shift, (b, 2)) if shift.shape == (2,) else shift
        if shift.shape != (b, 2) or not np.all(np.isfinite(shift)):
            raise ValueError(f"pinch_shift: expected finite (2,) or ({b}, 2) mm, got {np.shape(pinch_shift)}")
        return shift

    def _shifted_anchor(self, shift: np.ndarray) -> np.ndarray:
        b = self.task.num_envs
        anchor = self._anchor.reshape(b, -1, 3).copy()
        grasp = self._pin.reshape(b, -1) == int(kernels.PIN_GRASP)
        jx, jy = (j.reshape(b, -1, 3) for j in self._jacobian)
        moved = anchor + jx * shift[:, None, :1] + jy * shift[:, None, 1:]
        return np.where(grasp[..., None], moved, anchor).reshape(-1, 3).astype(np.float32)


def _deformation_gradient(settled: np.ndarray, nx: int, ny: int, grid) -> tuple[np.ndarray, np.ndarray]:
    """(B * N, 3) x2: the settled sheets' world position derivatives along material x and y (central
    differences on the grid, one-sided at its edges)."""
    b = settled.shape[0]
    hx, hy = grid.spacing_mm
    sheet = settled.reshape(b, ny, nx, 3).astype(np.float64)
    dy, dx = np.gradient(sheet, hy, hx, axis=(1, 2))
    return dx.reshape(-1, 3).astype(np.float32), dy.reshape(-1, 3).astype(np.float32)


class _StepTape:
    """One env step's replay under a tape, on arrays of its own that every step reuses: the forward
    kernels are recorded once, then each step copies its checkpoint, move, tips and path in, reruns them,
    seeds the end state's adjoint with the later step's and runs the backward pass, leaving the start
    state's adjoint for the earlier step. Recorded into a graph (``capture``), a step is one launch."""

    def __init__(self, owner: DifferentiableRollout, lo: int, hi: int, capture: bool):
        task = owner.task
        b, n, device = hi - lo, task.grid.num_vertices, task.sim.device
        ups = task.config.updates_per_step
        replay = Simulator(task.config, b, device=device, backend="colours", capture=False)
        replay.first_noise_stream = task.sim.first_noise_stream + lo
        self.replay, self.device, self.b, self.lo, self.hi, self.n = replay, device, b, lo, hi, n

        def grad_array(shape, dtype):
            return wp.zeros(shape, dtype=dtype, device=device, requires_grad=True)

        self.start = (grad_array(b * n, wp.vec3), grad_array(b * n, wp.vec3), grad_array(b, wp.vec3))
        self.alive = wp.zeros(b * n, dtype=wp.int32, device=device)
        self.action = grad_array(b, wp.vec3)
        self.shift = grad_array(b, wp.vec2)
        self.weight = wp.zeros(b, dtype=float, device=device)
        self.tips = [wp.zeros(b, dtype=wp.vec4, device=device) for _ in range(ups)]
        self.path = wp.zeros((b, ups), dtype=wp.vec3, device=device)
        self.target = wp.zeros((b, ups), dtype=wp.vec2, device=device)
        self.loss = grad_array(b, float)
        self.adjoint = tuple(wp.zeros_like(a) for a in self.start)
        rows = slice(lo * n, hi * n)
        anchor = wp.array(owner._anchor[rows], dtype=wp.vec3, device=device)
        jx, jy = (wp.array(j[rows], dtype=wp.vec3, device=device) for j in owner._jacobian)
        replay.pin.assign(owner._pin[rows])
        search = replay.tip_search()
        config = task.config

        replay.x, replay.x_prev, replay.displacement = self.start
        replay.alive = self.alive
        self.tape = wp.Tape()
        with self.tape:
            replay.anchor = wp.zeros_like(anchor, requires_grad=True)
            launch(
                kernels.grasp_anchor_kernel,
                dim=(b, n),
                inputs=[n, anchor, replay.pin, jx, jy, self.shift],
                outputs=[replay.anchor],
                device=device,
            )
            moved = wp.zeros_like(self.start[2], requires_grad=True)
            launch(
                kernels.move_grasp_kernel,
                dim=b,
                inputs=[config.max_step_mm, config.max_displacement_mm, self.start[2], self.action],
                outputs=[moved],
                device=device,
            )
            replay.displacement = moved
            for j in range(ups):
                replay.tip = self.tips[j]
                replay.sync_update_counter()  # each step sets the device counter (run), not update_count
                replay.update(tape_mode=True)
                launch(
                    kernels.path_surrogate_kernel,
                    dim=b,
                    inputs=[search, j, replay.x, self.tips[j], self.path, self.target, self.weight],
                    outputs=[self.loss],
                    device=device,
                )
        self.end = (replay.x, replay.x_prev, replay.displacement)
        self._zeroed = [
            a.grad
            for launch_ in self.tape.launches
            for a in (*launch_[3], *launch_[4])
            if isinstance(a, wp.array) and a.grad is not None and a is not self.shift
        ]
        self._zeroed = list({id(g): g for g in self._zeroed}.values())
        self.graph = None
        if capture:
            with wp.ScopedCapture(device=device) as recording:
                self._launch()
            self.graph = recording.graph

    def _launch(self) -> None:
        """Forward again, then backward from the seeded end state; the start's adjoint into ``adjoint``."""
        self.loss.zero_()
        for kernel, dim, max_blocks, inputs, outputs, device, block_dim, _ in self.tape.launches:
            wp.launch(
                kernel, dim=dim, inputs=inputs, outputs=outputs, device=device, max_blocks=max_blocks,
                block_dim=block_dim, record_tape=False,
            )  # fmt: skip
        for g in self._zeroed:
            g.zero_()
        self.loss.grad.fill_(1.0)
        for end, adjoint in zip(self.end, self.adjoint, strict=True):
            wp.copy(end.grad, adjoint)  # an end array that is also a start one (x_prev, one update) adds up
        self.tape.backward()
        for start, adjoint in zip(self.start, self.adjoint, strict=True):
            wp.copy(adjoint, start.grad)

    def begin(self, seed: int, shift: np.ndarray, weight: np.ndarray) -> None:
        """Start a backward pass: the episode's noise seed, and the batch's pinch shifts and surrogate
        weights (this part's rows are taken)."""
        self.replay.seed = seed
        self.shift.assign(shift[self.lo : self.hi].astype(np.float32))
        self.shift.grad.zero_()
        self.weight.assign(weight[self.lo : self.hi].astype(np.float32))
        self.cut_adjoint()

    def cut_adjoint(self) -> None:
        """Forget what later steps' surrogate terms ask of the state (a window's end)."""
        for adjoint in self.adjoint:
            adjoint.zero_()

    def run(self, first_update: int, state: dict, action, tips, path, target) -> np.ndarray:
        """Replay one step from the batch's ``state`` (its updates from ``first_update``); the gradient of
        the surrogate with respect to this part's rows of the (B, 3) ``action``. ``tips`` (B, ups, 4),
        ``path`` (B, ups, 3) and ``target`` (B, ups, 2) are the step's updates'."""
        lo, hi, n = self.lo, self.hi, self.n
        for array, key in zip(self.start, ("x", "x_prev"), strict=False):
            array.assign(state[key][lo * n : hi * n])
        self.start[2].assign(state["displacement"][lo:hi])
        self.alive.assign(state["alive"][lo * n : hi * n])
        self.action.assign(action[lo:hi])
        for j, array in enumerate(self.tips):
            array.assign(np.ascontiguousarray(tips[lo:hi, j]))
        self.path.assign(path[lo:hi])
        self.target.assign(target[lo:hi])
        self.replay.update_count = first_update
        self.replay.sync_update_counter()
        if self.graph is not None:
            wp.capture_launch(self.graph)
        else:
            self._launch()
        return self.action.grad.numpy().astype(np.float64)
