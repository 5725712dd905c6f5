"""Trajectories and whole cuts through CuttingTask."""

import numpy as np
import pytest

from warpcut import SheetGrid, SimConfig, Simulator
from warpcut.contours import load_contour, validate
from warpcut.task import CuttingTask, material_to_world
from warpcut.trajectory import Trajectory


def test_material_to_world_is_exact_on_a_flat_sheet():
    grid = SheetGrid(11, 11, 100.0, 100.0)
    flat = np.column_stack([grid.material, np.zeros(grid.num_vertices)])
    points = np.array([[0.0, 0.0], [12.3, 45.6], [100.0, 100.0]])
    np.testing.assert_allclose(material_to_world(points, flat, grid)[:, :2], points, atol=1e-9)


def test_trajectory_spacing_and_non_cutting_travel_between_segments():
    grid = SheetGrid(11, 11, 100.0, 100.0)
    flat = np.column_stack([grid.material, np.zeros(grid.num_vertices)])
    segments = [np.array([[80.0, 70.0], [20.0, 70.0]]), np.array([[80.0, 30.0], [20.0, 30.0]])]
    traj = Trajectory.from_segments(segments, flat, grid, spacing_mm=1.0)
    steps = np.linalg.norm(np.diff(traj.tip[:, :3], axis=0), axis=1)
    assert np.all(steps <= 1.0 + 1e-4)
    cutting = traj.tip[:, 3] > 0.5
    assert cutting[0] and cutting[-1] and not cutting.all()
    travel = traj.tip[~cutting]
    assert np.all(np.isnan(traj.material[~cutting]))
    # travel runs from the first segment's end (20, 70) to the second's start (80, 30)
    assert travel[:, 0].min() > 20.0 and travel[:, 0].max() < 80.0


def test_target_world_and_cut_deviation_follow_the_sheet(device):
    """What the envs observe and reward every step, from what the task precomputes once per layout, against
    the same quantities computed from scratch: each update's target interpolated on the sheet as it is now,
    and the distance between where the scissors cut and where they meant to (both contours, cutting and
    travelling updates, and past the horizon)."""
    contours = [load_contour("fls-circle"), load_contour("wave-1")]
    task = CuttingTask(
        SimConfig(resolution=13), contours, pinch_points=[[50.0, 50.0], [50.0, 30.0]], device=device,
        allow_infeasible_pinch=True,  # under the arm: the grasp moves the contour being cut
    )  # fmt: skip
    task.reset()
    targets = task.target_points()
    while not task.done:
        u, t = task.update_index, min(task.update_index, task.horizon_updates - 1)
        positions = task.sim.positions()
        for env in range(2):
            if np.isfinite(targets[env, t]).all() and u < task.horizon_updates:
                expected = material_to_world(targets[env, t][None], positions[env], task.grid)[0]
                np.testing.assert_allclose(task.target_world()[env], expected, rtol=0, atol=1e-9)
            else:
                assert np.isnan(task.target_world()[env]).all()
        task.step(None)
        path = task.cut_path()[:, u : task.update_index]
        target = targets[:, u : task.update_index]
        mapped = (path[..., 2] > 0.5) & np.isfinite(target).all(axis=-1)
        distance = np.linalg.norm(np.where(mapped[..., None], path[..., :2] - target, 0.0), axis=-1)
        mean, count = task.cut_deviation(u, task.update_index)
        np.testing.assert_array_equal(count, mapped.sum(axis=1))
        with np.errstate(invalid="ignore", divide="ignore"):
            np.testing.assert_array_equal(mean, np.where(count > 0, distance.sum(axis=1) / count, np.nan))
    assert np.isnan(task.target_world()).all()  # done: nothing left to cut


def test_scissors_do_not_cut_while_travelling(device):
    contour = load_contour("wave-1")
    config = SimConfig(resolution=21, gravity=0.0)
    segments = [[np.array([[90.0, 80.0], [60.0, 80.0]]), np.array([[40.0, 20.0], [10.0, 20.0]])]]
    task = CuttingTask(config, contour, segments=segments, device=device)
    task.run(None)
    removed = ~task.sim.alive_mask()[0]
    centre = np.linalg.norm(task.grid.material - [50.0, 50.0], axis=1) < 10.0  # on the travel path only
    assert removed.any() and not removed[centre].any()


def test_rigid_sheet_cut_exactly_on_the_contour_scores_near_zero(device):
    """No gravity: the sheet stays flat, the scissors land on the contour. The residual is the kerf
    split's resolution bound (tests/test_scoring.py): at most 0.35 * perimeter * spacing."""
    contour = load_contour("fls-circle")
    config = SimConfig(gravity=0.0)
    task = CuttingTask(config, contour, device=device)
    score = task.run(None)
    bound = 0.35 * contour.length * max(config.spacing_mm)
    assert score.error_mm2[0] <= bound
    assert score.error_mm2[0] < 0.2 * contour.area_mm2


def test_uncut_sheet_scores_the_intended_area(device):
    contour = load_contour("fls-circle")
    task = CuttingTask(SimConfig(resolution=13), contour, device=device)
    task.reset()
    score = task.score()
    # Nothing cut: the path encloses nothing (its error is the whole intended area) and nothing came free.
    assert score.metric == "path"
    assert score.error_mm2[0] == pytest.approx(contour.area_mm2)
    assert score.error_vertices[0] == pytest.approx(contour.area_mm2 / task.grid.vertex_area_mm2)
    assert np.isnan(score.dropped_fraction[0])
    assert score.separated_error_vertices[0] == score.missed_vertices[0] == score.intended.sum() > 0
    assert not score.separated[0]


def test_tasks_batch_different_contours_and_pinches(device):
    contours = [load_contour("fls-circle"), load_contour("s-curve")]
    task = CuttingTask(
        SimConfig(resolution=13), contours, pinch_points=[[50.0, 42.0], [np.nan, np.nan]], device=device,
        allow_infeasible_pinch=True,
    )  # fmt: skip
    assert task.num_steps == max(np.ceil(len(t.tip) / 2) for t in task.trajectories)
    score = task.run(lambda t: np.tile([[1.0, 0.0, 0.0]], (2, 1)))
    assert np.all(np.isfinite(score.error_vertices))
    assert task.sim.grasped.tolist() == [True, False]
    np.testing.assert_allclose(task.sim.displacements()[1], 0.0)
    with pytest.raises(RuntimeError, match="episode is over"):
        task.step()


def test_bad_task_inputs_are_named():
    contour = load_contour("fls-circle")
    with pytest.raises(ValueError, match="pinch_points: .* off the 100 x 100 mm sheet"):
        CuttingTask(SimConfig(resolution=7), contour, pinch_points=[120.0, 50.0])
    with pytest.raises(ValueError, match="contours: got 2 for 3 envs"):
        CuttingTask(SimConfig(resolution=7), [contour, contour], num_envs=3)


def test_fifty_by_fifty_sheet_runs():
    sim = Simulator(SimConfig(resolution=50, settle_updates=20), 1)
    settled = sim.settled_positions()
    assert settled.shape == (1, 2500, 3) and np.all(np.isfinite(settled))


@pytest.mark.slow
def test_every_builtin_has_a_positive_no_tension_error():
    from warpcut.contours import builtin_contours

    contours = list(builtin_contours().values())
    score = CuttingTask(SimConfig(), contours).run(None)
    bad = [
        c.name for c, e in zip(contours, score.error_vertices, strict=True) if not (np.isfinite(e) and e > 0)
    ]
    assert not bad, f"no-tension error not positive for {bad}"


def test_custom_contour_validates_through_the_same_path():
    contour = validate("square", True, [[30, 30], [70, 30], [70, 70], [30, 70]])
    task = CuttingTask(SimConfig(resolution=9), contour)
    assert task.trajectories[0].tip[0, 0] == pytest.approx(70.0, abs=1.0)  # starts at the right (notch side)
