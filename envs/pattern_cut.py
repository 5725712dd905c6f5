"""One sheet as a ``gymnasium.Env`` (:class:`PatternCutEnv`); the contract (observations, actions, rewards,
episodes) is :mod:`envs.core`'s, the natively batched env is :class:`envs.vector.PatternCutVecEnv`.

Rendering (``render_mode``):
    ``None`` (default): nothing is drawn and rendering costs nothing. ``"rgb_array"``: :meth:`render`
    returns the sheet as it is now, a (H, W, 3) uint8 image (:class:`warpcut.viz.render.TaskRenderer`:
    the mesh coloured by strain, the contour as the sheet carries it, the cut so far, the scissor tip, the
    grasp and the fiducials), 2 to 3 ms per 256 x 256 frame on one CPU core; it works with
    ``gymnasium.wrappers.RecordVideo`` (which needs ``moviepy``), at ``metadata["render_fps"]``, the
    simulated time of a step (one second of video is one simulated second). ``"human"``: the same
    image in a matplotlib window after every reset and step, where a display is available; without one
    (no ``DISPLAY`` or ``WAYLAND_DISPLAY`` on Linux) or without an interactive matplotlib backend the env
    refuses it with a ``ValueError``. The class's ``metadata["render_modes"]`` lists both (so that
    ``gym.make(..., render_mode="human")`` reaches the env and gets that error); an instance's lists
    ``"human"`` only where a display is available (what ``gymnasium.utils.env_checker.check_env`` tries).
    ``render_size`` (pixels, default 256) and ``render_view`` (``"top"`` or ``"three-quarter"``) choose
    the image.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from warpcut.task import CuttingTask

from .core import PatternCut, reject_reset_options
from .options import PatternCutOptions

RENDER_MODES = ["human", "rgb_array"]
"""The render modes of the envs (:class:`envs.vector.PatternCutVecEnv`: ``"rgb_array"`` only)."""


def step_fps(options: PatternCutOptions) -> int:
    """Frames per second at which a video of one frame per step plays in simulated time (env 0's ``dt``)."""
    from warpcut.viz.render import step_fps as fps

    return fps(options.config())


def check_render_mode(render_mode: str | None, modes: list[str]) -> None:
    """``ValueError`` naming ``render_mode`` unless it is None or one of ``modes``."""
    if render_mode is not None and render_mode not in modes:
        raise ValueError(f"render_mode: choose one of {modes} or None (got {render_mode!r})")


class PatternCutEnv(gym.Env):
    """One sheet being cut while the policy tensions it; see :mod:`envs.core` for the contract and
    :class:`PatternCutOptions` (every field is a keyword argument).

    Args:
        options: The scenario; keyword arguments replace its fields.
        render_mode: ``None``, ``"rgb_array"`` or ``"human"`` (module docstring).
        render_size: Rendered image size in pixels: ``N`` (square) or ``(width, height)``.
        render_view: The rendering camera, ``"top"`` or ``"three-quarter"``.
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": 31}

    def __init__(
        self,
        options: PatternCutOptions | None = None,
        render_mode: str | None = None,
        render_size: int | tuple[int, int] = 256,
        render_view: str = "top",
        **kwargs: Any,
    ):
        check_render_mode(render_mode, RENDER_MODES)
        self.options = PatternCutOptions.build(options, **kwargs)
        self.render_mode = render_mode
        self._render_args = {"size": render_size, "view": render_view}
        self._renderer = None
        self._window = None
        if render_mode is not None:  # fail here, before the sheet is built, not at the first render
            from warpcut.viz import render

            render.check_render_settings(render_size, render_view, prefix="render_")
            if render_mode == "human":
                render.check_human_rendering()
        self.scene = PatternCut(self.options, num_envs=1)
        self.observation_space = self.scene.observation_space
        self.action_space = self.scene.action_space
        from warpcut.viz.render import display_available

        # What env checkers may try here: "human" only where a window can open (module docstring).
        usable = list(RENDER_MODES) if display_available() else ["rgb_array"]
        self.metadata = {**type(self).metadata, "render_modes": usable, "render_fps": step_fps(self.options)}
        if render_mode == "human":
            from warpcut.viz.render import Window

            self._window = Window("warpcut/PatternCut")

    @property
    def task(self) -> CuttingTask:
        """The underlying one-env :class:`~warpcut.task.CuttingTask`."""
        return self.scene.task

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Settled, uncut sheet; the grasp at the pinch point. A ``seed`` also redraws the fiducials.
        There are no reset ``options``."""
        super().reset(seed=seed)
        reject_reset_options(options)
        obs = self.scene.reset(self.np_random, seed is not None or self.options.resample_fiducials)
        if self._window is not None:
            self._show()
        return obs[0], _first(self.scene.pinch_info())  # the pinch point's feasibility

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Move the grasp by ``action`` and advance the scissors one step (:mod:`envs.core`). A simulation
        that diverges ends the episode: ``terminated``, ``info["diverged"]`` True, a NaN score and a zero
        observation and reward."""
        obs, rewards, terminated, truncated, info = self.scene.step(np.asarray(action)[None])
        scalars = _first(info)
        if self._window is not None:
            self._show()
        return obs[0], float(rewards[0]), terminated, truncated, scalars

    def render(self) -> np.ndarray | None:
        """The sheet as it is now, (H, W, 3) uint8, in ``render_mode="rgb_array"``; ``"human"`` shows it
        in the window instead (and returns None); without a render mode, a warning and None."""
        if self.render_mode is None:
            gym.logger.warn(
                "render: the env was made without a render_mode; make it with render_mode='rgb_array', e.g. "
                'gym.make("warpcut/PatternCut-v0", render_mode="rgb_array")'
            )
            return None
        if self.render_mode == "human":
            self._show()
            return None
        return self._frame()

    def close(self) -> None:
        if self._window is not None:
            self._window.close()
            self._window = None
        super().close()

    def _frame(self) -> np.ndarray:
        if self._renderer is None:  # built at the first render: no cost without rendering
            from warpcut.viz.render import TaskRenderer

            self._renderer = TaskRenderer(self.task, envs=1, **self._render_args)
        return self._renderer.render()[0]

    def _show(self) -> None:
        self._window.show(self._frame(), self.metadata["render_fps"])


def _first(info: dict) -> dict:
    """The first env's entry of each of a batch's infos, as Python values (bools stay bools, counts ints,
    texts str)."""
    first = {k: np.asarray(v)[0] for k, v in info.items()}
    return {k: v.item() if isinstance(v, np.generic) else v for k, v in first.items()}
