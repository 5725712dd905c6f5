import numpy as np
import pytest
import warp as wp

from warpcut import ConfigError, SheetGrid, SimConfig, Simulator
from warpcut.sim.springs import colour_springs, spring_colours


def structural_stretch(positions: np.ndarray, grid: SheetGrid) -> np.ndarray:
    p = positions.reshape(grid.ny, grid.nx, 3)
    hx, hy = grid.spacing_mm
    sx = np.linalg.norm(p[:, 1:] - p[:, :-1], axis=-1) / hx - 1
    sy = np.linalg.norm(p[1:] - p[:-1], axis=-1) / hy - 1
    return np.concatenate([sx.ravel(), sy.ravel()])


@pytest.mark.parametrize(
    "springs", [("structural",), ("structural", "shear"), ("structural", "shear", "bending")]
)
def test_colours_cover_every_spring_once_and_share_no_vertex(springs):
    grid = SheetGrid(7, 6, 60.0, 50.0)
    config = SimConfig(resolution=(7, 6), width_mm=60.0, height_mm=50.0, springs=springs)
    pairs = []
    for starts, ends, _ in colour_springs(grid, config.springs):
        assert len(np.unique(np.concatenate([starts, ends]))) == 2 * len(starts)
        pairs += [tuple(sorted(p)) for p in zip(starts.tolist(), ends.tolist(), strict=True)]
    assert len(pairs) == len(set(pairs))
    expected = 7 * 5 + 6 * 6  # structural: rows * (nx-1) + cols * (ny-1)
    if "shear" in springs:
        expected += 2 * 6 * 5
    if "bending" in springs:
        expected += 6 * 5 + 7 * 4
    assert len(pairs) == expected
    assert len(spring_colours(springs)) == 4 * len(springs)


def test_default_sheet_settles_like_clipped_gauze(device):
    sim = Simulator(SimConfig(), 1, device=device)
    settled = sim.settled_positions()[0]
    z = settled[:, 2].reshape(25, 25)
    assert -25.0 < z[12, 12] < -10.0  # sag of the centre (mm), see docs/physics.md
    assert np.allclose(settled[sim.fixture, 2], 0.0)
    stretch = structural_stretch(settled, sim.grid)
    assert stretch.mean() < 0.03
    # Settled: another 100 updates move the centre by well under a millimetre.
    sim.reset()
    for _ in range(100):
        sim.update()
    assert abs(sim.positions()[0, 12 * 25 + 12, 2] - z[12, 12]) < 0.5


def test_per_env_parameters_and_shared_settling(device):
    config = SimConfig(gravity=[521.0, 1042.0, 521.0], resolution=11)
    sim = Simulator(config, 3, device=device)
    groups, env_group = sim.settle_groups()
    assert len(groups) == 2 and env_group[0] == env_group[2] != env_group[1]
    settled = sim.settled_positions()
    np.testing.assert_array_equal(settled[0], settled[2])
    assert settled[1][:, 2].min() < settled[0][:, 2].min()  # heavier sheet sags more


def test_same_seed_is_bit_identical(device):
    config = SimConfig(resolution=9, noise_std=0.05)
    runs = []
    for _ in range(2):
        sim = Simulator(config, 2, device=device, seed=7)
        sim.reset(np.array([[50.0, 50.0], [np.nan, np.nan]]))
        for _ in range(5):
            sim.move_grasp(np.array([[1.0, 0.5, 0.0], [1.0, 0.5, 0.0]]))
            sim.update()
        runs.append(sim.positions())
    np.testing.assert_array_equal(runs[0], runs[1])
    other = Simulator(config, 2, device=device, seed=8)
    other.reset()
    other.update()
    assert not np.array_equal(other.positions(), runs[0])


def test_grasp_is_clipped_per_step_and_in_total(device):
    sim = Simulator(SimConfig(resolution=9, max_displacement_mm=3.0), 2, device=device)
    sim.reset(np.array([[50.0, 50.0], [np.nan, np.nan]]))
    sim.move_grasp(np.array([[5.0, -0.3, 0.0], [1.0, 1.0, 1.0]]))
    np.testing.assert_allclose(sim.displacements(), [[1.0, -0.3, 0.0], [0.0, 0.0, 0.0]], atol=1e-6)
    for _ in range(10):
        sim.move_grasp(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]))
    assert np.linalg.norm(sim.displacements()[0]) == pytest.approx(3.0, abs=1e-5)
    with pytest.raises(ValueError, match="action: contains NaN"):
        sim.move_grasp(np.array([[np.nan, 0.0, 0.0], [0.0, 0.0, 0.0]]))


def test_grasp_moves_the_pinched_disc(device):
    sim = Simulator(SimConfig(resolution=13), 1, device=device)
    sim.reset(np.array([[50.0, 50.0]]))
    before = sim.positions()[0]
    for _ in range(5):
        sim.move_grasp(np.array([[1.0, 0.0, 0.0]]))
        sim.update()
    disc = sim.grid.disc_mask([50.0, 50.0], sim.config.grasp_radius)
    np.testing.assert_allclose(
        sim.positions()[0][disc] - before[disc], [[5.0, 0.0, 0.0]] * disc.sum(), atol=1e-4
    )


def test_cutting_removes_vertices_near_the_tip_only(device):
    sim = Simulator(SimConfig(resolution=11, gravity=0.0, noise_std=0.0), 1, device=device)
    sim.reset()
    sim.set_tip(np.array([[50.0, 50.0, 0.0, 1.0]]))
    sim.update()
    removed = ~sim.alive_mask()[0]
    near = np.linalg.norm(sim.grid.material - [50.0, 50.0], axis=1) <= sim.config.cut_radius
    np.testing.assert_array_equal(removed, near)
    sim.reset()
    sim.set_tip(np.array([[50.0, 50.0, 0.0, 0.0]]))  # travelling: no cut
    sim.update()
    assert sim.alive_mask().all()
    sim.set_tip(np.array([[50.0, 50.0, 20.0, 1.0]]))  # no height limit (the default): cut from above
    sim.update()
    np.testing.assert_array_equal(~sim.alive_mask()[0], near)


def test_a_cut_height_limit_misses_material_far_from_the_tip(device):
    sim = Simulator(SimConfig(resolution=11, gravity=0.0, noise_std=0.0, cut_height_mm=8.0), 1, device=device)
    sim.reset()
    sim.set_tip(np.array([[50.0, 50.0, 20.0, 1.0]]))  # 20 mm above the sheet: out of reach
    sim.update()
    assert sim.alive_mask().all()
    sim.set_tip(np.array([[50.0, 50.0, 5.0, 1.0]]))
    sim.update()
    assert not sim.alive_mask().all()


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"resolution": 3}, r"^SimConfig\.resolution: an integer in \[5, 100\], or a pair .* \(got 3\)$"),
        ({"damping": 1.5}, r"^SimConfig\.damping: a number in \[0, 1\]"),
        ({"elasticity": 2.0}, r"^SimConfig\.elasticity: a number in \(0, 2\)"),
        ({"fixture": "edges"}, r"^SimConfig\.fixture: one of 'corners', 'rows' \(got 'edges'\)"),
        (
            {"springs": ("shear",)},
            r"^SimConfig\.springs: a list of spring families .* including 'structural'",
        ),
        ({"sweeps": 0}, r"^SimConfig\.sweeps: an integer in \[1, 200\] \(got 0\)"),
        ({"gravity": [1.0, float("nan")]}, r"^SimConfig\.gravity: a number in .*\(got \[1\.0, nan\]\)"),
        ({"cut_height_mm": -1.0}, r"^SimConfig\.cut_height_mm: a number > 0 mm, or None for no limit"),
        ({"score": "area"}, r"^SimConfig\.score: one of 'path', 'separated'"),
        ({"chebyshev_rho": 1.0}, r"^SimConfig\.chebyshev_rho: a number in \[0, 0.99\)"),
        ({"sweeps": 2}, r"^SimConfig\.chebyshev_rho: 0.94 extrapolates too far for 2 sweeps.*at most 0.679"),
        ({"elasticity": [1.0, 1.5]}, r"^SimConfig\.elasticity: above 1.2 .* chebyshev_rho=0"),
    ],
)
def test_bad_config_names_the_field(change, message):
    with pytest.raises(ConfigError, match=message):
        SimConfig(**change).validated()


def test_chebyshev_sweeps_reach_the_sheet_of_20_plain_sweeps():
    """The default's calibration (docs/physics.md, "Fewer sweeps"): 7 Chebyshev sweeps settle the sheet
    within a fraction of a millimetre of 20 plain Gauss-Seidel sweeps (measured: RMS 0.07 mm, sag 17.17 vs
    17.23 mm), which 7 plain sweeps miss by millimetres (sag 25.5 mm)."""

    def settled(**changes):
        return Simulator(SimConfig(noise_std=0.0, **changes), 1).settled_positions()[0]

    reference = settled(sweeps=20, chebyshev_rho=0.0)
    assert SimConfig().sweeps < 10 and SimConfig().chebyshev_rho > 0
    gap = np.linalg.norm(settled() - reference, axis=1)
    assert np.sqrt(np.mean(gap**2)) < 0.2 and gap.max() < 1.0
    plain = np.linalg.norm(settled(chebyshev_rho=0.0) - reference, axis=1)
    assert np.sqrt(np.mean(plain**2)) > 2.0


@pytest.mark.parametrize("backend", ["simd", "colours"])
def test_gather_reads_what_positions_and_alive_mask_hold(backend):
    sim = Simulator(SimConfig(resolution=9), 11, backend=backend, seed=2)
    sim.reset(np.tile([[50.0, 50.0]], (11, 1)))
    sim.set_tip(np.tile([[50.0, 50.0, -5.0, 1.0]], (11, 1)))
    vertices = np.random.default_rng(0).integers(0, 81, size=(11, 7))
    for _ in range(2):  # straight after a reset (unpacked state), then after updates (packed, for simd)
        got = sim.gather(vertices)  # (before positions() unpacks the state)
        expected = np.concatenate(
            [
                np.take_along_axis(sim.positions(), vertices[..., None], axis=1),
                np.take_along_axis(sim.alive_mask(), vertices, axis=1)[..., None],
            ],
            axis=2,
        )
        np.testing.assert_array_equal(got, expected)
        for _ in range(3):
            sim.update()
    assert (sim.gather(vertices)[..., 3] == 0).any()  # the comparison covered cut vertices
    with pytest.raises(ValueError, match="vertices: indices must lie in"):
        sim.gather(np.full((11, 1), 81))


@pytest.mark.parametrize("backend", ["simd", "colours"])
def test_a_gatherer_reads_the_state_at_each_call(backend):
    """A :meth:`Simulator.gatherer` made once reads what ``gather`` reads now, call after call: after updates,
    after a reset (unpacked state) and after the caller changed its own index array."""
    sim = Simulator(SimConfig(resolution=9), 11, backend=backend, seed=2)
    sim.reset(np.tile([[50.0, 50.0]], (11, 1)))
    vertices = np.random.default_rng(1).integers(0, 81, size=(11, 9))
    read = sim.gatherer(vertices)
    expected = vertices.copy()
    vertices[:] = 0  # the gatherer kept its own indices
    for _ in range(2):
        sim.set_tip(np.tile([[50.0, 50.0, -5.0, 1.0]], (11, 1)))
        for _ in range(3):
            sim.update()
            np.testing.assert_array_equal(read(), sim.gather(expected))
        assert (read()[..., 3] == 0).any()
        sim.reset(np.tile([[50.0, 50.0]], (11, 1)))
        np.testing.assert_array_equal(read(), sim.gather(expected))
        assert (read()[..., 3] == 1).all()
    with pytest.raises(ValueError, match=r"vertices: expected \(11, K\) indices"):
        sim.gatherer(np.zeros((3, 2), dtype=int))


def test_per_env_length_mismatch_is_reported():
    with pytest.raises(ConfigError, match="gravity: got 2 values for 3 envs"):
        Simulator(SimConfig(gravity=[1.0, 2.0]), 3)


def test_unknown_device_is_reported():
    with pytest.raises(ValueError, match="device: unknown device 'tpu'"):
        Simulator(SimConfig(resolution=5), 1, device="tpu")


def test_backends_are_bit_identical(device):
    """simd (several blocks of 8 envs, over threads) and colours (launched one by one, or replayed from
    captured graphs): the same bits, noise included, across a reset."""
    config = SimConfig(resolution=13, noise_std=0.05)
    pinches = np.tile([[50.0, 50.0], [np.nan, np.nan], [30.0, 60.0]], (4, 1))[:11]
    cpu = wp.get_device(device).is_cpu
    variants = [("simd", 1, False), ("simd", 2, False)] if cpu else []
    results = []
    for backend, threads, capture in [*variants, ("colours", None, False), ("colours", None, True)]:
        sim = Simulator(config, 11, device=device, seed=3, backend=backend, threads=threads, capture=capture)
        z = sim.settled_positions()[0, 6 * 13 + 10, 2]
        for episode in range(2):
            if episode:
                sim.seed = 11  # a new noise stream for the next episode (as CuttingTask.reset(seed=...))
            sim.reset(pinches)
            for k in range(30 if episode else 7):
                sim.move_grasp(np.tile([[0.7, -0.4, 0.1]], (11, 1)))
                sim.set_tip(np.tile([[80.0 - 1.5 * k, 50.0, z, 1.0]], (11, 1)))
                sim.update()
                if k == 10:
                    sim.positions()  # a read-back in the middle must not disturb the packed state
        if capture:
            assert len(sim._graphs) == 6  # 3 position buffers x 2 alive buffers, recorded once each
        results.append((sim.positions(), sim.alive_mask()))
    assert (~results[0][1]).sum() > 0
    for positions, alive in results[1:]:
        np.testing.assert_array_equal(positions, results[0][0])
        np.testing.assert_array_equal(alive, results[0][1])


def test_unknown_backend_is_reported():
    with pytest.raises(
        ValueError, match=r"^Simulator\.backend: one of 'auto', 'simd', 'colours' \(got 'magic'\)"
    ):
        Simulator(SimConfig(resolution=5), 1, backend="magic")


def test_capture_needs_the_colours_backend():
    with pytest.raises(ValueError, match="capture: graph capture applies to the 'colours' backend"):
        Simulator(SimConfig(resolution=5), 1, device="cpu", backend="simd", capture=True)


def test_captured_graphs_stay_few_and_right_around_taped_updates():
    """Taped updates and a caller's displacement array run uncaptured; after a reset the simulator's
    own buffers (and its at most 6 graphs) are used again, with the same bits as launching one by one."""
    config = SimConfig(resolution=9, noise_std=0.05)
    runs = []
    for capture in (False, True):
        sim = Simulator(config, 2, device="cpu", backend="colours", capture=capture, seed=5)
        replays = []
        replay = sim._update_captured
        sim._update_captured = lambda s=sim, r=replays, f=replay: (r.append(s.update_count), f())
        for episode in range(3):
            sim.reset(np.array([[50.0, 50.0]] * 2))
            for k in range(8):
                sim.move_grasp(np.tile([[1.0, 0.0, 0.5]], (2, 1)))
                sim.update(tape_mode=episode == 1 and k == 3)
            if episode == 1:
                sim.displacement = wp.array(sim.displacements(), dtype=wp.vec3, device="cpu")
                sim.update()
        runs.append(sim.positions())
        assert len(sim._graphs) == (6 if capture else 0)
        # Episodes 0 and 2 replay graphs throughout; episode 1 only before its taped update.
        assert len(replays) == (8 + 3 + 8 if capture else 0)
    np.testing.assert_array_equal(runs[0], runs[1])


def test_simd_state_survives_a_switch_to_the_taped_path():
    config = SimConfig(resolution=9, noise_std=0.05)  # with noise: the taped update draws the same stream
    runs = []
    for backend in ("simd", "colours"):
        sim = Simulator(config, 3, backend=backend)
        sim.reset(np.array([[50.0, 50.0]] * 3))
        for k in range(6):
            sim.move_grasp(np.tile([[1.0, 0.0, 0.0]], (3, 1)))
            sim.update(tape_mode=k == 3)  # one update on the differentiable path in the middle
        runs.append(sim.positions())
    np.testing.assert_array_equal(runs[0], runs[1])


def test_authors_preset_reproduces_their_settled_sheet():
    """Their released code, ported and run as released: rows pinned, 200 updates, centre sag 12.5 mm,
    largest structural stretch 10.0%, mean 2.3%. Tolerance: 1 mm, 1.5 and 0.4 points."""
    from warpcut.sim.checks import settled_figures

    config = SimConfig.authors()
    assert config.settle_updates == 200 and config.updates_per_step == 1
    assert config.cut_radius == pytest.approx(10.0 / 4.8)
    sag, stretch_max, stretch_mean = settled_figures(Simulator(config, 1))
    assert sag == pytest.approx(12.5, abs=1.0)
    assert stretch_max == pytest.approx(10.0, abs=1.5)
    assert stretch_mean == pytest.approx(2.3, abs=0.4)
    # warpcut's own update (the full g dt^2 step) hangs the same rows much deeper.
    sag_full, _, _ = settled_figures(Simulator(config.replace(gravity=SimConfig().gravity), 1))
    assert sag_full > sag + 4.0


def test_process_noise_is_standard_normal_and_independent():
    """The hash-based draws (warpcut.sim.kernels.process_noise): mean 0, variance 1, no correlation between
    axes, neighbouring streams or consecutive seeds; bounded (Irwin-Hall, four bytes) at about +-3.45."""
    from warpcut.sim._warp import wp
    from warpcut.sim.kernels import process_noise

    @wp.kernel
    def draw(seeds: wp.array(dtype=wp.int32), out: wp.array2d(dtype=wp.vec3)):
        s, i = wp.tid()
        out[s, i] = process_noise(seeds[s], i)

    seeds = wp.array(np.array([7, 8, 123456], dtype=np.int32))
    out = wp.zeros((3, 20000), dtype=wp.vec3)
    wp.launch(draw, dim=(3, 20000), inputs=[seeds], outputs=[out])
    x = out.numpy()  # (seed, stream, axis)
    flat = x.reshape(-1)
    assert abs(flat.mean()) < 0.01 and abs(flat.std() - 1.0) < 0.01
    assert np.abs(flat).max() < 3.5
    corr = np.corrcoef([x[0, :, 0], x[0, :, 1], x[0, :, 2], x[1, :, 0], np.roll(x[0, :, 0], 1), x[2, :, 2]])
    assert np.abs(corr - np.eye(len(corr))).max() < 0.03


def test_a_launch_record_replays_what_a_launch_computes():
    """:class:`LaunchRecord` (the per-update launches, replayed): the same results as ``launch`` while its
    arrays are the same objects and their contents change, a changed number re-packed, a new array (or a
    NumPy array, copied at each launch) launched afresh."""
    from warpcut.sim import kernels
    from warpcut.sim._warp import LaunchRecord, launch

    rng = np.random.default_rng(0)
    disp = wp.array(rng.normal(size=(5, 3)), dtype=wp.vec3, device="cpu")
    action = wp.array(rng.normal(size=(5, 3)), dtype=wp.vec3, device="cpu")
    out, expected = (wp.zeros(5, dtype=wp.vec3, device="cpu") for _ in range(2))
    record = LaunchRecord()

    def check(max_step: float, act) -> None:
        record(kernels.move_grasp_kernel, 5, [max_step, 10.0, disp, act], [out], "cpu")
        launch(kernels.move_grasp_kernel, 5, [max_step, 10.0, disp, act], [expected], "cpu")
        np.testing.assert_array_equal(out.numpy(), expected.numpy())

    check(0.5, action)
    first = out.numpy().copy()
    action.assign(rng.normal(size=(5, 3)))  # the same array, new contents: replayed
    check(0.5, action)
    assert not np.array_equal(out.numpy(), first)
    check(0.25, action)  # a number changed: re-packed
    assert np.abs(out.numpy() - disp.numpy()).max() <= 0.25 + 1e-6
    check(0.25, wp.array(rng.normal(size=(5, 3)), dtype=wp.vec3, device="cpu"))  # another array: anew
    moves = rng.normal(size=(5, 3)).astype(np.float32)
    check(0.5, moves)
    moves[:] = 0.0  # a NumPy array is copied at every launch, never replayed stale
    check(0.5, moves)
    np.testing.assert_array_equal(out.numpy(), disp.numpy())
    empty = wp.zeros(0, dtype=wp.vec3, device="cpu")
    nothing = LaunchRecord()
    for _ in range(2):  # an empty launch (no fiducials, say) has nothing to record or run
        nothing(kernels.move_grasp_kernel, 0, [0.5, 10.0, empty, empty], [empty], "cpu")


@pytest.mark.parametrize("backend", ["simd", "colours"])
def test_an_interpolator_reads_what_gather_and_interpolation_give(backend):
    """:meth:`Simulator.interpolator` (the ``simd`` backend's kernel over its packed blocks; the others gather
    and interpolate in NumPy): the world positions ``interpolate_corners`` gives for the gathered corners,
    bit for bit, and whether each cell is whole, straight after a reset and after cutting updates."""
    from warpcut.sim.material import interpolate_corners, material_cells

    sim = Simulator(SimConfig(resolution=9), 11, backend=backend, seed=2)
    sim.reset(np.tile([[50.0, 50.0]], (11, 1)))
    points = np.random.default_rng(3).uniform(0.0, 100.0, size=(11, 6, 2))
    vertices, weights = material_cells(points, sim.grid)
    read = sim.interpolator(vertices, weights)
    for _ in range(2):
        for _ in range(3):
            state = sim.gather(vertices.reshape(11, -1)).reshape(11, 6, 4, 4)
            world, whole = read()
            np.testing.assert_array_equal(world, interpolate_corners(state[..., :3], weights))
            np.testing.assert_array_equal(whole, (state[..., 3] != 0).all(axis=-1))
            sim.set_tip(np.tile([[50.0, 50.0, -5.0, 1.0]], (11, 1)))
            sim.update()
        assert not whole.all()  # the comparison covered cut cells
        sim.reset(np.tile([[50.0, 50.0]], (11, 1)))
    with pytest.raises(ValueError, match=r"vertices, weights: expected \(11, K, 4\) each"):
        sim.interpolator(vertices[:, :, :3], weights[:, :, :3])
