"""Mesh export (warpcut.viz.mesh_export): the sheet at any step as GLB/OBJ/PLY, read back with trimesh."""

import numpy as np
import pytest
import trimesh

from warpcut.contours import load_contour
from warpcut.sim.config import SimConfig
from warpcut.task import CuttingTask
from warpcut.viz.colours import STRAIN_FULL_SCALE, ramp_rgba, vertex_strain
from warpcut.viz.mesh_export import MESH_FORMATS, MeshExports, export_mesh, sheet_mesh
from warpcut.viz.rerun_writer import grid_triangles


@pytest.fixture(scope="module")
def cut_task():
    """A small sheet, cut to the end (vertices removed), env 1 grasped."""
    task = CuttingTask(
        SimConfig(resolution=13),
        load_contour("fls-circle"),
        num_envs=2,
        pinch_points=np.array([[50.0, 45.0], [50.0, 45.0]]),
        device="cpu",
        allow_infeasible_pinch=True,  # under the arm: it grasps the piece, whose mesh is exported
    )
    task.run(lambda t: np.full((2, 3), 0.3))
    return task


def live_triangles(task, env):
    _, alive = task.sim.read_envs([env])
    triangles = grid_triangles(task.grid)
    return triangles[alive[0][triangles].all(axis=1)], alive[0]


@pytest.mark.parametrize("kind", MESH_FORMATS)
def test_exported_mesh_loads_back_with_the_live_triangles(tmp_path, cut_task, kind):
    live, alive = live_triangles(cut_task, 1)
    assert not alive.all() and len(live) < len(grid_triangles(cut_task.grid)), "the cut removed nothing"
    path = export_mesh(cut_task, tmp_path / f"sheet.{kind}", env=1)
    assert path == tmp_path / f"sheet.{kind}" and not list(tmp_path.glob(".*.tmp"))
    loaded = trimesh.load(path, process=False, force="mesh")
    positions, _ = cut_task.sim.read_envs([1])
    assert loaded.faces.shape == (len(live), 3)
    # The same triangles, vertex for vertex (positions are float32 in the simulation).
    np.testing.assert_allclose(loaded.vertices[loaded.faces], positions[0][live], atol=1e-4)
    assert loaded.visual.kind == "vertex"


def test_sheet_mesh_colours_and_grid_indices(cut_task):
    mesh = sheet_mesh(cut_task, env=0)
    used = mesh.metadata["grid_vertices"]
    positions, alive = cut_task.sim.read_envs([0])
    assert alive[0][used].all() and np.array_equal(mesh.vertices, positions[0, used])
    strain = vertex_strain(positions, alive, cut_task.grid, cut_task.config.springs)[0]
    packed = ramp_rgba(strain[used], 0.0, STRAIN_FULL_SCALE)
    assert np.array_equal(mesh.visual.vertex_colors[:, 0], (packed >> 24).astype(np.uint8))
    assert sheet_mesh(cut_task, 0, colour_by=None).visual.kind is None
    height = sheet_mesh(cut_task, 0, colour_by="height").visual.vertex_colors
    assert len(np.unique(height[:, :3], axis=0)) > 1


def test_bad_arguments_name_the_field(tmp_path, cut_task):
    with pytest.raises(ValueError, match=r"env: must be an integer in \[0, 2\) \(got 2\)"):
        sheet_mesh(cut_task, env=2)
    with pytest.raises(ValueError, match="colour_by: must be one of strain, height or None"):
        sheet_mesh(cut_task, colour_by="rainbow")
    with pytest.raises(ValueError, match=r"path: '.*sheet.stl' is not a mesh file type; end it in .glb"):
        export_mesh(cut_task, tmp_path / "sheet.stl")
    with pytest.raises(ValueError, match="every: must be a positive integer or None"):
        MeshExports(tmp_path, every=0)
    with pytest.raises(ValueError, match="formats: give some of glb, obj, ply"):
        MeshExports(tmp_path, formats=("stl",))


def test_step_callback_writes_at_the_end_and_every_k_steps(tmp_path):
    task = CuttingTask(SimConfig(resolution=9), load_contour("circle-small"), num_envs=2, device="cpu")
    every = MeshExports(tmp_path / "every", envs=1, every=10, formats=("ply",))
    end = MeshExports(tmp_path / "end", envs=5, formats=("glb", "obj"))

    def both(t, action):
        every.step_callback("none")(t, action)
        end.step_callback("no/ne")(t, action)

    task.run(None, on_step=both)
    steps = sorted({*range(0, task.num_steps + 1, 10), task.num_steps})
    assert [p.name for p in every.written] == [f"none_env0_step{s}.ply" for s in steps]
    names = sorted(p.name for p in end.written)
    stem = end.written[0].name.split("_env")[0]
    assert "/" not in stem and len(names) == 4  # two envs (of five asked), two formats, the last step only
    assert names == sorted(f"{stem}_env{e}_step{task.num_steps}.{k}" for e in (0, 1) for k in ("glb", "obj"))
    assert all(p.is_file() for p in every.written + end.written)


def test_simulate_export_mesh_writes_each_policys_final_sheet(tmp_path):
    import trimesh
    from click.testing import CliRunner

    from agents.cli import main

    result = CliRunner().invoke(
        main,
        ["simulate", "--contour", "circle-small", "--policy", "none,fixed", "--set", "sim.resolution=9",
         "--trials", "1", "--set", "plots=false", "--set", f"export_mesh={tmp_path / 'meshes'}",
         "--json", str(tmp_path / "r.json")],
        catch_exceptions=False,
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    written = sorted(p.name for p in (tmp_path / "meshes").glob("*.glb"))
    assert [n.split("_")[0] for n in written] == ["fixed", "none"] and all("_env0_step" in n for n in written)
    mesh = trimesh.load(tmp_path / "meshes" / written[0], force="mesh")
    assert len(mesh.faces) > 0 and f"wrote {tmp_path / 'meshes' / written[0]}" in result.output
