"""The ``simd`` backend's packed batch (:mod:`warpcut.sim.kernels_simd` has its layout and kernels): what
every env shares (:class:`SimdModel`: the springs in sweep order, the update's constants) and the packed
state of the batch (:class:`SimdState`): pack once per reset (:meth:`SimdState.load`), per update
:meth:`SimdState.load_controls` + :meth:`SimdState.step`, unpack on read-back (:meth:`SimdState.store`)."""

from dataclasses import dataclass

import numpy as np

from warpcut.sim._warp import LaunchRecords, launch, wp
from warpcut.sim.config import SheetGrid, SimConfig
from warpcut.sim.kernels_simd import DEFAULT_LANES, simd_kernels
from warpcut.sim.springs import colour_springs


@dataclass
class SimdModel:
    """What every env shares: the springs in sweep order and the constants of an update."""

    n: int
    sweeps: int
    chebyshev: int
    """1 if the sweeps are Chebyshev-accelerated (``SimConfig.chebyshev_rho > 0``)."""
    weights: wp.array
    """(sweeps,) float32 Chebyshev weight after each sweep (``SimConfig.sweep_weights``)."""
    pairs: wp.array
    """(num_springs,) ``vec2i``: each spring's two vertices, colour after colour."""
    colour_rest: wp.array
    """(num_colours,) rest length of each colour's springs (mm)."""
    colour_start: wp.array
    """(num_colours + 1,) where each colour's springs start in ``pairs``."""
    first_order_z: int
    cut_radius: float
    cut_height: float
    lower: wp.vec3
    """Lower corner of the box a vertex must stay in (mm; :attr:`SimConfig.runaway_bounds`)."""
    upper: wp.vec3
    """Upper corner of that box (mm)."""

    @classmethod
    def from_config(cls, config: SimConfig, grid: SheetGrid, device: str) -> "SimdModel":
        springs = colour_springs(grid, config.springs)
        pairs = np.stack(
            [np.concatenate([a for a, _, _ in springs]), np.concatenate([b for _, b, _ in springs])], axis=1
        )
        starts = np.concatenate([[0], np.cumsum([len(a) for a, _, _ in springs])])
        return cls(
            n=grid.num_vertices,
            sweeps=config.sweeps,
            chebyshev=int(config.chebyshev_rho > 0),
            weights=wp.array(config.sweep_weights, dtype=float, device=device),
            pairs=wp.array(pairs.astype(np.int32), dtype=wp.vec2i, device=device),
            colour_rest=wp.array(
                np.array([rest for _, _, rest in springs], dtype=np.float32), dtype=float, device=device
            ),
            colour_start=wp.array(starts.astype(np.int32), dtype=wp.int32, device=device),
            first_order_z=int(config.first_order_z),
            cut_radius=float(config.cut_radius),
            cut_height=float(config.cut_height),
            lower=wp.vec3(*config.runaway_bounds[0]),
            upper=wp.vec3(*config.runaway_bounds[1]),
        )


class SimdState:
    """The packed state of ``num_envs`` envs of ``n`` vertices, in blocks of ``lanes`` envs.

    Pack once per reset (:meth:`load`, :meth:`load_params`), per update :meth:`load_controls` (grasp
    displacement, tip: B x 7 floats) and :meth:`step`; unpack on read-back (:meth:`store`). Each pack or
    unpack is one pass over the batch's state.
    """

    def __init__(
        self, num_envs: int, n: int, lanes: int = DEFAULT_LANES, device: str = "cpu", chebyshev: bool = False
    ):
        if not wp.get_device(device).is_cpu:
            raise ValueError("device: the SIMD kernels are CPU kernels; use the colours backend on CUDA")
        self.kernels = simd_kernels(lanes)
        self.lanes = lanes
        self.num_envs = int(num_envs)
        self.n = int(n)
        self.device = device
        self.blocks = -(-self.num_envs // lanes)
        k = self.kernels
        size = self.blocks * self.n
        self.vert = wp.zeros(size, dtype=k.Vert, device=device)
        self.prev = wp.zeros(size, dtype=k.Prev, device=device)
        self.anchor = wp.zeros(size, dtype=k.Anchor, device=device)
        self.older = wp.zeros(2 * size if chebyshev else 0, dtype=k.Prev, device=device)
        """Scratch of the Chebyshev-accelerated sweeps (models with ``chebyshev``): two records per vertex."""
        self.lane_params = wp.zeros(self.blocks, dtype=k.Lanes, device=device)
        self.status = wp.zeros((2, self.num_envs), dtype=wp.int32, device=device)
        """(2, B) divergence flags of :meth:`step` without a ``status`` of the caller's: row 0 non-finite,
        row 1 beyond the bounds (``kernels.cut_kernel``)."""
        self.any_noise = 0
        self._lanes_view: np.ndarray | None = None
        self._launches = LaunchRecords()  # the per-update launches, replayed (one per slice for step)

    def load(self, x: wp.array, x_prev: wp.array, alive: wp.array, pin: wp.array, anchor: wp.array) -> None:
        """Env-major state (``B * n`` entries each, as the simulator holds it) into blocks."""
        launch(
            self.kernels.pack,
            dim=(self.blocks, self.n),
            inputs=[self.n, self.num_envs, x, x_prev, alive, pin, anchor, self.vert, self.prev, self.anchor],
            device=self.device,
        )

    def load_params(self, damping, dt, gravity, noise_std, elasticity) -> None:
        """Per-env parameter arrays of length 1 or B (read as ``p[env % len]``)."""
        self.any_noise = int(np.any(noise_std.numpy() > 0.0))
        launch(
            self.kernels.pack_params,
            dim=self.blocks,
            inputs=[self.num_envs, damping, dt, gravity, noise_std, elasticity, self.lane_params],
            device=self.device,
        )

    def load_controls(self, displacement: wp.array, tip: wp.array) -> None:
        """(B,) ``vec3`` grasp displacements and (B,) ``vec4`` tips; call after every change."""
        self._launches["controls"](
            self.kernels.pack_controls,
            dim=self.blocks,
            inputs=[self.num_envs, displacement, tip, self.lane_params],
            device=self.device,
        )

    def lane_views(self, envs: list[int]) -> list[np.ndarray]:
        """Per env of ``envs`` (valid indices), a zero-copy (n, 4) float32 view of its x, y, z and alive
        (1.0 or 0.0) lanes in the packed blocks (CPU memory; valid as long as this state): copying one out
        reads that env and nothing else of the batch, one strided copy."""
        view = self.packed_view()
        return [view[env // self.lanes, :, :4, env % self.lanes] for env in envs]

    def packed_view(self) -> np.ndarray:
        """A zero-copy (blocks, n, 5, lanes) float32 view of the packed vertices (CPU memory; valid as long
        as this state): field 0-4 are x, y, z, alive (1.0 or 0.0) and free; env ``e`` is lane ``e % lanes``
        of block ``e // lanes``."""
        if self._lanes_view is None:
            packed = self.vert.numpy()
            if packed.dtype.names[:4] != ("x", "y", "z", "alive") or packed.dtype.itemsize != 20 * self.lanes:
                raise RuntimeError(f"packed_view: unexpected vertex layout {packed.dtype}")
            self._lanes_view = packed.view(np.float32).reshape(self.blocks, self.n, 5, self.lanes)
        return self._lanes_view

    def store(self, x: wp.array, x_prev: wp.array, alive: wp.array) -> None:
        """Blocks back into env-major arrays (padding lanes dropped)."""
        launch(
            self.kernels.unpack,
            dim=(self.blocks, self.n),
            inputs=[self.n, self.num_envs, self.vert, self.prev, x, x_prev, alive],
            device=self.device,
        )

    def step(
        self,
        model: SimdModel,
        seed: int,
        block_offset: int = 0,
        block_count: int | None = None,
        first_stream: int = 0,
        status: wp.array | None = None,
    ) -> None:
        """One update of blocks ``[block_offset, block_offset + block_count)`` (default: to the end); env
        ``e`` draws noise stream ``first_stream + e``. Divergence is flagged in ``status`` (2, B) (default:
        :attr:`status`), as ``kernels.cut_kernel`` flags it.

        Disjoint block ranges may be stepped from different Python threads at once (``wp.launch``
        releases the GIL), as ``Simulator`` does with env slices.
        """
        count = self.blocks - block_offset if block_count is None else block_count
        if model.chebyshev and self.older.shape[0] < 2 * self.blocks * self.n:
            raise ValueError("model: Chebyshev sweeps need SimdState(..., chebyshev=True)")
        self._launches["update", block_offset](
            self.kernels.update,
            dim=count,
            inputs=[
                model.n,
                block_offset,
                model.sweeps,
                model.first_order_z,
                self.any_noise,
                int(seed),
                int(first_stream),
                self.num_envs,
                model.cut_radius,
                model.cut_height,
                model.lower,
                model.upper,
                model.pairs,
                model.colour_rest,
                model.colour_start,
                model.chebyshev,
                model.weights,
                self.lane_params,
                self.anchor,
            ],
            outputs=[self.vert, self.prev, self.status if status is None else status, self.older],
            device=self.device,
        )
