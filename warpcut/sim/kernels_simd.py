"""The ``simd`` backend (the default on CPU): one thread steps a *block* of ``L`` envs (8 by default) in
lockstep, in SIMD lanes.

Every value of an update becomes a ``vecL`` holding that value for the ``L`` envs, every ``if`` becomes a
per-lane select, and Warp's ``vec_t`` operations (fixed-length loops) compile to packed AVX instructions
(``vsqrtps``, ``vdivps``, ``vmulps`` on ``ymm`` registers with Warp's default ``-march=native``). The
relaxation loop is a ``wp.func_native`` C++ snippet with clang vector types, which avoids Warp's
per-access index arithmetic (negative-index wrap, spills).

Layout (structure of arrays, env innermost, "AoSoA"): env ``e`` is lane ``e % L`` of block ``e // L``;
a batch of ``B`` envs takes ``ceil(B / L)`` blocks, the padding lanes hold a copy of the last env and
their results are discarded. Per block and vertex ``i = block * n + v``:

- ``vert[i]``   (``Vert``, hot in the relaxation): ``x, y, z``, ``alive`` (1/0), ``free`` (1 where
  the vertex is not pinned), 5 x ``vecL`` = 160 bytes for ``L = 8``;
- ``prev[i]``   previous positions, ``anchor[i]`` anchors and a ``grasp`` mask (integration only).

Per block, ``lane_params[block]`` (``Lanes``) holds the per-env parameters, grasp displacement and
scissor tip.

**Bit-identical** to the ``colours`` kernels of :mod:`warpcut.sim.kernels`: every lane evaluates their
float expressions in the same order, spring colour by spring colour (Warp compiles CPU kernels without
FMA contraction), and each branch becomes a select whose discarded side never reaches the result (only
the sign of an exact zero may differ). Process noise draws the same stream (``process_noise(seed,
env * n + v)``), and the cut stage flags divergence as ``cut_kernel`` does (a few whole-lane vector
operations per vertex). Not differentiable; CPU only (the relaxation is C++ for the CPU compiler).

Use: keep a :class:`SimdState` for the batch: pack once per reset (:meth:`SimdState.load`), per update
:meth:`SimdState.load_controls` + :meth:`SimdState.step`, unpack on read-back (:meth:`SimdState.store`).
"""

import functools
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from warpcut.sim._warp import launch, wp
from warpcut.sim.config import SheetGrid, SimConfig
from warpcut.sim.kernels import PIN_FREE, PIN_GRASP, TipSearch, process_noise, tip_locator
from warpcut.sim.springs import colour_springs

DEFAULT_LANES = 8

_RELAX_SOURCE = """
    typedef float vf __attribute__((ext_vector_type(LANES), aligned(4)));
    typedef int vi __attribute__((ext_vector_type(LANES), aligned(4)));
    struct V { vf x, y, z, alive, free; };
    static_assert(sizeof(V) == 5 * LANES * sizeof(float), "Vert layout");
    V* block = (V*)vert.data + base;
    const int* pair = (const int*)pairs.data;
    const float* rest_of = (const float*)colour_rest.data;
    const int* start = (const int*)colour_start.data;
    const int num_colours = colour_start.shape[0] - 1;
    vf k;
    for (int lane = 0; lane < LANES; ++lane) k[lane] = stiff.c[lane];
    const vf one = 1.0f, half = 0.5f, zero = 0.0f, tiny = 1.0e-9f;
    for (int sweep = 0; sweep < sweeps; ++sweep) {
        for (int c = 0; c < num_colours; ++c) {
            const float rest = rest_of[c];
            const int end = start[c + 1];
            for (int s = start[c]; s < end; ++s) {
                V* pa = block + pair[2 * s];
                V* pb = block + pair[2 * s + 1];
                const vf ax = pa->x, ay = pa->y, az = pa->z;
                const vf bx = pb->x, by = pb->y, bz = pb->z;
                const vf fa = pa->free, fb = pb->free;
                const vf live = pa->alive * pb->alive;
                const vf dx = bx - ax, dy = by - ay, dz = bz - az;
                const vf length = __builtin_elementwise_sqrt(dx * dx + dy * dy + dz * dz);
                const vf share = one - half * (fa * fb);
                const vi ok = (live != zero) & (length >= tiny);
                vf scale = k * share * (length - rest) / length;
                scale = (vf)((vi)scale & ok);
                const vf sa = scale * fa, sb = scale * fb;
                pa->x = ax + dx * sa;
                pa->y = ay + dy * sa;
                pa->z = az + dz * sa;
                pb->x = bx + (ax - bx) * sb;
                pb->y = by + (ay - by) * sb;
                pb->z = bz + (az - bz) * sb;
            }
        }
    }
"""


@functools.cache
def simd_kernels(lanes: int = DEFAULT_LANES) -> SimpleNamespace:
    """Types and kernels for ``lanes`` envs per block, in their own Warp module (compiled on first use)."""
    if lanes not in (2, 4, 8, 16, 32):
        raise ValueError(f"lanes: choose a power of two from 2 to 32 (got {lanes!r}); 8 fills AVX registers")
    types = _lane_types(lanes)
    module = f"warpcut.sim.kernels_simd_L{lanes}"
    return SimpleNamespace(
        **vars(types),
        update=_update_kernel(types, module),
        **_packing_kernels(types, module),
        map_tip=_map_tip_kernel(types, module),
    )


def _lane_types(lanes: int) -> SimpleNamespace:
    """The per-block records of ``lanes`` envs: ``Vert``, ``Prev``, ``Anchor`` and ``Lanes`` (module doc)."""
    vecL = wp.types.vector(length=lanes, dtype=wp.float32)  # noqa: N806 (a type)

    @wp.struct
    class Vert:
        x: vecL
        y: vecL
        z: vecL
        alive: vecL
        free: vecL

    @wp.struct
    class Prev:
        x: vecL
        y: vecL
        z: vecL

    @wp.struct
    class Anchor:
        x: vecL
        y: vecL
        z: vecL
        grasp: vecL

    @wp.struct
    class Lanes:
        keep: vecL
        fall: vecL
        stiff: vecL
        sigma: vecL
        ux: vecL
        uy: vecL
        uz: vecL
        tx: vecL
        ty: vecL
        tz: vecL
        cutting: vecL

    return SimpleNamespace(lanes=lanes, vec=vecL, Vert=Vert, Prev=Prev, Anchor=Anchor, Lanes=Lanes)


def _relax_func(types: SimpleNamespace) -> wp.Function:
    """The native function that relaxes the springs of one block of ``L`` envs (:data:`_RELAX_SOURCE`)."""
    vecL, Vert = types.vec, types.Vert  # noqa: N806 (types)

    @wp.func_native(_RELAX_SOURCE.replace("LANES", str(types.lanes)))
    def relax(
        vert: wp.array(dtype=Vert),
        pairs: wp.array(dtype=wp.vec2i),
        colour_rest: wp.array(dtype=float),
        colour_start: wp.array(dtype=wp.int32),
        sweeps: int,
        base: int,
        stiff: vecL,
    ):
        """``sweeps`` Gauss-Seidel sweeps of one block, colour by colour, ``L`` envs per spring."""

    return relax


def _update_kernel(types: SimpleNamespace, module: str) -> wp.Kernel:
    """The kernel of one update (integrate, relax, cut) of ``L`` envs per thread, in place."""
    L, vecL = types.lanes, types.vec  # noqa: N806 (a constant and a type, as the kernel reads them)
    Vert, Prev, Anchor, Lanes = types.Vert, types.Prev, types.Anchor, types.Lanes  # noqa: N806
    relax = _relax_func(types)

    @wp.kernel(enable_backward=False, module=module)
    def update_kernel(
        # Model:
        n: int,
        block_offset: int,
        sweeps: int,
        first_order_z: int,
        any_noise: int,
        seed: int,
        first_stream: int,
        num_envs: int,
        cut_radius: float,
        cut_height: float,
        lower: wp.vec3,
        upper: wp.vec3,
        pairs: wp.array(dtype=wp.vec2i),
        colour_rest: wp.array(dtype=float),
        colour_start: wp.array(dtype=wp.int32),
        lane_params: wp.array(dtype=Lanes),
        anchor: wp.array(dtype=Anchor),
        # Data in/out:
        vert: wp.array(dtype=Vert),
        prev: wp.array(dtype=Prev),
        status: wp.array2d(dtype=wp.int32),
    ):
        blk = wp.tid() + block_offset
        base = blk * n
        p = lane_params[blk]
        # ---- integrate: integrate_kernel's expressions per lane, its branches as selects
        for v in range(n):
            i = base + v
            vt = vert[i]
            an = anchor[i]
            pv = prev[i]
            vx = wp.cw_mul(vt.x - pv.x, p.keep)
            vy = wp.cw_mul(vt.y - pv.y, p.keep)
            vz = wp.cw_mul(vt.z - pv.z, p.keep)
            if first_order_z != 0:
                vz = vecL()
            qx = vt.x + vx
            qy = vt.y + vy
            qz = (vt.z + vz) - p.fall
            gx = an.x + p.ux
            gy = an.y + p.uy
            gz = an.z + p.uz
            nx = vecL()
            ny = vecL()
            nz = vecL()
            for lane in range(L):
                free = vt.free[lane] != 0.0
                moving = free and vt.alive[lane] != 0.0
                grasped = an.grasp[lane] != 0.0
                # fixture: anchor; grasp: anchor + u; free and alive: Verlet; free and cut: frozen
                px = wp.where(grasped, gx[lane], an.x[lane])
                py = wp.where(grasped, gy[lane], an.y[lane])
                pz = wp.where(grasped, gz[lane], an.z[lane])
                nx[lane] = wp.where(moving, qx[lane], wp.where(free, vt.x[lane], px))
                ny[lane] = wp.where(moving, qy[lane], wp.where(free, vt.y[lane], py))
                nz[lane] = wp.where(moving, qz[lane], wp.where(free, vt.z[lane], pz))
            if any_noise != 0:
                for lane in range(L):
                    env = blk * L + lane
                    sigma = p.sigma[lane]
                    if sigma > 0.0 and vt.free[lane] != 0.0 and vt.alive[lane] != 0.0 and env < num_envs:
                        r = process_noise(seed, env * n + v + first_stream * n)
                        nx[lane] = nx[lane] + sigma * r[0]
                        ny[lane] = ny[lane] + sigma * r[1]
                        nz[lane] = nz[lane] + sigma * r[2]
            prev[i].x = vt.x
            prev[i].y = vt.y
            prev[i].z = vt.z
            vert[i].x = nx
            vert[i].y = ny
            vert[i].z = nz
        # ---- relax
        relax(vert, pairs, colour_rest, colour_start, sweeps, base, p.stiff)
        # ---- cut, and watch for divergence (cut_kernel's status, in whole-lane vector operations: x - x is
        # 0 for a finite x and NaN otherwise; ``beyond`` is the largest distance outside lower .. upper)
        r2 = cut_radius * cut_radius
        lo_x = vecL(lower[0])
        lo_y = vecL(lower[1])
        hi_x = vecL(upper[0])
        hi_y = vecL(upper[1])
        hi_z = vecL(upper[2])
        not_finite = vecL()
        beyond = vecL()
        for v in range(n):
            i = base + v
            vt = vert[i]
            ex = vt.x - p.tx
            ey = vt.y - p.ty
            d2 = wp.cw_mul(ex, ex) + wp.cw_mul(ey, ey)
            ez = vt.z - p.tz
            alive = vecL()
            for lane in range(L):
                hit = p.cutting[lane] > 0.5 and d2[lane] <= r2 and wp.abs(ez[lane]) <= cut_height
                alive[lane] = wp.where(hit, 0.0, vt.alive[lane])
            vert[i].alive = alive
            not_finite = not_finite + (vt.x - vt.x) + (vt.y - vt.y) + (vt.z - vt.z)
            out_x = wp.max(vt.x - hi_x, lo_x - vt.x)
            out_y = wp.max(vt.y - hi_y, lo_y - vt.y)
            beyond = wp.max(beyond, wp.max(wp.max(out_x, out_y), vt.z - hi_z))
        for lane in range(L):
            env = blk * L + lane
            if env < num_envs:
                if not_finite[lane] != 0.0:
                    status[0, env] = 1
                elif beyond[lane] > 0.0:
                    status[1, env] = 1

    return update_kernel


def _packing_kernels(types: SimpleNamespace, module: str) -> dict[str, wp.Kernel]:
    """Kernels that copy state, parameters and controls between the env-major arrays and the blocks."""
    L = types.lanes  # noqa: N806 (a constant, as the kernels read it)
    Vert, Prev, Anchor, Lanes = types.Vert, types.Prev, types.Anchor, types.Lanes  # noqa: N806

    @wp.kernel(enable_backward=False, module=module)
    def pack_kernel(
        n: int,
        num_envs: int,
        x: wp.array(dtype=wp.vec3),
        x_prev: wp.array(dtype=wp.vec3),
        alive: wp.array(dtype=wp.int32),
        pin: wp.array(dtype=wp.int32),
        anchor_in: wp.array(dtype=wp.vec3),
        vert: wp.array(dtype=Vert),
        prev: wp.array(dtype=Prev),
        anchor: wp.array(dtype=Anchor),
    ):
        """Env-major ``vec3`` state into blocks; padding lanes copy the last env."""
        blk, v = wp.tid()
        vt = Vert()
        pv = Prev()
        an = Anchor()
        for lane in range(L):
            j = wp.min(blk * L + lane, num_envs - 1) * n + v
            p = x[j]
            q = x_prev[j]
            r = anchor_in[j]
            vt.x[lane] = p[0]
            vt.y[lane] = p[1]
            vt.z[lane] = p[2]
            vt.alive[lane] = wp.where(alive[j] != 0, 1.0, 0.0)
            vt.free[lane] = wp.where(pin[j] == PIN_FREE, 1.0, 0.0)
            pv.x[lane] = q[0]
            pv.y[lane] = q[1]
            pv.z[lane] = q[2]
            an.x[lane] = r[0]
            an.y[lane] = r[1]
            an.z[lane] = r[2]
            an.grasp[lane] = wp.where(pin[j] == PIN_GRASP, 1.0, 0.0)
        i = blk * n + v
        vert[i] = vt
        prev[i] = pv
        anchor[i] = an

    @wp.kernel(enable_backward=False, module=module)
    def unpack_kernel(
        n: int,
        num_envs: int,
        vert: wp.array(dtype=Vert),
        prev: wp.array(dtype=Prev),
        x: wp.array(dtype=wp.vec3),
        x_prev: wp.array(dtype=wp.vec3),
        alive: wp.array(dtype=wp.int32),
    ):
        """Blocks back into env-major ``vec3`` state; padding lanes dropped."""
        blk, v = wp.tid()
        i = blk * n + v
        vt = vert[i]
        pv = prev[i]
        for lane in range(L):
            env = blk * L + lane
            if env < num_envs:
                j = env * n + v
                x[j] = wp.vec3(vt.x[lane], vt.y[lane], vt.z[lane])
                x_prev[j] = wp.vec3(pv.x[lane], pv.y[lane], pv.z[lane])
                alive[j] = wp.where(vt.alive[lane] != 0.0, 1, 0)

    @wp.kernel(enable_backward=False, module=module)
    def pack_params_kernel(
        num_envs: int,
        damping: wp.array(dtype=float),
        dt: wp.array(dtype=float),
        gravity: wp.array(dtype=float),
        noise_std: wp.array(dtype=float),
        elasticity: wp.array(dtype=float),
        lane_params: wp.array(dtype=Lanes),
    ):
        """Per-env parameters into lanes, with integrate_kernel's expressions (``g * h * h``)."""
        blk = wp.tid()
        for lane in range(L):
            env = wp.min(blk * L + lane, num_envs - 1)
            h = dt[env % dt.shape[0]]
            lane_params[blk].keep[lane] = damping[env % damping.shape[0]]
            lane_params[blk].fall[lane] = gravity[env % gravity.shape[0]] * h * h
            lane_params[blk].stiff[lane] = elasticity[env % elasticity.shape[0]]
            lane_params[blk].sigma[lane] = noise_std[env % noise_std.shape[0]]

    @wp.kernel(enable_backward=False, module=module)
    def pack_controls_kernel(
        num_envs: int,
        displacement: wp.array(dtype=wp.vec3),
        tip: wp.array(dtype=wp.vec4),
        lane_params: wp.array(dtype=Lanes),
    ):
        """Grasp displacements and scissor tips into lanes (every update)."""
        blk = wp.tid()
        for lane in range(L):
            env = wp.min(blk * L + lane, num_envs - 1)
            u = displacement[env]
            t = tip[env]
            lane_params[blk].ux[lane] = u[0]
            lane_params[blk].uy[lane] = u[1]
            lane_params[blk].uz[lane] = u[2]
            lane_params[blk].tx[lane] = t[0]
            lane_params[blk].ty[lane] = t[1]
            lane_params[blk].tz[lane] = t[2]
            lane_params[blk].cutting[lane] = t[3]

    return {
        "pack": pack_kernel,
        "unpack": unpack_kernel,
        "pack_params": pack_params_kernel,
        "pack_controls": pack_controls_kernel,
    }


def _map_tip_kernel(types: SimpleNamespace, module: str) -> wp.Kernel:
    """:func:`warpcut.sim.kernels.map_tip_kernel` for the ``L`` envs of a block, reading the packed state:
    the same search (:func:`warpcut.sim.kernels.tip_locator`), so the same bits."""
    L, Vert = types.lanes, types.Vert  # noqa: N806 (a constant and a type, as the kernel reads them)

    @wp.func
    def lane_corner(vert: wp.array(dtype=Vert), lane: int, i: int) -> wp.vec4:
        """Vertex ``i`` of the blocks, in lane ``lane``, as ``(x, y, z, alive)``."""
        return wp.vec4(vert[i].x[lane], vert[i].y[lane], vert[i].z[lane], vert[i].alive[lane])

    locate_tip = tip_locator(wp.array(dtype=Vert), int, lane_corner, f"locate_tip_L{L}", module)

    @wp.kernel(enable_backward=False, module=module)
    def map_tip_kernel(
        # Model:
        search: TipSearch,
        block_offset: int,
        num_envs: int,
        update: int,
        # Data in:
        vert: wp.array(dtype=Vert),
        tip: wp.array(dtype=wp.vec4),
        # Data in/out:
        removed_at: wp.array(dtype=wp.int32),
        # Data out:
        path: wp.array2d(dtype=wp.vec3),
    ):
        blk = wp.tid() + block_offset
        n = search.nx * search.ny
        base = blk * n
        for v in range(n):
            alive = vert[base + v].alive
            for lane in range(L):
                env = blk * L + lane
                if alive[lane] == 0.0 and env < num_envs:
                    if removed_at[env * n + v] < 0:
                        removed_at[env * n + v] = update
        for lane in range(L):
            env = blk * L + lane
            if env < num_envs:
                path[env, update] = locate_tip(
                    vert, lane, base, env, update, tip[env], removed_at, path, search
                )

    return map_tip_kernel


@dataclass
class SimdModel:
    """What every env shares: the springs in sweep order and the constants of an update."""

    n: int
    sweeps: int
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

    def __init__(self, num_envs: int, n: int, lanes: int = DEFAULT_LANES, device: str = "cpu"):
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
        self.lane_params = wp.zeros(self.blocks, dtype=k.Lanes, device=device)
        self.status = wp.zeros((2, self.num_envs), dtype=wp.int32, device=device)
        """(2, B) divergence flags of :meth:`step` without a ``status`` of the caller's: row 0 non-finite,
        row 1 beyond the bounds (``kernels.cut_kernel``)."""
        self.any_noise = 0
        self._lanes_view: np.ndarray | None = None

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
        launch(
            self.kernels.pack_controls,
            dim=self.blocks,
            inputs=[self.num_envs, displacement, tip, self.lane_params],
            device=self.device,
        )

    def lane_views(self, envs: list[int]) -> list[np.ndarray]:
        """Per env of ``envs`` (valid indices), a zero-copy (n, 4) float32 view of its x, y, z and alive
        (1.0 or 0.0) lanes in the packed blocks (CPU memory; valid as long as this state): copying one out
        reads that env and nothing else of the batch, one strided copy."""
        if self._lanes_view is None:
            # (blocks, n, fields, lanes) over ``struct V`` (x, y, z, alive, free), made once.
            packed = self.vert.numpy()
            if packed.dtype.names[:4] != ("x", "y", "z", "alive") or packed.dtype.itemsize != 20 * self.lanes:
                raise RuntimeError(f"lane_views: unexpected vertex layout {packed.dtype}")
            self._lanes_view = packed.view(np.float32).reshape(self.blocks, self.n, 5, self.lanes)
        return [self._lanes_view[env // self.lanes, :, :4, env % self.lanes] for env in envs]

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
        launch(
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
                self.lane_params,
                self.anchor,
            ],
            outputs=[self.vert, self.prev, self.status if status is None else status],
            device=self.device,
        )
