"""The sheet as a triangle mesh file (GLB, OBJ or PLY, through trimesh), at any step of a cut: for Blender,
MeshLab, a slicer or a paper figure rendered elsewhere.

:func:`sheet_mesh` builds the mesh of one env as it stands: its vertices where the simulation has them (mm,
z up) and the triangles of the grid whose three vertices the scissors left (the same triangles a recording
draws); vertices no live triangle uses are left out. Vertex colours show the strain or the height on the
recordings' ramp (:mod:`warpcut.viz.colours`). :func:`export_mesh` writes it; :class:`MeshExports` is a
step callback that writes each method's sheet when its episode ends, or every k steps.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from warpcut.io import WriteFailed, safe_name, write_atomic
from warpcut.viz.colours import COLOUR_FIELDS, STRAIN_FULL_SCALE, ramp_rgba, vertex_strain

MESH_FORMATS = ("glb", "obj", "ply")
"""The file types :func:`export_mesh` writes, by suffix."""


def sheet_mesh(task, env: int = 0, colour_by: str | None = "strain"):
    """Env ``env`` of ``task``'s sheet as it stands, as a ``trimesh.Trimesh`` (mm, z up).

    Args:
        task: A :class:`~warpcut.task.CuttingTask` (or anything with its ``sim``, ``grid`` and ``config``).
        env: The env, in ``[0, task.num_envs)``.
        colour_by: Vertex colours: ``"strain"`` (0 to :data:`~warpcut.viz.colours.STRAIN_FULL_SCALE`),
            ``"height"`` (the sheet's lowest to highest vertex) or None (none).

    Returns:
        The mesh: the grid's live triangles, counter-clockwise seen from above at rest, over the vertices
        they use (in grid order); ``metadata["grid_vertices"]`` gives each vertex's index on the grid.

    Raises:
        ValueError: ``env`` is out of range or ``colour_by`` unknown, naming the field.
    """
    import trimesh

    from warpcut.viz.rerun_writer import grid_triangles

    num_envs = task.sim.num_envs
    if not isinstance(env, int | np.integer) or isinstance(env, bool) or not 0 <= env < num_envs:
        raise ValueError(f"env: must be an integer in [0, {num_envs}) (got {env!r})")
    if colour_by is not None and colour_by not in COLOUR_FIELDS:
        raise ValueError(f"colour_by: must be one of {', '.join(COLOUR_FIELDS)} or None (got {colour_by!r})")
    positions, alive = task.sim.read_envs([int(env)])
    triangles = grid_triangles(task.grid)
    live = triangles[alive[0][triangles].all(axis=1)]
    used = np.unique(live)
    index = np.full(task.grid.num_vertices, -1, dtype=np.int64)
    index[used] = np.arange(len(used))
    colours = None
    if colour_by == "strain":
        strain = vertex_strain(positions, alive, task.grid, task.config.springs)[0]
        colours = _rgba_bytes(ramp_rgba(strain[used], 0.0, STRAIN_FULL_SCALE))
    elif colour_by == "height":
        z = positions[0, used, 2]
        low = float(z.min()) if len(z) else 0.0
        colours = _rgba_bytes(ramp_rgba(z, low, max(float(z.max()), low + 1.0) if len(z) else 1.0))
    mesh = trimesh.Trimesh(
        vertices=positions[0, used].astype(np.float64),
        faces=index[live].reshape(-1, 3),
        vertex_colors=colours,
        process=False,
    )
    mesh.units = "mm"
    mesh.metadata["grid_vertices"] = used
    return mesh


def export_mesh(task, path: str | os.PathLike, env: int = 0, colour_by: str | None = "strain") -> Path:
    """Write :func:`sheet_mesh` of ``task``'s env ``env`` to ``path`` (atomically), its type by suffix:
    ``.glb`` (binary glTF; vertex colours), ``.obj`` (vertex colours as ``v x y z r g b``) or ``.ply``
    (binary; vertex colours). Coordinates are mm, z up.

    Returns:
        ``path``.

    Raises:
        ValueError: an unknown suffix, a bad ``env`` or ``colour_by``, ``path`` is a directory, or the disk
            is full (the message names the file).
    """
    path = Path(path)
    kind = path.suffix.lower().lstrip(".")
    if kind not in MESH_FORMATS:
        raise ValueError(
            f"path: {str(path)!r} is not a mesh file type; end it in "
            f"{', '.join('.' + f for f in MESH_FORMATS)}"
        )
    data = sheet_mesh(task, env, colour_by).export(file_type=kind)
    try:
        return write_atomic(path, data)
    except WriteFailed as exc:
        raise ValueError(
            f"{exc.path}: not written, {exc.reason}; {exc.fix}, then export again"
        ) from exc.__cause__


class MeshExports:
    """Step callbacks that write the sheet of the first ``envs`` of a batch as mesh files
    ``out_dir/METHOD_env{E}_step{S}.{fmt}``: when the episode ends, and every ``every`` steps if given.

    Args:
        out_dir: Where the files go.
        envs: How many envs (the first ones) to export, >= 1.
        every: Also export every this many steps (and step 0); None: only the last step.
        formats: File types (:data:`MESH_FORMATS`).
        colour_by: As :func:`sheet_mesh`.
    """

    def __init__(
        self,
        out_dir: str | os.PathLike,
        envs: int = 1,
        every: int | None = None,
        formats: Sequence[str] = ("glb",),
        colour_by: str | None = "strain",
    ):
        if not isinstance(envs, int) or isinstance(envs, bool) or envs < 1:
            raise ValueError(f"envs: must be a positive integer (got {envs!r})")
        if every is not None and (not isinstance(every, int) or isinstance(every, bool) or every < 1):
            raise ValueError(f"every: must be a positive integer or None (got {every!r})")
        unknown = [f for f in formats if f not in MESH_FORMATS]
        if unknown or not formats:
            raise ValueError(f"formats: give some of {', '.join(MESH_FORMATS)} (got {list(formats)!r})")
        if colour_by is not None and colour_by not in COLOUR_FIELDS:
            raise ValueError(
                f"colour_by: must be one of {', '.join(COLOUR_FIELDS)} or None (got {colour_by!r})"
            )
        self.out_dir, self.envs, self.every = Path(out_dir), envs, every
        self.formats, self.colour_by = tuple(formats), colour_by
        self.written: list[Path] = []
        """Every file written, in order."""

    def step_callback(self, method: str):
        """A new step callback, for ``task.run(policy, on_step=exports.step_callback(method))``."""

        def callback(task, action) -> None:
            step = task.step_index
            if task.done or (self.every is not None and step % self.every == 0):
                self.export(task, method)

        return callback

    def export(self, task, method: str) -> list[Path]:
        """Write the first envs of ``task`` as they stand, as ``method``'s sheets; returns the paths."""
        paths = []
        for env in range(min(self.envs, task.sim.num_envs)):
            stem = f"{safe_name(method)}_env{env}_step{task.step_index}"
            for kind in self.formats:
                paths.append(export_mesh(task, self.out_dir / f"{stem}.{kind}", env, self.colour_by))
        self.written += paths
        return paths


def _rgba_bytes(packed: np.ndarray) -> np.ndarray:
    """Packed ``0xRRGGBBAA`` (uint32) colours as (N, 4) uint8."""
    packed = np.asarray(packed, dtype=np.uint32)
    return np.stack([(packed >> shift) & 0xFF for shift in (24, 16, 8, 0)], axis=-1).astype(np.uint8)
