"""The ``simd`` backend's kernels that read its packed blocks without stepping them: the scissor tip's tracing
through the cut sheet and the interpolation of material points (the envs' fiducials) over their cells.
:func:`warpcut.sim.kernels_simd.simd_kernels` builds them, for each number of lanes, into the same Warp
module as the update (one module per lane count: one compilation)."""

from types import SimpleNamespace

from warpcut.sim._warp import wp
from warpcut.sim.kernels import TipSearch, tip_locator


def map_tip_kernel(types: SimpleNamespace, module: str) -> wp.Kernel:
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


def interpolate_cells_kernel(types: SimpleNamespace, module: str) -> wp.Kernel:
    """Material points' world positions from the packed state: the corners of each point's cell, bilinearly
    weighted (:func:`warpcut.sim.material.interpolate_corners`, the same products and sums in the same order,
    in float64, so the same bits), and whether the cell is whole (all four corners uncut). ``packed`` is the
    blocks as flat floats (:meth:`SimdState.packed_view`: block, vertex, field x, y, z, alive, free, lane)."""
    L = types.lanes  # noqa: N806 (a constant, as the kernel reads it)

    @wp.func
    def corner(packed: wp.array(dtype=float), i: int) -> wp.vec3d:
        return wp.vec3d(wp.float64(packed[i]), wp.float64(packed[i + L]), wp.float64(packed[i + 2 * L]))

    @wp.kernel(enable_backward=False, module=module)
    def interpolate_cells_kernel(
        # Model:
        n: int,
        vertices: wp.array3d(dtype=wp.int32),
        weights: wp.array3d(dtype=wp.float64),
        # Data in:
        packed: wp.array(dtype=float),
        # Data out:
        world: wp.array3d(dtype=wp.float64),
        whole: wp.array2d(dtype=wp.int32),
    ):
        env, k = wp.tid()
        base = (env // L) * n
        lane = env % L
        i0 = (base + vertices[env, k, 0]) * 5 * L + lane  # field x of the corner's vertex, in its lane
        i1 = (base + vertices[env, k, 1]) * 5 * L + lane
        i2 = (base + vertices[env, k, 2]) * 5 * L + lane
        i3 = (base + vertices[env, k, 3]) * 5 * L + lane
        p0 = weights[env, k, 0] * corner(packed, i0)
        p1 = weights[env, k, 1] * corner(packed, i1)
        p2 = weights[env, k, 2] * corner(packed, i2)
        p3 = weights[env, k, 3] * corner(packed, i3)
        point = (p0 + p1) + (p2 + p3)
        world[env, k, 0] = point[0]
        world[env, k, 1] = point[1]
        world[env, k, 2] = point[2]
        a = 3 * L  # field alive
        cut = packed[i0 + a] == 0.0 or packed[i1 + a] == 0.0 or packed[i2 + a] == 0.0 or packed[i3 + a] == 0.0
        whole[env, k] = wp.where(cut, 0, 1)

    return interpolate_cells_kernel
