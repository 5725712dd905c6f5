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

Use: keep a :class:`warpcut.sim.simd.SimdState` for the batch (:mod:`warpcut.sim.simd`: the packed batch
that these kernels step).
"""

import functools
from types import SimpleNamespace

import numpy as np

from warpcut.sim._warp import wp
from warpcut.sim.kernels import NOISE_SCALE_VALUE, PIN_FREE, PIN_GRASP
from warpcut.sim.kernels_simd_reads import interpolate_cells_kernel, map_tip_kernel

DEFAULT_LANES = 8

_RELAX_SOURCE = """
    typedef float vf __attribute__((ext_vector_type(LANES), aligned(4)));
    typedef int vi __attribute__((ext_vector_type(LANES), aligned(4)));
    struct V { vf x, y, z, alive, free; };
    struct P { vf x, y, z; };
    static_assert(sizeof(V) == 5 * LANES * sizeof(float), "Vert layout");
    static_assert(sizeof(P) == 3 * LANES * sizeof(float), "Prev layout");
    V* block = (V*)vert.data + base;
    // Chebyshev: the positions two sweeps back, by sweep parity (two records per vertex of the block)
    P* older[2] = {nullptr, nullptr};
    const float* weight = (const float*)weights.data;
    if (chebyshev) {  // the first record holds the integrated positions (the integration wrote them)
        older[0] = (P*)older_data.data + 2 * base;
        older[1] = older[0] + n;
    }
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
        if (chebyshev) {
            // chebyshev_kernel's expression: older + (x - older) * w, kept for two sweeps on
            const int done = sweep + 1;
            const bool save = done < sweeps - 1;
            P* o = older[done % 2];
            if (done > 1) {
                const vf w = weight[sweep];
                for (int v = 0; v < n; ++v) {
                    V* p = block + v;
                    P* q = o + v;
                    const vf x = q->x + (p->x - q->x) * w;
                    const vf y = q->y + (p->y - q->y) * w;
                    const vf z = q->z + (p->z - q->z) * w;
                    p->x = x;
                    p->y = y;
                    p->z = z;
                    if (save) {
                        q->x = x;
                        q->y = y;
                        q->z = z;
                    }
                }
            } else if (save) {
                for (int v = 0; v < n; ++v) {
                    o[v].x = block[v].x;
                    o[v].y = block[v].y;
                    o[v].z = block[v].z;
                }
            }
        }
    }
"""


_INTEGRATE_SOURCE = """
    typedef float vf __attribute__((ext_vector_type(LANES), aligned(4)));
    typedef int vi __attribute__((ext_vector_type(LANES), aligned(4)));
    typedef unsigned int vu __attribute__((ext_vector_type(LANES), aligned(4)));
    NOISE_HELPERS
    struct V { vf x, y, z, alive, free; };
    struct P { vf x, y, z; };
    struct A { vf x, y, z, grasp; };
    V* block = (V*)vert.data + base;
    P* before = (P*)prev.data + base;
    const A* held = (const A*)anchor.data + base;
    P* older0 = chebyshev ? (P*)older.data + 2 * base : nullptr;
    vf keep, fall, sigma, ux, uy, uz;
    vi env;
    for (int lane = 0; lane < LANES; ++lane) {
        keep[lane] = keep_in.c[lane];
        fall[lane] = fall_in.c[lane];
        sigma[lane] = sigma_in.c[lane];
        ux[lane] = ux_in.c[lane];
        uy[lane] = uy_in.c[lane];
        uz[lane] = uz_in.c[lane];
        env[lane] = blk * LANES + lane;
    }
    const vf zero = 0.0f;
    const vi noisy = (sigma > zero) & (env < num_envs);
    // process_noise(seed, env * n + v + first_stream * n) of every lane, in 32-bit unsigned arithmetic
    const unsigned seed_hash = HASH((unsigned)seed);
    const vu first = (vu)env * (unsigned)n + (unsigned)first_stream * (unsigned)n;
    #define SELECT(m, a, b) ((vf)(((vi)(a) & (m)) | ((vi)(b) & ~(m))))
    for (int v = 0; v < n; ++v) {
        V* vt = block + v;
        P* q = before + v;
        const A* a = held + v;
        const vf x = vt->x, y = vt->y, z = vt->z;
        const vf vx = (x - q->x) * keep;
        const vf vy = (y - q->y) * keep;
        const vf vz = first_order_z ? zero : (z - q->z) * keep;
        const vf qx = x + vx, qy = y + vy, qz = (z + vz) - fall;
        const vi free = vt->free != zero;
        const vi moving = free & (vt->alive != zero);
        const vi grasped = a->grasp != zero;
        const vf px = SELECT(grasped, a->x + ux, a->x);
        const vf py = SELECT(grasped, a->y + uy, a->y);
        const vf pz = SELECT(grasped, a->z + uz, a->z);
        vf nx = SELECT(moving, qx, SELECT(free, x, px));
        vf ny = SELECT(moving, qy, SELECT(free, y, py));
        vf nz = SELECT(moving, qz, SELECT(free, z, pz));
        if (any_noise) {
            const vi m = noisy & moving;
            const vu key = seed_hash + (first + (unsigned)v) * 3u;
            nx = SELECT(m, nx + sigma * NORMAL(HASH(key)), nx);
            ny = SELECT(m, ny + sigma * NORMAL(HASH(key + 1u)), ny);
            nz = SELECT(m, nz + sigma * NORMAL(HASH(key + 2u)), nz);
        }
        q->x = x;
        q->y = y;
        q->z = z;
        vt->x = nx;
        vt->y = ny;
        vt->z = nz;
        if (chebyshev) {
            older0[v].x = nx;
            older0[v].y = ny;
            older0[v].z = nz;
        }
    }
    #undef SELECT
"""
"""The integration of one block (``integrate_kernel``'s expressions, its branches as lane masks), with the
process noise drawn for all lanes at once: ``HASH`` and ``NORMAL`` are ``kernels.hash32`` and
``kernels.byte_sum_normal`` written for vectors of unsigned ints (:func:`_native_source`)."""


def _native_source(source: str, lanes: int) -> str:
    """A native snippet for ``lanes`` envs per block, with the lane-wise noise helpers in place of
    ``NOISE_HELPERS`` (a lambda
    per helper, generic over scalar and vector unsigned ints; :data:`kernels.NOISE_SCALE` as an exact
    float32 hex literal, so both backends scale by the same float)."""
    scale = float(np.float32(NOISE_SCALE_VALUE)).hex()
    helpers = f"""
    auto hash32_lanes = [](auto x) {{
        x = x ^ (x >> 16u);
        x = x * 0x7FEB352Du;
        x = x ^ (x >> 15u);
        x = x * 0x846CA68Bu;
        x = x ^ (x >> 16u);
        return x;
    }};
    auto byte_sum_normal_lanes = [](auto h) {{
        auto total = (h & 255u) + ((h >> 8u) & 255u);
        total = total + ((h >> 16u) & 255u) + (h >> 24u);
        return (__builtin_convertvector(total, vf) - 510.0f) * {scale}f;
    }};
    #define HASH(h) hash32_lanes(h)
    #define NORMAL(h) byte_sum_normal_lanes(h)
"""
    source = source.replace("NOISE_HELPERS", helpers) + "\n    #undef HASH\n    #undef NORMAL\n"
    return source.replace("LANES", str(lanes))


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
        map_tip=map_tip_kernel(types, module),
        interpolate_cells=interpolate_cells_kernel(types, module),
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
    vecL, Vert, Prev = types.vec, types.Vert, types.Prev  # noqa: N806 (types)

    @wp.func_native(_RELAX_SOURCE.replace("LANES", str(types.lanes)))
    def relax(
        vert: wp.array(dtype=Vert),
        pairs: wp.array(dtype=wp.vec2i),
        colour_rest: wp.array(dtype=float),
        colour_start: wp.array(dtype=wp.int32),
        sweeps: int,
        n: int,
        base: int,
        stiff: vecL,
        chebyshev: int,
        weights: wp.array(dtype=float),
        older_data: wp.array(dtype=Prev),
    ):
        """``sweeps`` Gauss-Seidel sweeps of one block, colour by colour, ``L`` envs per spring, each
        followed by a Chebyshev extrapolation if ``chebyshev`` (``older_data``: two ``Prev`` records per
        vertex of each block, scratch)."""

    return relax


def _integrate_func(types: SimpleNamespace) -> wp.Function:
    """The native function that integrates one block of ``L`` envs (:data:`_INTEGRATE_SOURCE`)."""
    vecL, Vert, Prev, Anchor = types.vec, types.Vert, types.Prev, types.Anchor  # noqa: N806 (types)

    @wp.func_native(_native_source(_INTEGRATE_SOURCE, types.lanes))
    def integrate(
        vert: wp.array(dtype=Vert),
        prev: wp.array(dtype=Prev),
        anchor: wp.array(dtype=Anchor),
        n: int,
        base: int,
        blk: int,
        num_envs: int,
        first_order_z: int,
        any_noise: int,
        seed: int,
        first_stream: int,
        keep_in: vecL,
        fall_in: vecL,
        sigma_in: vecL,
        ux_in: vecL,
        uy_in: vecL,
        uz_in: vecL,
        chebyshev: int,
        older: wp.array(dtype=Prev),
    ):
        """Damped Verlet of one block's free vertices, fixture and grasp pins, process noise; the new
        positions also go to the Chebyshev scratch's first record if ``chebyshev``."""

    return integrate


def _update_kernel(types: SimpleNamespace, module: str) -> wp.Kernel:
    """The kernel of one update (integrate, relax, cut) of ``L`` envs per thread, in place."""
    L, vecL = types.lanes, types.vec  # noqa: N806 (a constant and a type, as the kernel reads them)
    Vert, Prev, Anchor, Lanes = types.Vert, types.Prev, types.Anchor, types.Lanes  # noqa: N806
    relax = _relax_func(types)
    integrate = _integrate_func(types)

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
        chebyshev: int,
        weights: wp.array(dtype=float),
        lane_params: wp.array(dtype=Lanes),
        anchor: wp.array(dtype=Anchor),
        # Data in/out:
        vert: wp.array(dtype=Vert),
        prev: wp.array(dtype=Prev),
        status: wp.array2d(dtype=wp.int32),
        older: wp.array(dtype=Prev),
    ):
        blk = wp.tid() + block_offset
        base = blk * n
        p = lane_params[blk]
        # ---- integrate: integrate_kernel's expressions per lane, its branches as lane masks
        integrate(
            vert,
            prev,
            anchor,
            n,
            base,
            blk,
            num_envs,
            first_order_z,
            any_noise,
            seed,
            first_stream,
            p.keep,
            p.fall,
            p.sigma,
            p.ux,
            p.uy,
            p.uz,
            chebyshev,
            older,
        )
        # ---- relax
        relax(vert, pairs, colour_rest, colour_start, sweeps, n, base, p.stiff, chebyshev, weights, older)
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
