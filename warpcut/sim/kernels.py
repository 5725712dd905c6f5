"""Warp kernels of the ``colours`` backend (integrate, relax one spring colour, cut, move the grasps),
and the functions every backend shares: the process noise and the mapping of the scissor tip into
material coordinates (the cut path).

All of these live in this one module so they compile once (a cold compile costs seconds per module).
Each per-vertex kernel is launched over ``(num_envs, num_vertices)`` and starts with ``env, v = wp.tid()``;
state is flattened env-major (``i = env * n + v``). Kernels are out-of-place (state in -> state out): the
fast path ping-pongs buffers, a differentiable rollout allocates fresh outputs under ``wp.Tape``.
A physical parameter array has length 1 (shared) or num_envs and is read as ``p[env % p.shape[0]]``.
"""

from warpcut.sim._warp import wp

PIN_FREE = wp.constant(0)
PIN_FIXTURE = wp.constant(1)
PIN_GRASP = wp.constant(2)


# ---------------------------------------------------------------------------------------------- noise
# Process noise is drawn from a counter-based integer hash, the same in every backend (bit for bit), and
# cheaper than Warp's rand_init + randn (Box-Muller: logs and cosines per draw; docs/performance.md).

NOISE_SCALE_VALUE = 0.0067658750867932
"""1 / std of the sum of four uniform bytes: sqrt(4 * (256^2 - 1) / 12) = 147.8006."""
NOISE_SCALE = wp.constant(NOISE_SCALE_VALUE)


@wp.func
def hash32(x: wp.uint32) -> wp.uint32:
    """A full-avalanche 32-bit integer hash (lowbias32, C. Wellons)."""
    x = x ^ (x >> wp.uint32(16))
    x = x * wp.uint32(0x7FEB352D)
    x = x ^ (x >> wp.uint32(15))
    x = x * wp.uint32(-2073254261)  # 0x846CA68B: Warp writes integer literals as int32 first
    x = x ^ (x >> wp.uint32(16))
    return x


@wp.func
def byte_sum_normal(h: wp.uint32) -> float:
    """An approximately standard normal draw from 32 random bits: the sum of their four bytes (Irwin-Hall
    with n = 4: mean 0, variance 1 exactly, bounded at +-3.45, excess kurtosis -0.3), centred and scaled."""
    total = (h & wp.uint32(255)) + ((h >> wp.uint32(8)) & wp.uint32(255))
    total = total + ((h >> wp.uint32(16)) & wp.uint32(255)) + (h >> wp.uint32(24))
    return (float(total) - 510.0) * NOISE_SCALE


@wp.func
def process_noise(seed: int, index: int) -> wp.vec3:
    """Three independent, approximately standard normal draws for vertex stream ``index`` (``env * n +
    v``) of the update whose noise seed is ``seed``."""
    # Within an update every (stream, axis) hashes its own counter; another seed shifts all counters by a
    # hashed offset.
    key = hash32(wp.uint32(seed)) + wp.uint32(index) * wp.uint32(3)
    return wp.vec3(
        byte_sum_normal(hash32(key)),
        byte_sum_normal(hash32(key + wp.uint32(1))),
        byte_sum_normal(hash32(key + wp.uint32(2))),
    )


@wp.kernel
def integrate_kernel(
    # Model:
    n: int,
    damping: wp.array(dtype=float),
    dt: wp.array(dtype=float),
    gravity: wp.array(dtype=float),
    noise_std: wp.array(dtype=float),
    first_order_z: int,
    seed_base: wp.array(dtype=wp.int32),
    update_counter: wp.array(dtype=wp.int32),
    first_stream: int,
    # Data in:
    x: wp.array(dtype=wp.vec3),
    x_prev: wp.array(dtype=wp.vec3),
    alive: wp.array(dtype=wp.int32),
    pin: wp.array(dtype=wp.int32),
    anchor: wp.array(dtype=wp.vec3),
    displacement: wp.array(dtype=wp.vec3),
    # Data out:
    x_out: wp.array(dtype=wp.vec3),
):
    """Damped Verlet: ``x + damping * (x - x_prev) + g dt^2 (+ noise)``; pinned vertices go to target.

    The noise seed of this update is ``(seed_base[0] + update_counter[0]) mod (2^31 - 1)``, read from
    device memory so that a captured graph draws a fresh stream at every replay and follows a new seed
    (see ``count_update_kernel``). Env ``e`` draws noise stream ``first_stream + e``.
    """
    env, v = wp.tid()
    i = env * n + v
    p = x[i]
    kind = pin[i]
    if kind == PIN_FIXTURE:
        x_out[i] = anchor[i]
        return
    if kind == PIN_GRASP:
        x_out[i] = anchor[i] + displacement[env]
        return
    if alive[i] == 0:
        # Removed material no longer takes part; freeze it.
        x_out[i] = p
        return
    velocity = (p - x_prev[i]) * damping[env % damping.shape[0]]
    if first_order_z != 0:
        velocity = wp.vec3(velocity[0], velocity[1], 0.0)
    h = dt[env % dt.shape[0]]
    q = p + velocity - wp.vec3(0.0, 0.0, gravity[env % gravity.shape[0]] * h * h)
    sigma = noise_std[env % noise_std.shape[0]]
    if sigma > 0.0:
        seed = wp.int32((wp.int64(seed_base[0]) + wp.int64(update_counter[0])) % wp.int64(2147483647))
        q = q + sigma * process_noise(seed, i + first_stream * n)
    x_out[i] = q


@wp.kernel
def count_update_kernel(update_counter: wp.array(dtype=wp.int32)):
    """Advance the device-side update counter (the last launch of an update; part of a captured graph)."""
    update_counter[0] = update_counter[0] + 1


@wp.kernel
def relax_colour_kernel(
    # Model:
    nx: int,
    ny: int,
    elasticity: wp.array(dtype=float),
    di: int,
    dj: int,
    rest_length: float,
    on_rows: int,
    divisor: int,
    parity: int,
    # Data in:
    x: wp.array(dtype=wp.vec3),
    alive: wp.array(dtype=wp.int32),
    pin: wp.array(dtype=wp.int32),
    # Data out:
    x_out: wp.array(dtype=wp.vec3),
):
    """Relax every spring of one colour; a colour's springs share no vertex, so each vertex has at most
    one spring to gather from and the sweep is deterministic without atomics.

    A colour holds the springs ``(row, col) -> (row + dj, col + di)`` whose start satisfies
    ``(key // divisor) % 2 == parity`` with ``key = row if on_rows else col``.
    """
    env, v = wp.tid()
    n = nx * ny
    i = env * n + v
    p = x[i]
    x_out[i] = p
    if alive[i] == 0 or pin[i] != PIN_FREE:
        return
    row = v // nx
    col = v - row * nx
    partner = -1
    # As the start of a spring of this colour.
    key = col
    if on_rows != 0:
        key = row
    r2 = row + dj
    c2 = col + di
    if (key // divisor) % 2 == parity and r2 >= 0 and r2 < ny and c2 >= 0 and c2 < nx:
        partner = r2 * nx + c2
    # As the end of one.
    r0 = row - dj
    c0 = col - di
    key0 = c0
    if on_rows != 0:
        key0 = r0
    if r0 >= 0 and r0 < ny and c0 >= 0 and c0 < nx and key0 >= 0 and (key0 // divisor) % 2 == parity:
        partner = r0 * nx + c0
    if partner < 0:
        return
    j = env * n + partner
    if alive[j] == 0:
        return
    d = x[j] - p
    length = wp.length(d)
    if length < 1.0e-9:
        return
    # Split the correction by inverse mass: a pinned partner does not move, so this vertex takes it all.
    share = 0.5
    if pin[j] != PIN_FREE:
        share = 1.0
    k = elasticity[env % elasticity.shape[0]]
    x_out[i] = p + d * (k * share * (length - rest_length) / length)


@wp.kernel
def chebyshev_kernel(
    weight: float,
    first: int,
    save: int,
    # Data in:
    x: wp.array(dtype=wp.vec3),
    older: wp.array(dtype=wp.vec3),
    # Data out:
    x_out: wp.array(dtype=wp.vec3),
    saved_out: wp.array(dtype=wp.vec3),
):
    """Chebyshev extrapolation after a sweep (``SimConfig.chebyshev_rho``), launched over all ``B * n``
    vertices: ``older + (x - older) * weight``, ``older`` being the positions two sweeps back (``x`` as it
    is when ``first``); a copy goes to ``saved_out`` when ``save``. Element-wise, so it may run in place.
    Pinned and cut vertices do not move within an update (``x == older``), so they stay exactly put."""
    i = wp.tid()
    y = x[i]
    if first == 0:
        o = older[i]
        y = o + (y - o) * weight
    x_out[i] = y
    if save != 0:
        saved_out[i] = y


@wp.kernel
def cut_kernel(
    # Model:
    n: int,
    cut_radius: float,
    cut_height: float,
    lower: wp.vec3,
    upper: wp.vec3,
    # Data in:
    x: wp.array(dtype=wp.vec3),
    alive: wp.array(dtype=wp.int32),
    tip: wp.array(dtype=wp.vec4),
    # Data out:
    alive_out: wp.array(dtype=wp.int32),
    # Data in/out:
    status: wp.array2d(dtype=wp.int32),
):
    """Remove vertices within ``cut_radius`` (in x-y) and ``cut_height`` (in z) of an active scissor tip;
    watch for divergence.

    ``tip[env] = (x, y, z, cutting)``; ``cutting`` is 0 while the scissors travel between segments.
    ``status[0, env]`` is set to 1 once a vertex of the env is not finite, ``status[1, env]`` once one lies
    outside the box ``lower .. upper`` (:attr:`SimConfig.runaway_bounds`); both stay set until a reset.
    Every writer writes the same 1, so the unsynchronised stores are deterministic.
    """
    env, v = wp.tid()
    i = env * n + v
    a = alive[i]
    t = tip[env]
    p = x[i]
    if not wp.isfinite(p):
        status[0, env] = 1
    elif p[0] < lower[0] or p[0] > upper[0] or p[1] < lower[1] or p[1] > upper[1] or p[2] > upper[2]:
        status[1, env] = 1
    if a != 0 and t[3] > 0.5:
        dx = p[0] - t[0]
        dy = p[1] - t[1]
        if dx * dx + dy * dy <= cut_radius * cut_radius and wp.abs(p[2] - t[2]) <= cut_height:
            a = 0
    alive_out[i] = a


@wp.kernel
def move_grasp_kernel(
    # Model:
    max_step: float,
    max_displacement: float,
    # Data in:
    displacement: wp.array(dtype=wp.vec3),
    action: wp.array(dtype=wp.vec3),
    # Data out:
    displacement_out: wp.array(dtype=wp.vec3),
):
    """Move each grasp by its action (:func:`grasp_move`)."""
    env = wp.tid()
    displacement_out[env] = grasp_move(displacement[env], action[env], max_step, max_displacement)


@wp.func
def grasp_move(displacement: wp.vec3, action: wp.vec3, max_step: float, max_displacement: float) -> wp.vec3:
    """The grasp's displacement after ``action``: clipped to ``max_step`` per axis, the total to
    ``max_displacement`` in norm (differentiable where neither clip binds)."""
    step = wp.vec3(
        wp.clamp(action[0], -max_step, max_step),
        wp.clamp(action[1], -max_step, max_step),
        wp.clamp(action[2], -max_step, max_step),
    )
    u = displacement + step
    norm = wp.length(u)
    if norm > max_displacement:
        u = u * (max_displacement / norm)
    return u


# ---------------------------------------------------------------------------------------------- path
# Where the scissors went through the material: after every cutting update, the tip is located in the
# deformed mesh (two triangles per grid cell) and mapped back to rest (material) coordinates. The search,
# :func:`tip_locator`, is written once; the flat kernel below and the SIMD-layout kernel in ``kernels_simd``
# instantiate it with their own way of fetching a vertex, so both backends map bit-identically.

PATH_MAPPED = wp.constant(1.0)
PATH_DROPPED = wp.constant(0.0)
PATH_IDLE = wp.constant(-1.0)


@wp.struct
class TipSearch:
    """What the search for the tip knows of the sheet (:meth:`Simulator.trace_path`)."""

    nx: int
    """Vertices per row."""
    ny: int
    """Vertices per column."""
    hx: float
    """Rest spacing along x (mm)."""
    hy: float
    """Rest spacing along y (mm)."""
    window: int
    """Updates for which a cut vertex still carries the tip (:attr:`Simulator.path_window`)."""
    reach: int
    """Cells around the tip searched when the previous point does not lead to it (:attr:`path_reach`)."""


@wp.func
def triangle_weights(a: wp.vec4, b: wp.vec4, c: wp.vec4, tx: float, ty: float) -> wp.vec3:
    """Barycentric weights of ``(tx, ty)`` in triangle ``abc`` projected on x-y; a negative first weight
    when the point lies outside it or the triangle is degenerate."""
    e1x = b[0] - a[0]
    e1y = b[1] - a[1]
    e2x = c[0] - a[0]
    e2y = c[1] - a[1]
    det = e1x * e2y - e2x * e1y
    if wp.abs(det) < 1.0e-9:
        return wp.vec3(-1.0, 0.0, 0.0)
    px = tx - a[0]
    py = ty - a[1]
    wb = (px * e2y - e2x * py) / det
    wc = (e1x * py - px * e1y) / det
    wa = 1.0 - wb - wc
    tol = -1.0e-5
    if wa < tol or wb < tol or wc < tol:
        return wp.vec3(-1.0, 0.0, 0.0)
    return wp.vec3(wa, wb, wc)


@wp.func
def usable(corner: wp.vec4, removed_at: int, update: int, window: int) -> int:
    """Whether a vertex ``(x, y, z, alive)`` may carry the tip: alive, or cut within the last ``window``
    updates (the tip always sits on freshly cut material; older cuts are holes)."""
    if corner[3] != 0.0 or update - removed_at <= window:
        return 1
    return 0


@wp.func
def locate_in_cell(
    p00: wp.vec4,
    p10: wp.vec4,
    p01: wp.vec4,
    p11: wp.vec4,
    ok00: int,
    ok10: int,
    ok01: int,
    ok11: int,
    mx0: float,
    my0: float,
    hx: float,
    hy: float,
    tip: wp.vec4,
    best: wp.vec4,
) -> wp.vec4:
    """Test the cell's triangles ``(00, 10, 11)`` and ``(00, 11, 01)`` for the tip; keep the hit nearest
    the tip in height. ``best = (|dz|, mx, my, found)``: ``mx, my`` the tip's material position (the
    cell's rest square starts at ``(mx0, my0)``); only usable triangles (``ok`` at every corner) count."""
    out = best
    if ok00 != 0 and ok10 != 0 and ok11 != 0:
        w = triangle_weights(p00, p10, p11, tip[0], tip[1])
        if w[0] >= -1.0e-5:
            dz = wp.abs(w[0] * p00[2] + w[1] * p10[2] + w[2] * p11[2] - tip[2])
            if out[3] == 0.0 or dz < out[0]:
                out = wp.vec4(dz, mx0 + (w[1] + w[2]) * hx, my0 + w[2] * hy, 1.0)
    if ok00 != 0 and ok11 != 0 and ok01 != 0:
        w = triangle_weights(p00, p11, p01, tip[0], tip[1])
        if w[0] >= -1.0e-5:
            dz = wp.abs(w[0] * p00[2] + w[1] * p11[2] + w[2] * p01[2] - tip[2])
            if out[3] == 0.0 or dz < out[0]:
                out = wp.vec4(dz, mx0 + w[1] * hx, my0 + (w[1] + w[2]) * hy, 1.0)
    return out


@wp.func
def search_window(
    attempt: int, path: wp.array2d(dtype=wp.vec3), env: int, update: int, tip: wp.vec4, search: TipSearch
) -> wp.vec4i:
    """Cells ``(row_lo, row_hi, col_lo, col_hi)`` searched by attempt 0 (the cells around the previous
    update's material point, if it was mapped) and 1 (``reach`` cells around the tip's x-y taken as a
    material point); an empty range skips the attempt."""
    nx = search.nx
    ny = search.ny
    cx = tip[0]
    cy = tip[1]
    r = search.reach
    if attempt == 0:
        if update == 0:
            return wp.vec4i(1, 0, 1, 0)
        previous = path[env, update - 1]
        if previous[2] != PATH_MAPPED:
            return wp.vec4i(1, 0, 1, 0)
        cx = previous[0]
        cy = previous[1]
        r = 1
    c0 = wp.clamp(int(cx / search.hx), 0, nx - 2)
    r0 = wp.clamp(int(cy / search.hy), 0, ny - 2)
    return wp.vec4i(wp.max(r0 - r, 0), wp.min(r0 + r, ny - 2), wp.max(c0 - r, 0), wp.min(c0 + r, nx - 2))


def tip_locator(Sheet, Part, corner, name: str, module: str | None = None):  # noqa: N803 (Warp types)
    """A ``wp.func`` ``locate_tip(sheet, part, base, env, update, tip, removed_at, path, search) -> vec3``:
    where env ``env``'s tip of update ``update`` went through the material, as
    :attr:`path` stores it, ``(mx, my, PATH_MAPPED)``, ``(0, 0, PATH_DROPPED)`` off the sheet or over a
    hole, ``(0, 0, PATH_IDLE)`` while the scissors do not cut. The cells of :func:`search_window` are
    searched in turn until one holds the tip.

    One search for every state layout: ``corner(sheet, part, base + v) -> vec4`` fetches the env's vertex
    ``v`` as ``(x, y, z, alive)`` (alive 1.0 or 0.0); ``Sheet`` and ``Part`` are the Warp types of its
    first two arguments (env-major: the positions and the alive flags; SIMD blocks: the blocks and the
    env's lane). ``removed_at`` is env-major (``env * n + v``). ``module``: the Warp module of the kernel
    that calls it (default: this one; one that is already loaded would be reloaded).
    """

    @wp.func(name=name, module=module)
    def locate_tip(
        sheet: Sheet,
        part: Part,
        base: int,
        env: int,
        update: int,
        tip: wp.vec4,
        removed_at: wp.array(dtype=wp.int32),
        path: wp.array2d(dtype=wp.vec3),
        search: TipSearch,
    ) -> wp.vec3:
        nx = search.nx
        hx = search.hx
        hy = search.hy
        window = search.window
        flat = env * nx * search.ny
        status = PATH_IDLE
        best = wp.vec4(0.0, 0.0, 0.0, 0.0)
        if tip[3] > 0.5:
            status = PATH_DROPPED
            for attempt in range(2):
                cells = search_window(attempt, path, env, update, tip, search)
                if cells[0] <= cells[1]:
                    for r in range(cells[0], cells[1] + 1):
                        for c in range(cells[2], cells[3] + 1):
                            v = r * nx + c
                            p00 = corner(sheet, part, base + v)
                            p10 = corner(sheet, part, base + v + 1)
                            p01 = corner(sheet, part, base + v + nx)
                            p11 = corner(sheet, part, base + v + nx + 1)
                            best = locate_in_cell(
                                p00,
                                p10,
                                p01,
                                p11,
                                usable(p00, removed_at[flat + v], update, window),
                                usable(p10, removed_at[flat + v + 1], update, window),
                                usable(p01, removed_at[flat + v + nx], update, window),
                                usable(p11, removed_at[flat + v + nx + 1], update, window),
                                float(c) * hx,
                                float(r) * hy,
                                hx,
                                hy,
                                tip,
                                best,
                            )
                    if best[3] != 0.0:
                        status = PATH_MAPPED
                        break
        return wp.vec3(best[1], best[2], status)

    return locate_tip


@wp.func
def flat_corner(x: wp.array(dtype=wp.vec3), alive: wp.array(dtype=wp.int32), i: int) -> wp.vec4:
    """Vertex ``i`` of the env-major state as ``(x, y, z, alive)``."""
    p = x[i]
    return wp.vec4(p[0], p[1], p[2], wp.where(alive[i] != 0, 1.0, 0.0))


locate_tip_flat = tip_locator(
    wp.array(dtype=wp.vec3), wp.array(dtype=wp.int32), flat_corner, "locate_tip_flat"
)


@wp.kernel
def map_tip_kernel(
    # Model:
    search: TipSearch,
    update: int,
    # Data in:
    x: wp.array(dtype=wp.vec3),
    alive: wp.array(dtype=wp.int32),
    tip: wp.array(dtype=wp.vec4),
    # Data in/out:
    removed_at: wp.array(dtype=wp.int32),
    # Data out:
    path: wp.array2d(dtype=wp.vec3),
):
    """Map each env's tip of update ``update`` to material coordinates into ``path[env, update]``
    (:func:`tip_locator`), after recording when vertices were cut (``removed_at``)."""
    env = wp.tid()
    n = search.nx * search.ny
    base = env * n
    for v in range(n):
        if alive[base + v] == 0 and removed_at[base + v] < 0:
            removed_at[base + v] = update
    path[env, update] = locate_tip_flat(x, alive, base, env, update, tip[env], removed_at, path, search)


# ----------------------------------------------------------------------------------------- gradients
# What a differentiable rollout (:mod:`warpcut.gradients`) adds under ``wp.Tape``: the grasp's hold
# shifted with the pinch point, and the path surrogate. The search for the
# tip is not differentiated: the surrogate re-reads the triangle the traced path found and differentiates
# the barycentric map inside it.


@wp.kernel
def grasp_anchor_kernel(
    n: int,
    anchor: wp.array(dtype=wp.vec3),
    pin: wp.array(dtype=wp.int32),
    jacobian_x: wp.array(dtype=wp.vec3),
    jacobian_y: wp.array(dtype=wp.vec3),
    shift: wp.array(dtype=wp.vec2),
    anchor_out: wp.array(dtype=wp.vec3),
):
    """Grasped vertices hold the material ``shift[env]`` (mm) away: their anchors move by the settled
    sheet's deformation gradient ``(jacobian_x, jacobian_y)`` times the shift; other anchors stay."""
    env, v = wp.tid()
    i = env * n + v
    a = anchor[i]
    if pin[i] == PIN_GRASP:
        s = shift[env]
        a = a + jacobian_x[i] * s[0] + jacobian_y[i] * s[1]
    anchor_out[i] = a


@wp.kernel
def path_surrogate_kernel(
    search: TipSearch,
    update: int,
    x: wp.array(dtype=wp.vec3),
    tip: wp.array(dtype=wp.vec4),
    path: wp.array2d(dtype=wp.vec3),
    target: wp.array2d(dtype=wp.vec2),
    weight: wp.array(dtype=float),
    loss: wp.array(dtype=float),
):
    """Add ``weight[env] * |m - target|^2`` to ``loss[env]``: ``m`` the tip of update ``update`` mapped
    through the deformed mesh ``x`` into material coordinates, in the triangle the traced ``path`` found
    (its cell and half by the material point); nothing where the path was not mapped or there is no
    target. ``m`` is the same barycentric map as :func:`locate_in_cell`, without its inside test."""
    env = wp.tid()
    p = path[env, update]
    t = target[env, update]
    if p[2] != PATH_MAPPED or not wp.isfinite(t):
        return
    nx = search.nx
    hx = search.hx
    hy = search.hy
    c = wp.clamp(int(p[0] / hx), 0, nx - 2)
    r = wp.clamp(int(p[1] / hy), 0, search.ny - 2)
    fx = p[0] / hx - float(c)
    fy = p[1] / hy - float(r)
    base = env * nx * search.ny + r * nx + c
    a = x[base]
    b = x[base + 1]
    d = x[base + nx + 1]
    if fy > fx:  # the upper-left half (00, 11, 01)
        b = x[base + nx + 1]
        d = x[base + nx]
    q = tip[env]
    e1x = b[0] - a[0]
    e1y = b[1] - a[1]
    e2x = d[0] - a[0]
    e2y = d[1] - a[1]
    det = e1x * e2y - e2x * e1y
    px = q[0] - a[0]
    py = q[1] - a[1]
    wb = (px * e2y - e2x * py) / det
    wc = (e1x * py - px * e1y) / det
    mx = float(c) * hx + (wb + wc) * hx
    my = float(r) * hy + wc * hy
    if fy > fx:
        mx = float(c) * hx + wb * hx
        my = float(r) * hy + (wb + wc) * hy
    dx = mx - t[0]
    dy = my - t[1]
    wp.atomic_add(loss, env, weight[env] * (dx * dx + dy * dy))
