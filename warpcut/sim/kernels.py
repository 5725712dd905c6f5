"""Warp kernels of one simulator update: integrate, relax one spring colour, cut.

All kernels live in this one module so they compile once (a cold compile costs seconds per module).
Each kernel is launched over ``(num_envs, num_vertices)`` and starts with ``env, v = wp.tid()``; state
is flattened env-major (``i = env * n + v``). Kernels are out-of-place (state in -> state out): the fast
path ping-pongs two buffers, a differentiable rollout allocates fresh outputs under ``wp.Tape``.
A physical parameter array has length 1 (shared) or num_envs and is read as ``p[env % p.shape[0]]``.
"""

from __future__ import annotations

from warpcut.sim._warp import wp

PIN_FREE = wp.constant(0)
PIN_FIXTURE = wp.constant(1)
PIN_GRASP = wp.constant(2)


# ---------------------------------------------------------------------------------------------- noise
# Process noise is drawn from a counter-based integer hash, the same in every backend (bit for bit), and
# several times cheaper than Warp's rand_init + randn (Box-Muller: logs and cosines per draw), which had
# halved the default physics' throughput once noise became the default.

NOISE_SCALE = wp.constant(0.0067658750867932)
"""1 / std of the sum of four uniform bytes: sqrt(4 * (256^2 - 1) / 12) = 147.8006."""


@wp.func
def hash32(x: wp.uint32) -> wp.uint32:
    """A full-avalanche 32-bit integer hash (lowbias32, C. Wellons)."""
    x = x ^ (x >> wp.uint32(16))
    x = x * wp.uint32(0x7FEB352D)
    x = x ^ (x >> wp.uint32(15))
    x = x * wp.uint32(0x846CA68B)
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
def cut_kernel(
    # Model:
    n: int,
    cut_radius: float,
    cut_height: float,
    # Data in:
    x: wp.array(dtype=wp.vec3),
    alive: wp.array(dtype=wp.int32),
    tip: wp.array(dtype=wp.vec4),
    # Data out:
    alive_out: wp.array(dtype=wp.int32),
):
    """Remove vertices within ``cut_radius`` (in x-y) and ``cut_height`` (in z) of an active scissor tip.

    ``tip[env] = (x, y, z, cutting)``; ``cutting`` is 0 while the scissors travel between segments.
    """
    env, v = wp.tid()
    i = env * n + v
    a = alive[i]
    t = tip[env]
    if a != 0 and t[3] > 0.5:
        p = x[i]
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
    """Move each grasp by its action, clipped to ``max_step`` per axis and ``max_displacement`` in norm."""
    env = wp.tid()
    a = action[env]
    step = wp.vec3(
        wp.clamp(a[0], -max_step, max_step),
        wp.clamp(a[1], -max_step, max_step),
        wp.clamp(a[2], -max_step, max_step),
    )
    u = displacement[env] + step
    norm = wp.length(u)
    if norm > max_displacement:
        u = u * (max_displacement / norm)
    displacement_out[env] = u


@wp.kernel
def fused_update_kernel(
    # Model:
    n: int,
    env_offset: int,
    iterations: int,
    spring_a: wp.array(dtype=wp.int32),
    spring_b: wp.array(dtype=wp.int32),
    spring_rest: wp.array(dtype=float),
    colour_start: wp.array(dtype=wp.int32),
    damping: wp.array(dtype=float),
    dt: wp.array(dtype=float),
    gravity: wp.array(dtype=float),
    noise_std: wp.array(dtype=float),
    elasticity: wp.array(dtype=float),
    first_order_z: int,
    seed: int,
    first_stream: int,
    cut_radius: float,
    cut_height: float,
    # Data in:
    pin: wp.array(dtype=wp.int32),
    anchor: wp.array(dtype=wp.vec3),
    displacement: wp.array(dtype=wp.vec3),
    tip: wp.array(dtype=wp.vec4),
    # Data in/out:
    x: wp.array(dtype=wp.vec3),
    x_prev: wp.array(dtype=wp.vec3),
    alive: wp.array(dtype=wp.int32),
):
    """A whole update of one env per thread, in place: the CPU fast path.

    One launch advances every env by integrate + ``iterations`` sweeps + cut, keeping the env's state
    hot in cache, instead of one launch per stage and colour. It visits the springs colour by colour in
    the order of :func:`relax_colour_kernel` and evaluates the same expressions, so it reproduces the
    out-of-place kernels bit for bit (``tests/test_simulator.py``); it is not differentiable.
    """
    env = wp.tid() + env_offset
    base = env * n
    h = dt[env % dt.shape[0]]
    fall = wp.vec3(0.0, 0.0, gravity[env % gravity.shape[0]] * h * h)
    keep = damping[env % damping.shape[0]]
    sigma = noise_std[env % noise_std.shape[0]]
    k = elasticity[env % elasticity.shape[0]]
    u = displacement[env]
    for v in range(n):
        i = base + v
        p = x[i]
        q = p
        kind = pin[i]
        if kind == PIN_FIXTURE:
            q = anchor[i]
        elif kind == PIN_GRASP:
            q = anchor[i] + u
        elif alive[i] != 0:
            velocity = (p - x_prev[i]) * keep
            if first_order_z != 0:
                velocity = wp.vec3(velocity[0], velocity[1], 0.0)
            q = p + velocity - fall
            if sigma > 0.0:
                q = q + sigma * process_noise(seed, i + first_stream * n)
        x_prev[i] = p
        x[i] = q
    num_colours = colour_start.shape[0] - 1
    for _sweep in range(iterations):
        for c in range(num_colours):
            for s in range(colour_start[c], colour_start[c + 1]):
                a = base + spring_a[s]
                b = base + spring_b[s]
                if alive[a] == 0 or alive[b] == 0:
                    continue
                free_a = pin[a] == PIN_FREE
                free_b = pin[b] == PIN_FREE
                pa = x[a]
                pb = x[b]
                d = pb - pa
                length = wp.length(d)
                if length < 1.0e-9:
                    continue
                rest = spring_rest[s]
                if free_a:
                    share = 0.5
                    if not free_b:
                        share = 1.0
                    x[a] = pa + d * (k * share * (length - rest) / length)
                if free_b:
                    share = 0.5
                    if not free_a:
                        share = 1.0
                    x[b] = pb + (pa - pb) * (k * share * (length - rest) / length)
    t = tip[env]
    if t[3] > 0.5:
        for v in range(n):
            i = base + v
            if alive[i] != 0:
                p = x[i]
                dx = p[0] - t[0]
                dy = p[1] - t[1]
                if dx * dx + dy * dy <= cut_radius * cut_radius and wp.abs(p[2] - t[2]) <= cut_height:
                    alive[i] = 0


# ---------------------------------------------------------------------------------------------- path
# Where the scissors went through the material: after every cutting update, the tip is located in the
# deformed mesh (two triangles per grid cell) and mapped back to rest (material) coordinates. The flat
# kernel below and the SIMD-layout kernel in ``kernels_simd`` share these functions, so both backends map
# bit-identically; they differ only in how they fetch a vertex.

PATH_MAPPED = wp.constant(1.0)
PATH_DROPPED = wp.constant(0.0)
PATH_IDLE = wp.constant(-1.0)


@wp.func
def triangle_weights(a: wp.vec3, b: wp.vec3, c: wp.vec3, tx: float, ty: float) -> wp.vec3:
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
def locate_in_cell(
    p00: wp.vec3,
    p10: wp.vec3,
    p01: wp.vec3,
    p11: wp.vec3,
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
def usable(alive: int, removed_at: int, update: int, window: int) -> int:
    """Whether a vertex may carry the tip: alive, or cut within the last ``window`` updates (the tip
    always sits on freshly cut material; older cuts are holes)."""
    if alive != 0 or update - removed_at <= window:
        return 1
    return 0


@wp.func
def search_window(
    attempt: int,
    path: wp.array2d(dtype=wp.vec3),
    env: int,
    update: int,
    tip: wp.vec4,
    nx: int,
    ny: int,
    hx: float,
    hy: float,
    reach: int,
) -> wp.vec4i:
    """Cells ``(row_lo, row_hi, col_lo, col_hi)`` searched by attempt 0 (the cells around the previous
    update's material point, if it was mapped) and 1 (``reach`` cells around the tip's x-y taken as a
    material point); an empty range skips the attempt."""
    cx = tip[0]
    cy = tip[1]
    r = reach
    if attempt == 0:
        if update == 0:
            return wp.vec4i(1, 0, 1, 0)
        previous = path[env, update - 1]
        if previous[2] != PATH_MAPPED:
            return wp.vec4i(1, 0, 1, 0)
        cx = previous[0]
        cy = previous[1]
        r = 1
    c0 = wp.clamp(int(cx / hx), 0, nx - 2)
    r0 = wp.clamp(int(cy / hy), 0, ny - 2)
    return wp.vec4i(wp.max(r0 - r, 0), wp.min(r0 + r, ny - 2), wp.max(c0 - r, 0), wp.min(c0 + r, nx - 2))


@wp.kernel
def map_tip_kernel(
    # Model:
    nx: int,
    ny: int,
    hx: float,
    hy: float,
    window: int,
    reach: int,
    env_offset: int,
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
    """Map each env's tip of update ``update`` to material coordinates: ``path[env, update] = (mx, my,
    PATH_MAPPED)``, ``(0, 0, PATH_DROPPED)`` off the sheet or over a hole, ``(0, 0, PATH_IDLE)`` while the
    scissors do not cut. First records when vertices were cut (``removed_at``). The cells of
    :func:`search_window` are searched in turn until one holds the tip."""
    env = wp.tid() + env_offset
    n = nx * ny
    base = env * n
    for v in range(n):
        if alive[base + v] == 0 and removed_at[base + v] < 0:
            removed_at[base + v] = update
    t = tip[env]
    status = PATH_IDLE
    best = wp.vec4(0.0, 0.0, 0.0, 0.0)
    if t[3] > 0.5:
        status = PATH_DROPPED
        for attempt in range(2):
            cells = search_window(attempt, path, env, update, t, nx, ny, hx, hy, reach)
            if cells[0] <= cells[1]:
                for r in range(cells[0], cells[1] + 1):
                    for c in range(cells[2], cells[3] + 1):
                        i = base + r * nx + c
                        best = locate_in_cell(
                            x[i],
                            x[i + 1],
                            x[i + nx],
                            x[i + nx + 1],
                            usable(alive[i], removed_at[i], update, window),
                            usable(alive[i + 1], removed_at[i + 1], update, window),
                            usable(alive[i + nx], removed_at[i + nx], update, window),
                            usable(alive[i + nx + 1], removed_at[i + nx + 1], update, window),
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
