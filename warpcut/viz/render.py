"""RGB images of cutting episodes: :class:`TaskRenderer` draws the first envs of a
:class:`~warpcut.task.CuttingTask` as it is now, with Pillow (no matplotlib, no rerun), for the envs'
``render_mode="rgb_array"`` and for videos (:mod:`warpcut.viz.video`).

Each image shows, from a fixed camera (``view``: ``"top"``, straight down, or ``"three-quarter"``, from
the front and above):

* the sheet as its mesh, one polygon per grid cell (a cell touching a cut vertex keeps the triangle that
  does not touch it, or is dropped, so the cut opens as a gap), coloured as the recordings colour it
  (:mod:`warpcut.viz.colours`): by strain (default) or by height, with darker cell edges;
* the intended contour as the sheet carries it (black; bilinear lookup of its points on the deformed
  sheet, as the recordings draw it);
* the scissors' path so far where they cut (red) and the tip (red while cutting, grey while travelling);
* the grasp (a blue ring of the grasp's radius) and its displacement from where it pinched (blue line),
  where the env is grasped;
* the fiducials an env's policy observes, where the task has them (green where seen, grey where hidden, at
  their last seen position);
* the step, top left.

An env whose simulation diverged (non-finite positions) is drawn as a grey image saying so. Drawing costs a
few milliseconds per image (2 to 3 ms at 256 x 256 on the default 25 x 25 sheet, on one CPU core: about two
env steps); nothing is computed until :meth:`TaskRenderer.render` is called.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from warpcut.contours import ring
from warpcut.sim.material import interpolate, material_cells
from warpcut.viz.colours import CUTTING_RGB, HIDDEN_RGB, STRAIN_FULL_SCALE, TRAVEL_RGB, VISIBLE_RGB, ramp_rgba

if TYPE_CHECKING:
    from warpcut.sim.config import SimConfig
    from warpcut.task import CuttingTask

VIEWS = {"top": (0.0, 90.0), "three-quarter": (-25.0, 50.0)}
"""Camera of each view: (azimuth about z, elevation above the sheet's plane), in degrees."""
RENDER_COLOURS = ("strain", "height")
"""What the sheet's colours show (as ``Recorder(colour_by=...)``)."""
SIZE_RANGE = (32, 4096)
"""Allowed image width and height (pixels)."""

BACKGROUND_RGB = (238, 238, 238)
CONTOUR_RGB = (20, 20, 20)
GRASP_RGB = (40, 90, 220)
TEXT_RGB = (30, 30, 30)
_MARGIN = 0.06
"""Empty border around the sheet, as a fraction of the image."""
_HEADROOM_MM = 10.0
"""How far above the sheet's plane the camera's frame reaches (a lifted grasp stays in view)."""


class TaskRenderer:
    """Draws envs ``0 .. envs - 1`` of ``task`` (or the envs listed) as RGB images.

    Args:
        task: The task to draw; the renderer reads it at every :meth:`render` (through resets too).
        envs: How many envs to draw (the first ones), or which.
        size: Image ``width`` (and height) in pixels, or ``(width, height)``.
        view: The camera: ``"top"`` or ``"three-quarter"`` (:data:`VIEWS`).
        colour_by: The sheet's colours: ``"strain"`` or ``"height"`` (:data:`RENDER_COLOURS`).

    Raises:
        ValueError: naming the argument that is out of range.
    """

    def __init__(
        self,
        task: CuttingTask,
        envs: int | Sequence[int] = 1,
        size: int | tuple[int, int] = 256,
        view: str = "top",
        colour_by: str = "strain",
    ):
        self.envs = _env_indices(envs, task.num_envs)
        self.width, self.height = check_render_settings(size, view)
        if colour_by not in RENDER_COLOURS:
            raise ValueError(f"colour_by: choose one of {RENDER_COLOURS} (got {colour_by!r})")
        self.task, self.view, self.colour_by = task, view, colour_by
        self._font = None
        grid, config = task.grid, task.config
        self._read = task.sim.state_reader(self.envs)
        self._quads = _grid_quads(grid.nx, grid.ny)
        settled = task.sim.settled_positions()[self.envs]
        self._height_range = [
            (float(z.min()), max(float(z.max()), float(z.min()) + 1.0)) for z in settled[..., 2]
        ]
        self._camera = _camera(*VIEWS[view])
        box = np.array(
            [[x, y, z] for x in (0, grid.width_mm) for y in (0, grid.height_mm) for z in
             (float(settled[..., 2].min()) - 2.0, _HEADROOM_MM)]
        )  # fmt: skip
        self._fit(box @ self._camera[:2].T)
        spacing = 0.5 * min(grid.spacing_mm)
        self._contours = [
            material_cells(ring(task.contours[e].resample(spacing), task.contours[e].closed)[None], grid)
            for e in self.envs
        ]
        self._trajectories = [task.trajectories[e].tip for e in self.envs]
        self._cut_runs = [_cutting_runs(tip[:, 3] > 0) for tip in self._trajectories]
        self._discs = []
        for e in self.envs:  # the vertices the simulator grasps at a reset (none without a pinch point)
            pinch = task.pinch_points[e]
            grasped = np.isfinite(pinch).all()
            disc = grid.disc_mask(pinch, config.grasp_radius) & ~task.sim.fixture if grasped else None
            self._discs.append(disc if grasped and disc.any() else None)
        self._grasp_origins = [
            None if disc is None else settled[k, disc].mean(axis=0) for k, disc in enumerate(self._discs)
        ]

    def render(self) -> np.ndarray:
        """(n, height, width, 3) uint8 images of the drawn envs as they are now."""
        from PIL import Image, ImageDraw, ImageFont

        if self._font is None:  # a bitmap font: a tenth of the default's cost to draw
            self._font = ImageFont.load_default_imagefont()
        font = self._font
        state = self._read()
        positions, alive = state[..., :3], state[..., 3] != 0.0
        strain = self._strain(positions, alive) if self.colour_by == "strain" else None
        images = np.empty((len(self.envs), self.height, self.width, 3), dtype=np.uint8)
        for k in range(len(self.envs)):
            image = Image.new("RGB", (self.width, self.height), BACKGROUND_RGB)
            draw = ImageDraw.Draw(image)
            if np.all(np.isfinite(positions[k])):
                self._draw_env(draw, k, positions[k], alive[k], None if strain is None else strain[k])
            else:
                draw.text(
                    (self.width * 0.3, self.height * 0.45), "simulation diverged", fill=TEXT_RGB, font=font
                )
            draw.text((4, 2), f"step {self.task.step_index}/{self.task.num_steps}", fill=TEXT_RGB, font=font)
            images[k] = np.asarray(image)
        return images

    # ------------------------------------------------------------------ drawing
    def _fit(self, corners: np.ndarray) -> None:
        """Scale and offset from camera-plane mm to pixels, fitting ``corners`` (M, 2) with a margin."""
        low, high = corners.min(axis=0), corners.max(axis=0)
        span = np.maximum(high - low, 1e-6)
        usable = np.array([self.width, self.height]) * (1 - 2 * _MARGIN)
        self._scale = float(np.min(usable / span))
        centre = (low + high) / 2
        self._offset = np.array([self.width / 2, self.height / 2]) - centre * np.array([1, -1]) * self._scale

    def _pixels(self, points: np.ndarray) -> np.ndarray:
        """(..., 2) pixel coordinates of world points (..., 3); far-flung points clipped near the image."""
        plane = points @ self._camera[:2].T
        pixels = plane * np.array([1.0, -1.0]) * self._scale + self._offset
        limit = 4.0 * max(self.width, self.height)
        return np.clip(pixels, -limit, limit)

    def _strain(self, positions: np.ndarray, alive: np.ndarray) -> np.ndarray:
        from warpcut.viz.colours import vertex_strain

        return vertex_strain(positions, alive, self.task.grid, self.task.config.springs)

    def _draw_env(self, draw, k: int, positions: np.ndarray, alive: np.ndarray, strain) -> None:
        self._draw_sheet(draw, k, positions, alive, strain)
        vertices, weights = self._contours[k]
        contour = interpolate(positions[None].astype(np.float64), vertices, weights)[0]
        draw.line(_points(self._pixels(contour)), fill=CONTOUR_RGB, width=1)
        self._draw_scissors(draw, k)
        disc = self._discs[k]
        if disc is not None:
            origin, grasp = self._pixels(np.stack([self._grasp_origins[k], positions[disc].mean(axis=0)]))
            draw.line(_points(np.stack([origin, grasp])), fill=GRASP_RGB, width=2)
            radius = self._scale * self.task.config.grasp_radius
            x, y = float(grasp[0]), float(grasp[1])
            draw.ellipse((x - radius, y - radius, x + radius, y + radius), outline=GRASP_RGB, width=2)
            _dot(draw, grasp, 3.0, GRASP_RGB)
        self._draw_fiducials(draw, k)

    def _draw_sheet(self, draw, k: int, positions: np.ndarray, alive: np.ndarray, strain) -> None:
        """Every live cell (or its live triangle), far ones first, coloured by strain or height."""
        quads = self._quads
        corners_alive = alive[quads]  # (Q, 4)
        tri_a = corners_alive[:, [0, 1, 2]].all(axis=1)  # v00, v10, v11
        tri_b = corners_alive[:, [0, 2, 3]].all(axis=1)  # v00, v11, v01
        whole = tri_a & tri_b
        faces = [quads[whole], quads[tri_a & ~whole][:, [0, 1, 2]], quads[tri_b & ~whole][:, [0, 2, 3]]]
        if self.colour_by == "strain":
            values = strain
            low, high = 0.0, STRAIN_FULL_SCALE
        else:
            values = positions[:, 2]
            low, high = self._height_range[k]
        depth = positions @ self._camera[2]
        pixels = self._pixels(positions)
        corners, depths, shades = [], [], []
        for face in faces:
            corners += pixels[face].reshape(len(face), 2 * face.shape[1]).tolist()
            depths.append(depth[face].mean(axis=1))
            shades.append(values[face].mean(axis=1))
        packed = ramp_rgba(np.concatenate(shades), low, high)
        fill = np.stack([(packed >> 24) & 0xFF, (packed >> 16) & 0xFF, (packed >> 8) & 0xFF], axis=1)
        fills, edges = fill.tolist(), (fill * 3 // 4).tolist()
        for i in np.argsort(np.concatenate(depths), kind="stable").tolist():  # painter's: far first
            draw.polygon(corners[i], fill=tuple(fills[i]), outline=tuple(edges[i]))

    def _draw_scissors(self, draw, k: int) -> None:
        """The path the scissors cut so far (red) and the tip (red while cutting, grey while travelling)."""
        tip = self._trajectories[k]
        update = self.task.update_index
        current = min(max(update - 1, 0), len(tip) - 1)
        for start, stop in self._cut_runs[k]:
            if start >= update:
                break
            run = tip[start : min(stop, update), :3]
            if len(run) > 1:
                draw.line(_points(self._pixels(run)), fill=CUTTING_RGB, width=2)
        cutting = tip[current, 3] > 0 and update <= len(tip)
        _dot(draw, self._pixels(tip[current, :3]), 3.5, CUTTING_RGB if cutting else TRAVEL_RGB, TEXT_RGB)

    def _draw_fiducials(self, draw, k: int) -> None:
        fiducials = self.task.fiducials
        env = self.envs[k]
        if fiducials is None or fiducials.last_visible.shape[:1] != (self.task.num_envs,):
            return
        seen = fiducials.visible[env]
        for point, visible in zip(self._pixels(fiducials.last_visible[env]), seen, strict=True):
            _dot(draw, point, 2.0, VISIBLE_RGB if visible else HIDDEN_RGB)


# ---------------------------------------------------------------------- helpers
def step_fps(config: SimConfig) -> int:
    """Frames per second at which one frame per env step plays in simulated time (env 0's ``dt``)."""
    dt = float(np.asarray(config.dt, dtype=np.float64).reshape(-1)[0])
    return max(1, round(1.0 / (dt * config.updates_per_step)))


def _env_indices(envs: int | Sequence[int], num_envs: int) -> np.ndarray:
    if isinstance(envs, int | np.integer) and not isinstance(envs, bool):
        if not 1 <= envs <= num_envs:
            raise ValueError(f"envs: draw 1 to {num_envs} envs (the task's batch), got {envs}")
        return np.arange(int(envs))
    indices = np.asarray(envs, dtype=np.int64).reshape(-1)
    if not len(indices) or indices.min() < 0 or indices.max() >= num_envs:
        raise ValueError(f"envs: give env indices in [0, {num_envs}), got {list(envs)}")
    return indices


def check_render_settings(size: int | tuple[int, int], view: str, prefix: str = "") -> tuple[int, int]:
    """``(width, height)`` of an image ``size``; ``ValueError`` naming ``{prefix}size`` or ``{prefix}view``
    where either is out of range."""
    low, high = SIZE_RANGE
    try:
        width, height = (size, size) if isinstance(size, int | np.integer) else tuple(size)
    except (TypeError, ValueError):
        raise ValueError(
            f"{prefix}size: give N or (width, height) in pixels, {low} to {high} (got {size!r})"
        ) from None
    for name, value in (("width", width), ("height", height)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or not low <= value <= high:
            raise ValueError(
                f"{prefix}size: the image {name} must be an integer from {low} to {high} px (got {value!r})"
            )
    if view not in VIEWS:
        raise ValueError(f"{prefix}view: choose one of {tuple(VIEWS)} (got {view!r})")
    return int(width), int(height)


def _camera(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """(3, 3) rows: the image's right and up directions and the direction toward the camera (world)."""
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    right = np.array([math.cos(a), math.sin(a), 0.0])
    back = np.array([-math.sin(a), math.cos(a), 0.0])  # in the sheet's plane, away from the camera
    toward = -back * math.cos(e) + np.array([0.0, 0.0, math.sin(e)])
    up = back * math.sin(e) + np.array([0.0, 0.0, math.cos(e)])
    return np.stack([right, up, toward])


def _grid_quads(nx: int, ny: int) -> np.ndarray:
    """(Q, 4) vertex indices of every grid cell, counter-clockwise: v00, v10, v11, v01."""
    rows, cols = np.meshgrid(np.arange(ny - 1), np.arange(nx - 1), indexing="ij")
    v00 = (rows * nx + cols).ravel()
    return np.stack([v00, v00 + 1, v00 + nx + 1, v00 + nx], axis=1)


def _cutting_runs(cutting: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` update ranges where the trajectory cuts."""
    edges = np.diff(np.concatenate([[0], cutting.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(), strict=True))


def _points(pixels: np.ndarray) -> list[float]:
    return pixels.reshape(-1).tolist()


def _dot(draw, centre: np.ndarray, radius: float, fill, outline=None) -> None:
    x, y = float(centre[0]), float(centre[1])
    draw.ellipse((x - radius, y - radius, x + radius, y + radius), fill=fill, outline=outline)


def display_available() -> bool:
    """Whether a window can open: on Linux and the BSDs, ``DISPLAY`` or ``WAYLAND_DISPLAY`` is set."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def check_human_rendering() -> None:
    """``ValueError`` naming ``render_mode`` unless a :class:`Window` can open here: a display, and an
    interactive matplotlib backend."""
    hint = "use render_mode='rgb_array' (e.g. with gymnasium.wrappers.RecordVideo) instead"
    if not display_available():
        raise ValueError(
            f"render_mode: 'human' needs a display, and there is none (DISPLAY and WAYLAND_DISPLAY are "
            f"unset); {hint}"
        )
    import matplotlib

    backend = matplotlib.get_backend().lower()
    if backend in NON_INTERACTIVE_BACKENDS or backend.startswith("module://matplotlib_inline"):
        raise ValueError(
            f"render_mode: 'human' needs an interactive matplotlib backend, and {backend!r} is not one "
            f"(install tkinter or PyQt, or set MPLBACKEND); {hint}"
        )


NON_INTERACTIVE_BACKENDS = ("agg", "cairo", "pdf", "pgf", "ps", "svg", "template")


class Window:
    """A matplotlib window showing one image at a time (``render_mode="human"``).

    Raises:
        ValueError: :func:`check_human_rendering`'s.
    """

    def __init__(self, title: str = "warpcut"):
        check_human_rendering()
        import matplotlib.pyplot as plt

        self._plt = plt
        plt.ion()
        self.figure, axes = plt.subplots(num=title)
        axes.set_axis_off()
        self._axes, self._image = axes, None

    def show(self, image: np.ndarray, fps: float) -> None:
        """Show ``image`` (H, W, 3) and wait ``1 / fps`` s for the window to draw it."""
        if self._image is None:
            self._image = self._axes.imshow(image)
        else:
            self._image.set_data(image)
        self.figure.canvas.draw_idle()
        self._plt.pause(1.0 / fps)

    def close(self) -> None:
        self._plt.close(self.figure)
