"""Reading a :class:`~warpcut.sim.simulator.Simulator`'s sheets back to NumPy: the whole batch, a few envs,
or a few vertices of every env, each read the cheapest way its backend allows (docs/performance.md,
sections 5 and 6); the grasps' displacements and which envs diverged; and the state as a checkpoint to
continue from."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from warpcut.sim._warp import wp

if TYPE_CHECKING:
    from warpcut.sim.config import SheetGrid
    from warpcut.sim.simd import SimdState


class StateReads:
    """The read-back methods of :class:`~warpcut.sim.simulator.Simulator`, which it inherits (one module per
    concern; the simulator's own module holds the stepping). They read the simulator's ``x`` and ``alive``
    arrays, or the ``simd`` backend's packed blocks (``_simd``) while those hold the newer state
    (``_flat_current`` False); and the grasp displacements and the divergence flags every update sets. The
    checkpoint (:meth:`state`, :meth:`load_state`) reads the state out and writes it back."""

    num_envs: int
    device: str
    grid: SheetGrid
    x: wp.array
    alive: wp.array
    x_prev: wp.array
    displacement: wp.array
    update_count: int
    _status: wp.array
    _simd: SimdState | None
    _is_cpu: bool
    _flat_current: bool
    _packed_current: bool
    _counter_synced: bool
    _spare: wp.array
    _buffers: list[wp.array]
    _alive: list[wp.array]
    _displacement_own: wp.array

    def _sync_flat(self) -> None:  # the simulator's: unpack the blocks into x and alive if they are newer
        raise NotImplementedError

    def positions(self) -> np.ndarray:
        """(B, N, 3) current vertex positions (mm)."""
        self._sync_flat()
        return self.x.numpy().reshape(self.num_envs, self.grid.num_vertices, 3).copy()

    def alive_mask(self) -> np.ndarray:
        """(B, N) bool: False where the scissors removed the vertex."""
        self._sync_flat()
        return self.alive.numpy().reshape(self.num_envs, self.grid.num_vertices).astype(bool)

    def read_envs(self, envs: np.ndarray | list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Positions (k, N, 3) float32 (mm) and alive masks (k, N) bool of the envs ``envs`` (k,) only.

        The same values as ``positions()[envs]`` and ``alive_mask()[envs]``, but only those envs are read
        (see :meth:`read_state`). For recorders that watch a few envs of a big batch.
        """
        state = self.read_state(envs)
        return np.ascontiguousarray(state[..., :3]), state[..., 3] != 0.0

    def read_state(self, envs: np.ndarray | list[int], out: np.ndarray | None = None) -> np.ndarray:
        """(k, N, 4) float32 state of the envs ``envs`` (k,) only: x, y, z (mm) and alive (1.0, or 0.0 where
        the scissors removed the vertex), written into ``out`` if given.

        The cheapest read-back of a few envs: the ``simd`` backend copies their lanes out of the packed
        blocks (one strided copy per env) instead of unpacking the whole batch as :meth:`positions` and
        :meth:`alive_mask` do, and on a GPU only their slices are copied. A step callback that reads the
        same envs every step calls :meth:`state_reader` once instead.
        """
        return self.state_reader(envs)(out)

    def state_reader(self, envs: np.ndarray | list[int]) -> Callable[..., np.ndarray]:
        """A function ``read(out=None)`` that does what ``read_state(envs, out)`` does, with the checks and
        lookups done once, here: what a recorder's step callback calls every step (in the stepping loop the
        simulation's kernels have evicted Python's own working set, and every call it makes is slow;
        docs/performance.md §5)."""
        envs = np.asarray(envs, dtype=np.intp).reshape(-1)
        if envs.size and (envs.min() < 0 or envs.max() >= self.num_envs):
            raise ValueError(f"envs: indices must lie in [0, {self.num_envs}) (got {envs.tolist()})")
        envs = envs.tolist()
        n = self.grid.num_vertices
        shape = (len(envs), n, 4)
        lanes = self._simd.lane_views(envs) if self._simd is not None and self._is_cpu else None

        def read(out: np.ndarray | None = None) -> np.ndarray:
            if out is None:
                out = np.empty(shape, dtype=np.float32)
            elif out.shape != shape or out.dtype != np.float32:
                raise ValueError(
                    f"out: expected a float32 array of shape {shape}, got {out.dtype} {out.shape}"
                )
            if not self._flat_current:
                for k, lane in enumerate(lanes):
                    out[k] = lane
            elif self._is_cpu:
                x = self.x.numpy().reshape(self.num_envs, n, 3)
                alive = self.alive.numpy().reshape(self.num_envs, n)
                for k, env in enumerate(envs):
                    out[k, :, :3] = x[env]
                    out[k, :, 3] = alive[env] != 0
            else:
                for k, env in enumerate(envs):
                    out[k, :, :3] = self.x[env * n : (env + 1) * n].numpy()
                    out[k, :, 3] = self.alive[env * n : (env + 1) * n].numpy() != 0
            return out

        return read

    def gather(self, vertices: np.ndarray) -> np.ndarray:
        """(B, K, 4) float32 state of K vertices per env, ``vertices`` (B, K) indices: x, y, z (mm) and alive
        (1.0, or 0.0 where the scissors removed the vertex).

        The same values as ``positions()`` and ``alive_mask()`` at those indices, without reading the rest:
        the ``simd`` backend takes them from its packed blocks in place instead of unpacking the batch (what
        the envs' observations read every step: fiducials, the scissors' target; docs/performance.md). To
        read the same vertices every step, make a :meth:`gatherer` once."""
        return self.gatherer(vertices)()

    def interpolator(
        self, vertices: np.ndarray, weights: np.ndarray
    ) -> Callable[[], tuple[np.ndarray, np.ndarray]]:
        """A function ``read()`` that returns where material points are now and whether their cells are
        whole: ``(world, whole)``, (B, K, 3) float64 positions (mm) and (B, K) bool, for points whose cells
        are ``vertices`` and ``weights`` (B, K, 4) each (:func:`warpcut.sim.material.material_cells`).

        The values of ``interpolate_state(gather(vertices), weights)`` (:mod:`warpcut.sim.material`), bit for
        bit. The ``simd`` backend computes them in one kernel from
        its packed blocks (the envs observe the fiducials every step: the gather and the interpolation in
        NumPy cost as much as the rest of an observation; docs/performance.md, section 6); otherwise they
        are computed so.
        """
        from warpcut.sim._warp import LaunchRecord, wp
        from warpcut.sim.material import interpolate_state

        vertices = np.asarray(vertices, dtype=np.intp)
        weights = np.asarray(weights, dtype=np.float64)
        b = self.num_envs
        if (
            vertices.ndim != 3
            or vertices.shape[0] != b
            or vertices.shape[2] != 4
            or weights.shape != vertices.shape
        ):
            raise ValueError(
                f"vertices, weights: expected ({b}, K, 4) each, got {vertices.shape} and {weights.shape}"
            )
        gather = self.gatherer(vertices.reshape(b, -1))  # checks the indices

        def read_gathered() -> tuple[np.ndarray, np.ndarray]:
            return interpolate_state(gather().reshape(vertices.shape + (4,)), weights)

        if self._simd is None or not self._is_cpu:
            return read_gathered
        k = vertices.shape[1]
        cells = wp.array(vertices.astype(np.int32), dtype=wp.int32, device=self.device)
        cell_weights = wp.array(weights, dtype=wp.float64, device=self.device)
        world = wp.empty((b, k, 3), dtype=wp.float64, device=self.device)
        whole = wp.empty((b, k), dtype=wp.int32, device=self.device)
        world_view, whole_view = world.numpy(), whole.numpy()  # zero-copy on the CPU
        launch = LaunchRecord()
        packed: dict = {}  # of the blocks last read: their state object and a flat float array of them

        def read() -> tuple[np.ndarray, np.ndarray]:
            simd = self._simd
            if self._flat_current or simd is None:
                return read_gathered()
            if packed.get("state") is not simd:
                flat = wp.array(
                    simd.packed_view().reshape(-1), dtype=wp.float32, device=self.device, copy=False
                )
                packed.update(state=simd, flat=flat)
            kernel = simd.kernels.interpolate_cells
            launch(kernel, (b, k), [simd.n, cells, cell_weights, packed["flat"]], [world, whole], self.device)
            return world_view.copy(), whole_view != 0

        return read

    def gatherer(self, vertices: np.ndarray) -> Callable[[], np.ndarray]:
        """A function ``read()`` that returns what ``gather(vertices)`` returns at the time of the call, with
        the indices checked and their offsets in the packed blocks computed once, here (for a reader of the
        same vertices every step: the offsets cost as much as the read; docs/performance.md, section 6).
        """
        vertices = np.asarray(vertices, dtype=np.intp)
        n = self.grid.num_vertices
        if vertices.ndim != 2 or vertices.shape[0] != self.num_envs:
            raise ValueError(f"vertices: expected ({self.num_envs}, K) indices, got shape {vertices.shape}")
        if vertices.size and (vertices.min() < 0 or vertices.max() >= n):
            raise ValueError(f"vertices: indices must lie in [0, {n})")
        vertices = vertices.copy()  # the caller's array may change; this reader's vertices do not
        offsets: dict = {}  # of the packed blocks last read: their state object and the flat indices

        def read() -> np.ndarray:
            simd = self._simd
            if not self._flat_current and simd is not None and self._is_cpu:
                view = simd.packed_view()  # (blocks, n, fields, lanes), contiguous
                if offsets.get("state") is not simd:
                    _, _, fields, lanes = view.shape
                    env = np.arange(self.num_envs)[:, None]
                    first = ((env // lanes) * n + vertices) * (fields * lanes) + env % lanes
                    offsets.update(state=simd, index=first[..., None] + lanes * np.arange(4))
                return np.take(view.reshape(-1), offsets["index"])  # a float32 copy
            self._sync_flat()
            x = self.x.numpy().reshape(self.num_envs, n, 3)
            alive = self.alive.numpy().reshape(self.num_envs, n)
            out = np.empty(vertices.shape + (4,), dtype=np.float32)
            out[..., :3] = np.take_along_axis(x, vertices[..., None], axis=1)
            out[..., 3] = np.take_along_axis(alive, vertices, axis=1) != 0
            return out

        return read

    def displacements(self) -> np.ndarray:
        """(B, 3) grasp displacement from where it pinched (mm)."""
        return self.displacement.numpy().copy()

    def diverged(self) -> np.ndarray:
        """(B,) bool: envs whose state left the physical range since the last reset (a non-finite vertex
        coordinate, or a vertex beyond :attr:`SimConfig.runaway_bounds`). Cheap: B flags set by the
        kernels of every update; no state is read back."""
        return self.divergence() != 0

    def divergence(self) -> np.ndarray:
        """(B,) int8 why each env diverged since the last reset: 0 it did not, 1 a non-finite vertex
        coordinate (:data:`~warpcut.sim.checks.DIVERGENCE_REASONS`), 2 a vertex flung beyond the bounds."""
        status = self._status.numpy()
        return np.where(status[0] != 0, 1, np.where(status[1] != 0, 2, 0)).astype(np.int8)

    # ------------------------------------------------------------------ checkpoint
    def state(self) -> dict:
        """A copy of what the next updates start from: ``x``, ``x_prev`` (B * N, 3), ``alive`` (B * N,),
        ``displacement`` (B, 3) and ``update_count`` (the noise stream): a checkpoint for :meth:`load_state`
        (pins, anchors, seed and tips are the caller's to keep; the traced path is not part of it)."""
        self._sync_flat()
        arrays = {k: getattr(self, k).numpy().copy() for k in ("x", "x_prev", "alive", "displacement")}
        return {**arrays, "update_count": self.update_count}

    def load_state(self, state: dict, requires_grad: bool = False) -> None:
        """Continue from a :meth:`state`, of this simulator or another of the same shape; with
        ``requires_grad`` into fresh arrays that record gradients, as the start of a taped replay."""
        if requires_grad:
            for k in ("x", "x_prev", "alive", "displacement"):
                dtype = wp.int32 if k == "alive" else wp.vec3
                setattr(
                    self, k, wp.array(state[k], dtype=dtype, device=self.device, requires_grad=k != "alive")
                )
        else:
            self.x, self.x_prev, self._spare = self._buffers
            self.alive, self.displacement = self._alive[0], self._displacement_own
            for k in ("x", "x_prev", "alive", "displacement"):
                getattr(self, k).assign(state[k])
        self.update_count = int(state["update_count"])
        self._counter_synced = False
        self._flat_current, self._packed_current = True, False
