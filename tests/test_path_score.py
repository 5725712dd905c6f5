"""The path score (the paper's): hand-checkable cases, end to end through the simulator where it can be."""

import numpy as np
import pytest
import shapely

from warpcut import SimConfig, Simulator
from warpcut.contours import load_contour, validate
from warpcut.scoring import order_cut_path, order_cut_paths, path_region, path_regions
from warpcut.sim.kernels import PATH_DROPPED, PATH_IDLE, PATH_MAPPED
from warpcut.task import CuttingTask
from warpcut.trajectory import default_segments

RIGID = SimConfig(gravity=0.0, noise_std=0.0)
"""No gravity, no noise: the sheet never moves, so material and world coordinates coincide."""


def circle(radius: float, centre=(50.0, 50.0), points: int = 720) -> np.ndarray:
    t = np.linspace(0.0, 2 * np.pi, points, endpoint=False)
    return np.column_stack([centre[0] + radius * np.cos(t), centre[1] + radius * np.sin(t)])


def test_a_rigid_sheet_cut_exactly_on_the_contour_scores_under_one_vertex(device):
    contour = load_contour("fls-circle")
    score = CuttingTask(RIGID, contour, num_envs=2, device=device).run(None)
    assert np.all(score.path_error_vertices < 1.0)
    assert score.metric == "path" and np.array_equal(score.error_vertices, score.path_error_vertices)
    assert np.all(score.separated)  # the disc came free too


def test_a_path_displaced_by_d_scores_about_perimeter_times_d():
    contour = validate("disc", True, circle(20.0))
    for d in (0.5, 1.0, 2.0):
        region = path_region(circle(20.0 + d), contour)
        error = shapely.symmetric_difference(region, contour.intended_region()).area
        assert error == pytest.approx(contour.length * d, rel=0.06), d


def test_an_offset_cut_through_the_simulator_scores_perimeter_times_d(device):
    contour = validate("disc", True, circle(20.0))
    d = 2.0
    wider = validate("wider", True, circle(20.0 + d))  # the scissors follow a circle 2 mm too wide
    task = CuttingTask(RIGID, contour, segments=[default_segments(wider)], device=device)
    score = task.run(None)
    assert score.path_error_mm2[0] == pytest.approx(contour.length * d, rel=0.1)
    assert score.dropped_fraction[0] < 0.05


def test_an_open_contour_closes_on_the_intended_side(device):
    contour = load_contour("arc-top")
    exact = CuttingTask(RIGID, contour, device=device).run(None)
    assert exact.path_error_vertices[0] < 1.0
    # Shifted 2 mm toward the sheet's middle: about length x 2 mm, not the rest of the sheet.
    shifted = contour.points - [0.0, 2.0]
    region = path_region(shifted, contour)
    error = shapely.symmetric_difference(region, contour.intended_region()).area
    inside = contour.length - 2 * 2.0  # the ends run along the edges, not across
    assert error == pytest.approx(inside * 2.0, rel=0.1)
    assert error < 0.2 * contour.area_mm2


def test_two_segments_score_as_the_single_loop(device):
    contour = load_contour("fls-circle")
    loop = default_segments(contour)[0]
    half = len(loop) // 2
    # Second half first, then the first half cut backwards: the path is still put in contour order.
    two = [loop[half:], loop[: half + 1][::-1]]
    score = CuttingTask(RIGID, [contour] * 2, segments=[[loop], two], device=device).run(None)
    assert np.all(score.path_error_vertices < 1.0)
    assert score.path_error_vertices[1] == pytest.approx(score.path_error_vertices[0], abs=0.5)


def test_a_tip_over_a_hole_is_dropped_and_counted(device):
    contour = load_contour("fls-circle")
    loop = default_segments(contour)[0]
    again = loop[:21]  # 20 mm of the loop cut a second time: the tip is over its own old cut
    score = CuttingTask(RIGID, contour, segments=[[loop, again]], device=device).run(None)
    cutting_updates = contour.length + 20.0  # 1 mm per update
    assert score.dropped_fraction[0] == pytest.approx(20.0 / cutting_updates, abs=0.03)
    assert score.path_error_vertices[0] < 1.0  # dropped points are left out, the loop still closes


def test_a_tip_off_the_sheet_is_dropped_and_an_idle_one_marked(device):
    sim = Simulator(RIGID.replace(resolution=9), 3, device=device)
    sim.trace_path(2)
    sim.reset()
    sim.set_tip(np.array([[150.0, 50.0, 0.0, 1.0], [30.0, 40.0, 0.0, 1.0], [30.0, 40.0, 0.0, 0.0]]))
    sim.update()
    path = sim.path.numpy()[:, 0]
    assert path[0, 2] == PATH_DROPPED
    assert path[1, 2] == PATH_MAPPED and path[1, :2] == pytest.approx([30.0, 40.0], abs=1e-4)
    assert path[2, 2] == PATH_IDLE


def test_the_cut_path_is_bit_identical_across_backends():
    contour = load_contour("kidney")
    config = SimConfig(resolution=13, noise_std=0.05)
    paths = []
    for backend in ("simd", "colours"):
        task = CuttingTask(
            config, contour, num_envs=3, pinch_points=[60.0, 20.0], backend=backend, seed=4,
            allow_infeasible_pinch=True,
        )  # fmt: skip
        task.run(lambda t: np.tile([[0.5, -1.0, 0.2]], (3, 1)))
        paths.append(task.cut_path())
    for other in paths[1:]:
        np.testing.assert_array_equal(paths[0], other)


def test_order_cut_path_sorts_by_arc_and_counts_drops():
    path = np.array(
        [[1.0, 1.0, PATH_MAPPED], [2.0, 2.0, PATH_DROPPED], [3.0, 3.0, PATH_MAPPED], [0.0, 0.0, PATH_IDLE]]
    )
    arc = np.array([5.0, 4.0, 1.0, np.nan])
    points, dropped = order_cut_path(path, arc)
    np.testing.assert_array_equal(points, [[3.0, 3.0], [1.0, 1.0]])
    assert dropped == pytest.approx(1 / 3)


def test_a_batch_of_cut_paths_is_ordered_as_each_env_alone():
    """:func:`order_cut_paths` sorts a batch in one call: per env, the points and dropped share of
    :func:`order_cut_path`'s own definition (mapped points by arc length, stably), equal arc lengths, envs
    that never cut and envs with every update dropped among them."""
    rng = np.random.default_rng(5)
    b, t = 12, 40
    paths = rng.uniform(0.0, 100.0, size=(b, t, 3))
    paths[..., 2] = rng.choice([PATH_MAPPED, PATH_DROPPED, PATH_IDLE], size=(b, t), p=[0.6, 0.2, 0.2])
    arc = rng.integers(0, 15, size=(b, t)).astype(np.float64)  # ties: the stable order decides
    arc[rng.uniform(size=(b, t)) < 0.1] = np.nan
    paths[2, :, 2] = PATH_IDLE
    paths[3, :, 2] = PATH_DROPPED
    points, dropped = order_cut_paths(paths, arc)
    for env in range(b):
        cutting = (paths[env, :, 2] >= 0.0) & np.isfinite(arc[env])
        mapped = cutting & (paths[env, :, 2] > 0.5)
        order = np.argsort(arc[env][mapped], kind="stable")
        np.testing.assert_array_equal(points[env], paths[env][mapped][order, :2])
        expected = (cutting.sum() - mapped.sum()) / cutting.sum() if cutting.any() else np.nan
        np.testing.assert_equal(dropped[env], expected)
        single = order_cut_path(paths[env], arc[env])
        np.testing.assert_array_equal(single[0], points[env])
        np.testing.assert_equal(single[1], dropped[env])
    assert np.isnan(dropped[2]) and dropped[3] == 1.0 and len(points[3]) == 0


def test_a_batch_of_path_regions_is_each_env_alone():
    """:func:`path_regions` closes the closed contours' rings in one vectorised call: the same geometry as
    one env at a time, closed and open contours, self-crossing and too-short paths mixed."""
    closed, wavy = load_contour("kidney"), load_contour("wave-2")
    crossing = np.array([[30.0, 30.0], [70.0, 70.0], [70.0, 30.0], [30.0, 70.0]])  # a bow tie
    points = [
        circle(20.0),
        wavy.points + [0.0, 1.5],
        crossing,
        circle(20.0)[:2],
        wavy.points[:1],
        circle(30.0),
    ]
    contours = [closed, wavy, closed, closed, wavy, closed]
    batch = path_regions(points, contours)
    for region, p, c in zip(batch, points, contours, strict=True):
        alone = path_region(p, c)
        assert region.equals(alone) or (region.is_empty and alone.is_empty)
        if c.closed and len(p) >= 3:  # ... and what one polygon made valid gives
            one = shapely.make_valid(shapely.Polygon(p), method="structure", keep_collapsed=False)
            assert region.equals(one)
    assert batch[2].area > 0 and batch[3].is_empty and batch[4].is_empty


def test_an_open_contour_that_halves_the_sheet_keeps_its_side_on_a_tie():
    """A row of vertices halving the sheet: its two pieces are equal, so the intended side is the one on the
    contour's left, and a shift by round-off (1e-9 mm either way) keeps it; the cut path is closed on that
    same piece, never on the other half (an error of the whole sheet, 575.5 vertices)."""
    from warpcut.scoring import path_errors
    from warpcut.sim.config import SheetGrid

    grid = SheetGrid.from_config(SimConfig())
    path = np.array([[0.0, 50.0], [25.0, 50.0], [50.0, 50.0], [75.0, 50.0], [100.0, 50.0]])
    for dy in (0.0, 1e-9, -1e-9):
        contour = validate("half", False, [[0, 50 + dy], [50, 50 + dy], [100, 50 + dy]])
        assert contour.intended_region().bounds[1] == pytest.approx(50.0) and contour.area_mm2 > 4999
        error_mm2, error_vertices, _ = path_errors([path], [contour], grid)
        assert error_mm2[0] < 1e-6 and error_vertices[0] < 1e-6
    backwards = validate("half", False, [[100, 50], [50, 50], [0, 50]])  # its left: the lower half
    assert backwards.intended_region().bounds[3] == pytest.approx(50.0)
