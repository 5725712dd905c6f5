"""Prototype CPU backend: the fused update with ``L`` envs per thread in SIMD lanes.

:func:`warpcut.sim.kernels.fused_update_kernel` steps one env per thread with scalar code. Here one thread
steps a *block* of ``L`` envs (8 by default) in lockstep: every value of the fused kernel becomes a
``vecL`` holding that value for the ``L`` envs, every ``if`` becomes a per-lane select, and Warp's
``vec_t`` operations (fixed-length loops) compile to packed AVX instructions (``vsqrtps``, ``vdivps``,
``vmulps`` on ``ymm`` registers with Warp's default ``-march=native``).

Layout (structure of arrays, env innermost, "AoSoA"): env ``e`` is lane ``e % L`` of block ``e // L``;
a batch of ``B`` envs takes ``ceil(B / L)`` blocks, the padding lanes hold a copy of the last env and
their results are discarded. Per block and vertex ``i = block * n + v``:

- ``vert[i]``   (:class:`Vert`, hot in the relaxation): ``x, y, z``, ``alive`` (1/0), ``free`` (1 where
  the vertex is not pinned), 5 x ``vecL`` = 160 bytes for ``L = 8``;
- ``prev[i]``   previous positions, ``anchor[i]`` anchors and a ``grasp`` mask (integration only).

Per block, ``lane_params[block]`` (:class:`Lanes`) holds the per-env parameters, grasp displacement
and scissor tip.

Two relaxation loops compute the same thing: ``relax="warp"`` is plain Warp (auto-vectorized), and
``relax="native"`` is the same loop as a ``wp.func_native`` C++ snippet with clang vector types, which
avoids Warp's per-access index arithmetic (negative-index wrap, spills) and is ~10% faster
(``scripts/simd_bench.py``: 25 x 25, B = 1024, one thread, default physics: fused 1.9k env updates/s,
``warp`` 17.6k, ``native`` 19.4k; paper sweeps: 14.2k, 110k, 120k).

Both are **bit-identical** to the fused kernel: every lane evaluates the fused kernel's float
expressions in the same order (Warp compiles CPU kernels without FMA contraction), and each branch
becomes a select whose discarded side never reaches the result (only the sign of an exact zero may
differ). Process noise is supported and draws the fused kernel's stream (``process_noise(seed, env * n +
v)``). Not differentiable; CPU only (``relax="native"`` is C++ for the CPU compiler).

Use: keep a :class:`SimdState` for the batch (pack once per reset with :meth:`SimdState.load`, per update
:meth:`SimdState.load_controls` + :meth:`SimdState.step`, unpack on read-back with
:meth:`SimdState.store`), or call :func:`simd_update` with the arguments of ``fused_update_kernel``
(packs and unpacks every call). ``scripts/simd_bench.py`` measures it.
"""

import functools
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from warpcut.sim._warp import wp
from warpcut.sim.kernels import (
    PATH_DROPPED,
    PATH_IDLE,
    PATH_MAPPED,
    PIN_FREE,
    PIN_GRASP,
    locate_in_cell,
    process_noise,
    search_window,
    usable,
)

DEFAULT_LANES = 8
RELAX_MODES = ("warp", "native")

_NATIVE_RELAX = """
    typedef float vf __attribute__((ext_vector_type(LANES), aligned(4)));
    typedef int vi __attribute__((ext_vector_type(LANES), aligned(4)));
    struct V { vf x, y, z, alive, free; };
    static_assert(sizeof(V) == 5 * LANES * sizeof(float), "Vert layout");
    V* block = (V*)vert.data + base;
    const int* pair = (const int*)pairs.data;
    const float* rest_of = (const float*)spring_rest.data;
    const int* start = (const int*)colour_start.data;
    const int num_colours = colour_start.shape[0] - 1;
    vf k;
    for (int lane = 0; lane < LANES; ++lane) k[lane] = stiff.c[lane];
    const vf one = 1.0f, half = 0.5f, zero = 0.0f, tiny = 1.0e-9f;
    for (int sweep = 0; sweep < iterations; ++sweep) {
        for (int c = 0; c < num_colours; ++c) {
            const float rest = rest_of[start[c]];
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
    L = lanes
    vecL = wp.types.vector(length=L, dtype=wp.float32)
    module = f"warpcut.kernels_simd_L{L}"

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

    @wp.func
    def relax_warp(
        vert: wp.array(dtype=Vert),
        pairs: wp.array(dtype=wp.vec2i),
        spring_rest: wp.array(dtype=float),
        colour_start: wp.array(dtype=wp.int32),
        iterations: int,
        base: int,
        stiff: vecL,
    ):
        """``iterations`` Gauss-Seidel sweeps of one block, colour by colour, ``L`` envs per spring."""
        one = vecL()
        half = vecL()
        for lane in range(L):
            one[lane] = 1.0
            half[lane] = 0.5
        num_colours = colour_start.shape[0] - 1
        for _sweep in range(iterations):
            for c in range(num_colours):
                rest = spring_rest[colour_start[c]]
                for s in range(colour_start[c], colour_start[c + 1]):
                    ab = pairs[s]
                    a = base + ab[0]
                    b = base + ab[1]
                    va = vert[a]
                    vb = vert[b]
                    dx = vb.x - va.x
                    dy = vb.y - va.y
                    dz = vb.z - va.z
                    len2 = wp.cw_mul(dx, dx) + wp.cw_mul(dy, dy) + wp.cw_mul(dz, dz)
                    fa = va.free
                    fb = vb.free
                    live = wp.cw_mul(va.alive, vb.alive)
                    # 0.5 when both ends move, 1 when the other end is pinned (as in the fused kernel)
                    share = one - wp.cw_mul(half, wp.cw_mul(fa, fb))
                    scale = vecL()
                    for lane in range(L):
                        length = wp.sqrt(len2[lane])
                        ok = live[lane] != 0.0 and length >= 1.0e-9
                        scale[lane] = wp.where(ok, stiff[lane] * share[lane] * (length - rest) / length, 0.0)
                    sa = wp.cw_mul(scale, fa)
                    sb = wp.cw_mul(scale, fb)
                    vert[a].x = va.x + wp.cw_mul(dx, sa)
                    vert[a].y = va.y + wp.cw_mul(dy, sa)
                    vert[a].z = va.z + wp.cw_mul(dz, sa)
                    vert[b].x = vb.x + wp.cw_mul(va.x - vb.x, sb)
                    vert[b].y = vb.y + wp.cw_mul(va.y - vb.y, sb)
                    vert[b].z = vb.z + wp.cw_mul(va.z - vb.z, sb)

    @wp.func_native(_NATIVE_RELAX.replace("LANES", str(L)))
    def relax_native(
        vert: wp.array(dtype=Vert),
        pairs: wp.array(dtype=wp.vec2i),
        spring_rest: wp.array(dtype=float),
        colour_start: wp.array(dtype=wp.int32),
        iterations: int,
        base: int,
        stiff: vecL,
    ): ...

    def make_update(relax, name):
        @wp.kernel(enable_backward=False, module=module, name=name)
        def update_kernel(
            # Model:
            n: int,
            block_offset: int,
            iterations: int,
            first_order_z: int,
            any_noise: int,
            seed: int,
            first_stream: int,
            num_envs: int,
            cut_radius: float,
            cut_height: float,
            pairs: wp.array(dtype=wp.vec2i),
            spring_rest: wp.array(dtype=float),
            colour_start: wp.array(dtype=wp.int32),
            lane_params: wp.array(dtype=Lanes),
            anchor: wp.array(dtype=Anchor),
            # Data in/out:
            vert: wp.array(dtype=Vert),
            prev: wp.array(dtype=Prev),
        ):
            """One update (integrate, relax, cut) of ``L`` envs per thread, in place."""
            blk = wp.tid() + block_offset
            base = blk * n
            p = lane_params[blk]
            # ---- integrate: the fused kernel's expressions per lane, its branches as selects
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
            relax(vert, pairs, spring_rest, colour_start, iterations, base, p.stiff)
            # ---- cut
            r2 = cut_radius * cut_radius
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

        return update_kernel

    update_warp = make_update(relax_warp, "simd_update_warp")
    update_native = make_update(relax_native, "simd_update_native")

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
        """Per-env parameters into lanes, with the fused kernel's expressions (``g * h * h``)."""
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

    @wp.func
    def lane_vertex(vert: wp.array(dtype=Vert), i: int, lane: int) -> wp.vec4:
        return wp.vec4(vert[i].x[lane], vert[i].y[lane], vert[i].z[lane], vert[i].alive[lane])

    @wp.kernel(enable_backward=False, module=module)
    def map_tip_kernel(
        # Model:
        nx: int,
        ny: int,
        hx: float,
        hy: float,
        window: int,
        reach: int,
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
        """:func:`warpcut.sim.kernels.map_tip_kernel` for the ``L`` envs of a block: the same search and
        arithmetic (:func:`warpcut.sim.kernels.locate_in_cell`), reading the packed state."""
        blk = wp.tid() + block_offset
        n = nx * ny
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
                flat = env * n
                t = tip[env]
                status = PATH_IDLE
                best = wp.vec4(0.0, 0.0, 0.0, 0.0)
                if t[3] > 0.5:
                    status = PATH_DROPPED
                    for attempt in range(2):
                        window_cells = search_window(attempt, path, env, update, t, nx, ny, hx, hy, reach)
                        if window_cells[0] <= window_cells[1]:
                            for r in range(window_cells[0], window_cells[1] + 1):
                                for c in range(window_cells[2], window_cells[3] + 1):
                                    v = r * nx + c
                                    i = base + v
                                    j = flat + v
                                    a = lane_vertex(vert, i, lane)
                                    b = lane_vertex(vert, i + 1, lane)
                                    d = lane_vertex(vert, i + nx, lane)
                                    e = lane_vertex(vert, i + nx + 1, lane)
                                    best = locate_in_cell(
                                        wp.vec3(a[0], a[1], a[2]),
                                        wp.vec3(b[0], b[1], b[2]),
                                        wp.vec3(d[0], d[1], d[2]),
                                        wp.vec3(e[0], e[1], e[2]),
                                        usable(wp.where(a[3] != 0.0, 1, 0), removed_at[j], update, window),
                                        usable(
                                            wp.where(b[3] != 0.0, 1, 0), removed_at[j + 1], update, window
                                        ),
                                        usable(
                                            wp.where(d[3] != 0.0, 1, 0), removed_at[j + nx], update, window
                                        ),
                                        usable(
                                            wp.where(e[3] != 0.0, 1, 0),
                                            removed_at[j + nx + 1],
                                            update,
                                            window,
                                        ),
                                        float(c) * hx,
                                        float(r) * hy,
                                        hx,
                                        hy,
                                        t,
                                        best,
                                    )
                            if best[3] != 0.0:
                                status = PATH_MAPPED
                                break
                path[env, update] = wp.vec3(best[1], best[2], status)

    return SimpleNamespace(
        lanes=L,
        vec=vecL,
        Vert=Vert,
        Prev=Prev,
        Anchor=Anchor,
        Lanes=Lanes,
        update={"warp": update_warp, "native": update_native},
        pack=pack_kernel,
        unpack=unpack_kernel,
        pack_params=pack_params_kernel,
        pack_controls=pack_controls_kernel,
        map_tip=map_tip_kernel,
    )


@dataclass
class SimdModel:
    """What every env shares: the spring lists (as given to the fused kernel) and the constants."""

    n: int
    iterations: int
    pairs: wp.array  # (num_springs,) vec2i: (spring_a, spring_b), in sweep order
    spring_rest: wp.array
    colour_start: wp.array
    first_order_z: int
    cut_radius: float
    cut_height: float

    @classmethod
    def from_arrays(
        cls,
        n: int,
        iterations: int,
        spring_a: wp.array,
        spring_b: wp.array,
        spring_rest: wp.array,
        colour_start: wp.array,
        first_order_z: int,
        cut_radius: float,
        cut_height: float,
    ) -> "SimdModel":
        """From ``fused_update_kernel``'s arguments. The kernels read one rest length per colour (every
        spring of a colour has the same length, as :func:`warpcut.sim.simulator.colour_springs` builds them)."""
        rest = spring_rest.numpy()
        starts = colour_start.numpy()
        for c in range(len(starts) - 1):
            part = rest[starts[c] : starts[c + 1]]
            if part.size and np.any(part != part[0]):
                raise ValueError(
                    f"spring_rest: colour {c} mixes rest lengths; the SIMD kernels need one per colour"
                )
        if not (spring_rest.is_contiguous and colour_start.is_contiguous):
            raise ValueError("spring_rest, colour_start: the native relaxation needs contiguous arrays")
        pairs = np.stack([spring_a.numpy(), spring_b.numpy()], axis=1).astype(np.int32)
        return cls(
            n=int(n),
            iterations=int(iterations),
            pairs=wp.array(pairs, dtype=wp.vec2i, device=spring_a.device),
            spring_rest=spring_rest,
            colour_start=colour_start,
            first_order_z=int(first_order_z),
            cut_radius=float(cut_radius),
            cut_height=float(cut_height),
        )


class SimdState:
    """The packed state of ``num_envs`` envs of ``n`` vertices, in blocks of ``lanes`` envs.

    Pack once per reset (:meth:`load`, :meth:`load_params`), per update :meth:`load_controls` (grasp
    displacement, tip: B x 7 floats) and :meth:`step`; unpack on read-back (:meth:`store`). Each pack or
    unpack is one pass over the batch's state (pack ~6 ms, unpack ~4 ms at B = 1024, 25 x 25).
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
        self.any_noise = 0
        self._lanes_view: np.ndarray | None = None

    def load(self, x: wp.array, x_prev: wp.array, alive: wp.array, pin: wp.array, anchor: wp.array) -> None:
        """Env-major state (``B * n`` entries each, as the fused kernel takes it) into blocks."""
        wp.launch(
            self.kernels.pack,
            dim=(self.blocks, self.n),
            inputs=[self.n, self.num_envs, x, x_prev, alive, pin, anchor, self.vert, self.prev, self.anchor],
            device=self.device,
        )

    def load_params(self, damping, dt, gravity, noise_std, elasticity) -> None:
        """Per-env parameter arrays of length 1 or B (read as ``p[env % len]``)."""
        self.any_noise = int(np.any(noise_std.numpy() > 0.0))
        wp.launch(
            self.kernels.pack_params,
            dim=self.blocks,
            inputs=[self.num_envs, damping, dt, gravity, noise_std, elasticity, self.lane_params],
            device=self.device,
        )

    def load_controls(self, displacement: wp.array, tip: wp.array) -> None:
        """(B,) ``vec3`` grasp displacements and (B,) ``vec4`` tips; call after every change."""
        wp.launch(
            self.kernels.pack_controls,
            dim=self.blocks,
            inputs=[self.num_envs, displacement, tip, self.lane_params],
            device=self.device,
        )

    def lane_views(self, envs: list[int]) -> list[np.ndarray]:
        """Per env of ``envs`` (valid indices), a zero-copy (n, 4) float32 view of its x, y, z and alive
        (1.0 or 0.0) lanes in the packed blocks (CPU memory; valid as long as this state): copying one out
        reads that env and nothing else of the batch, one strided copy (~10 µs for a 25 x 25 sheet)."""
        if self._lanes_view is None:
            # (blocks, n, fields, lanes) over ``struct V`` (x, y, z, alive, free); numpy() costs ~70 us.
            packed = self.vert.numpy()
            if packed.dtype.names[:4] != ("x", "y", "z", "alive") or packed.dtype.itemsize != 20 * self.lanes:
                raise RuntimeError(f"lane_views: unexpected vertex layout {packed.dtype}")
            self._lanes_view = packed.view(np.float32).reshape(self.blocks, self.n, 5, self.lanes)
        return [self._lanes_view[env // self.lanes, :, :4, env % self.lanes] for env in envs]

    def store(self, x: wp.array, x_prev: wp.array, alive: wp.array) -> None:
        """Blocks back into env-major arrays (padding lanes dropped)."""
        wp.launch(
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
        relax: str = "native",
        first_stream: int = 0,
    ) -> None:
        """One update of blocks ``[block_offset, block_offset + block_count)`` (default: to the end); env
        ``e`` draws noise stream ``first_stream + e``.

        Disjoint block ranges may be stepped from different Python threads at once (``wp.launch``
        releases the GIL), as ``Simulator`` does with env slices.
        """
        if relax not in RELAX_MODES:
            raise ValueError(f"relax: choose one of {RELAX_MODES} (got {relax!r})")
        count = self.blocks - block_offset if block_count is None else block_count
        wp.launch(
            self.kernels.update[relax],
            dim=count,
            inputs=[
                model.n,
                block_offset,
                model.iterations,
                model.first_order_z,
                self.any_noise,
                int(seed),
                int(first_stream),
                self.num_envs,
                model.cut_radius,
                model.cut_height,
                model.pairs,
                model.spring_rest,
                model.colour_start,
                self.lane_params,
                self.anchor,
            ],
            outputs=[self.vert, self.prev],
            device=self.device,
        )


def simd_update(
    n: int,
    iterations: int,
    spring_a: wp.array,
    spring_b: wp.array,
    spring_rest: wp.array,
    colour_start: wp.array,
    damping: wp.array,
    dt: wp.array,
    gravity: wp.array,
    noise_std: wp.array,
    elasticity: wp.array,
    first_order_z: int,
    seed: int,
    first_stream: int,
    cut_radius: float,
    cut_height: float,
    pin: wp.array,
    anchor: wp.array,
    displacement: wp.array,
    tip: wp.array,
    x: wp.array,
    x_prev: wp.array,
    alive: wp.array,
    lanes: int = DEFAULT_LANES,
    relax: str = "native",
) -> None:
    """One update of the whole batch, in place, from the arguments of ``fused_update_kernel`` (without
    ``env_offset``: the whole batch). Packs, steps and unpacks on every call: ~10 ms at B = 1024, 25 x 25,
    i.e. ~15-20% on top of a default-physics update (~4x the update with the paper sweeps); keep a
    :class:`SimdState` instead when stepping repeatedly."""
    num_envs = x.shape[0] // n
    state = SimdState(num_envs, n, lanes, str(x.device))
    state.load(x, x_prev, alive, pin, anchor)
    state.load_params(damping, dt, gravity, noise_std, elasticity)
    state.load_controls(displacement, tip)
    model = SimdModel.from_arrays(
        n, iterations, spring_a, spring_b, spring_rest, colour_start, first_order_z, cut_radius, cut_height
    )
    state.step(model, seed, relax=relax, first_stream=first_stream)
    state.store(x, x_prev, alive)
