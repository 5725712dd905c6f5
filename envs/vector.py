"""The pattern-cutting env natively batched: one :class:`~warpcut.task.CuttingTask` of B sheets.

All B envs share one episode clock, so every episode ends on the same step. How the batch restarts is
``autoreset_mode`` (https://farama.org/Vector-Autoreset-Mode), ``metadata["autoreset_mode"]``:

``AutoresetMode.NEXT_STEP`` (the default, as Gymnasium's own vector envs):
    the ending step returns the final observations, with the score in its ``info`` (each key with its
    ``_key`` mask); the next ``step`` ignores its actions, resets every env and returns the first
    observations, zero rewards and no ``terminated`` / ``truncated``. Gymnasium's vector observation
    wrappers (``gymnasium.wrappers.vector.NormalizeObservation``, ``TransformObservation``,
    ``DtypeObservation``, ``FlattenObservation``, ...) need it: they refuse SAME_STEP. It costs one extra
    ``step`` call per episode, the reset that SAME_STEP does inside the ending step anyway: the same
    simulation work (``tests/test_gym_conventions.py`` counts it; timed, the seconds per episode of a 64-env
    fls-circle batch are the same within the noise).
``AutoresetMode.SAME_STEP``:
    the env resets all envs at once inside the ending ``step`` and returns the new episodes' first
    observations. The ending step's observations and score are in ``info["final_obs"]`` (an object array
    of B observations) and ``info["final_info"]`` (a dict of (B,) arrays), each with its ``"_final_obs"`` /
    ``"_final_info"`` mask (all True). What rsl-rl (:mod:`envs.rsl`) and Stable-Baselines3 (:mod:`envs.sb3`)
    expect, resets inside ``step``: their adapters are built on it.
``AutoresetMode.DISABLED``:
    as NEXT_STEP, but a ``step`` after the episode's end raises ``RuntimeError``: call ``reset()``.

Every step's info has the per-step ``cut_deviation_mm`` and ``running_path_error_mm2`` of :mod:`envs.core`
(of the episode that the step ended, where it ended one), with their masks.

An env whose simulation diverges (:mod:`envs.core`, "Divergence") is terminated at that step on its own:
``terminated[env]`` is True and its observation zero; with SAME_STEP ``info["final_obs"][env]`` is that
observation and ``info["final_info"]`` holds ``diverged`` (with ``_final_info``, ``_final_obs`` and
``_diverged`` True for the envs that ended there); it has no score. It cannot restart before the others (one
clock), so until the batch's episode ends it idles: zero observations, zero rewards, its actions ignored; at
the batch's end it is reset with the others, its ``terminated`` True (also where the batch's episode is
truncated: it ended when it diverged, so nothing is to be bootstrapped) but (SAME_STEP) its ``_final_obs``
and ``_final_info`` False, or (NEXT_STEP, DISABLED) its score masks False: nothing more to report. An env
that diverges on the step that truncates the batch is likewise terminated, not truncated. Every step's
info has ``diverged`` (with its mask) once an env has diverged.

Resets take Gymnasium's forms: ``seed`` is an int, None, or a list of B ints (or of B Nones). The batch has
one random stream (process noise and fiducials, which differ from env to env), so a list seeds the batch as
a whole: ``[s, s + 1, ..., s + B - 1]`` (what a ``SyncVectorEnv`` makes of ``seed=s``) is the same as
``seed=s``, any other list a batch seed derived from all of it (the same list, the same episodes; env k of
that batch is not the single env seeded with list[k]). ``options={"reset_mask": mask}`` with a (B,) bool
``mask`` resets every env where it is all True and nothing where it is all False; a partial mask is accepted
only where each env it names has already ended (diverged: it idles, and restarts with the batch), and then
resets nothing; any other partial mask is a ``ValueError`` (the envs cannot restart one by one). No other
reset options exist.

Rendering: ``render_mode="rgb_array"`` makes :meth:`PatternCutVecEnv.render` return a tuple of images, one
per env of the first ``render_envs`` (default: all B, Gymnasium's convention, which its vector
``RecordVideo`` needs), each (H, W, 3) uint8 as :class:`~envs.pattern_cut.PatternCutEnv` draws it, a few ms
per env; without a render mode nothing is drawn and nothing is spent.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from warpcut.task import CuttingTask
from warpcut.validation import check_integer

from .core import PatternCut, check_part, check_reset_options
from .options import PatternCutOptions
from .pattern_cut import check_render_mode, step_fps

VECTOR_RENDER_MODES = ["rgb_array"]


class PatternCutVecEnv(VectorEnv):
    """B sheets cut at once (see :mod:`envs.core` for observations, actions and rewards).

    Args:
        num_envs: Batch size B.
        options: The scenario; keyword arguments (any :class:`~envs.options.PatternCutOptions` field)
            replace its fields. Per-env lists (contours, physical parameters, pinch points) have length B.
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` (default), ``SAME_STEP`` or ``DISABLED``, or its value
            (``"NextStep"``, ...) or name (``"same_step"``, ...); module docstring.
        render_mode: ``None`` or ``"rgb_array"`` (module docstring).
        render_envs: How many envs :meth:`render` draws, the first ones; default all.
        render_size: Rendered image size in pixels: ``N`` (square) or ``(width, height)``.
        render_view: The rendering camera, ``"top"`` or ``"three-quarter"``.
        part: ``(first, total)``: these envs are envs ``first ..`` of a batch of ``total`` and cut as those
            would (:class:`envs.core.PatternCut`; ``options`` theirs, :meth:`PatternCutOptions.part`): a batch
            split over processes, each stepping a part.

    ``reset(seed=..., options=...)`` takes Gymnasium's forms (module docstring). Actions are (B,) indices
    (discrete) or (B, A) moves (continuous).
    """

    metadata = {
        "autoreset_mode": AutoresetMode.NEXT_STEP,
        "render_modes": VECTOR_RENDER_MODES,
        "render_fps": 31,
    }

    def __init__(
        self,
        num_envs: int = 1,
        options: PatternCutOptions | None = None,
        *,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        render_mode: str | None = None,
        render_envs: int | None = None,
        render_size: int | tuple[int, int] = 256,
        render_view: str = "top",
        part: tuple[int, int] | None = None,
        **kwargs: Any,
    ):
        num_envs = check_integer("PatternCutVecEnv.num_envs", num_envs, 1)
        self.autoreset_mode = _autoreset_mode(autoreset_mode)
        check_render_mode(render_mode, VECTOR_RENDER_MODES)
        render_envs = check_integer(
            "PatternCutVecEnv.render_envs", render_envs, 1, optional=True, note="all envs"
        )
        if render_mode is not None:
            from warpcut.viz.render import check_render_settings

            check_render_settings(render_size, render_view, prefix="render_")
        self.options = PatternCutOptions.build(options, **kwargs)  # its fields checked as it is built
        self.num_envs = num_envs
        part = check_part(part, num_envs)
        self.scene = PatternCut.checked(self.options, num_envs, part)
        self.single_observation_space = self.scene.observation_space
        self.single_action_space = self.scene.action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.metadata = {
            **type(self).metadata,
            "autoreset_mode": self.autoreset_mode,
            "render_modes": list(VECTOR_RENDER_MODES),
            "render_fps": step_fps(self.options),
        }
        self.render_mode = render_mode
        self.render_envs = num_envs if render_envs is None else min(int(render_envs), num_envs)
        self._render_args = {"size": render_size, "view": render_view}
        self._renderer = None
        self._started = False
        self._over = False
        """The batch's episode ended (NEXT_STEP: the next step resets; DISABLED: reset() must)."""
        self._ended = np.zeros(num_envs, dtype=bool)
        self._obs: np.ndarray | None = None
        self.common_sheets = 1
        """With randomised parameters, the batch is this many copies of ``num_envs / common_sheets`` sheets
        (:meth:`envs.core.PatternCut.reset`'s ``repeat``); takes effect at the next reset."""
        self._start: dict | None = None

    @property
    def task(self) -> CuttingTask:
        """The underlying :class:`~warpcut.task.CuttingTask` of B envs."""
        return self.scene.task

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every env (or, with ``options["reset_mask"]``, as the module docstring says); a ``seed``
        also redraws the fiducials."""
        options = check_reset_options(options, allowed=("reset_mask",))
        seed = batch_seed(seed, self.num_envs)
        if "reset_mask" in options and not self._resets_all(options["reset_mask"]):
            if seed is not None:
                raise ValueError(
                    "reset: options['reset_mask'] resets no env here, so the seed would be dropped; reset "
                    "every env to seed the batch (a mask of all True, or no options)"
                )
            return self._obs, {}
        super().reset(seed=seed)
        self._started, self._over = True, False
        self._ended[:] = False
        self._obs = self._reset_scene(seed is not None or self.options.resample_fiducials)
        info = self.scene.pinch_info()  # each env's pinch point's feasibility, Gymnasium's masks beside
        return self._obs, info | {f"_{k}": np.ones(self.num_envs, dtype=bool) for k in info}

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every env; at the episode's end, reset them as ``autoreset_mode`` says (module docstring)."""
        if not self._started:
            raise RuntimeError("step: call reset() first")
        if self._over:
            if self.autoreset_mode is AutoresetMode.NEXT_STEP:
                return self._reset_step()
            raise RuntimeError("step: the episode is over and autoreset_mode is DISABLED; call reset() first")
        obs, rewards, terminated, truncated, info = self.scene.step(actions)
        b = self.num_envs
        every_env = np.ones(b, dtype=bool)
        step_keys = [k for k in ("cut_deviation_mm", "running_path_error_mm2", "diverged") if k in info]
        infos: dict[str, Any] = {k: info[k] for k in step_keys}
        infos.update({f"_{k}": every_env for k in step_keys})
        ended, cut_short = np.full(b, terminated), np.full(b, truncated)
        same_step = self.autoreset_mode is AutoresetMode.SAME_STEP
        if truncated:  # an env that diverged, now or before, ended then: terminated, nothing to bootstrap
            gone = self._ended | self.scene.newly_diverged
            ended, cut_short = gone.copy(), ~gone
        if terminated or truncated:
            ending = ~self._ended  # envs that ended earlier (diverged) have nothing more to report
            if same_step:
                final_info = {**info, **{f"_{k}": ending.copy() for k in info}}
                infos |= self._final(obs, ending, final_info)
                obs = self._reset_scene(self.options.resample_fiducials)
                self._ended[:] = False
            else:  # the score in this step's info; the next step (NEXT_STEP) or reset() restarts
                score_keys = [k for k in info if k not in step_keys]
                infos |= {k: info[k] for k in score_keys} | {f"_{k}": ending.copy() for k in score_keys}
                self._ended[:] = True
                self._over = True
        elif self.scene.newly_diverged.any():
            newly = self.scene.newly_diverged.copy()
            ended |= newly
            self._ended |= newly
            if same_step:
                infos |= self._final(obs, newly, {"diverged": info["diverged"], "_diverged": newly.copy()})
        self._obs = obs
        return obs, rewards, ended, cut_short, infos

    def render(self) -> tuple[np.ndarray, ...] | None:
        """Images of the first ``render_envs`` envs as they are now, each (H, W, 3) uint8, in
        ``render_mode="rgb_array"``; without a render mode, a warning and None."""
        if self.render_mode is None:
            gym.logger.warn(
                "render: the vector env was made without a render_mode; make it with render_mode='rgb_array'"
            )
            return None
        if self._renderer is None:  # built at the first render: no cost without rendering
            from warpcut.viz.render import TaskRenderer

            self._renderer = TaskRenderer(self.task, envs=self.render_envs, **self._render_args)
        return tuple(self._renderer.render())

    def _reset_step(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """NEXT_STEP's step after the episode's end: every env restarts, its action ignored."""
        b = self.num_envs
        self._obs = self._reset_scene(self.options.resample_fiducials)
        self._ended[:] = False
        self._over = False
        none = np.zeros(b, dtype=bool)
        return self._obs, np.zeros(b), none, none.copy(), {}

    def _reset_scene(self, resample_fiducials: bool) -> np.ndarray:
        """Start a new episode in every env, remembering how (:meth:`episode_start`)."""
        self._start = {
            "rng": self.np_random.bit_generator.state,
            "resample_fiducials": bool(resample_fiducials),
            "common_sheets": int(self.common_sheets),
        }
        return self.scene.reset(self.np_random, resample_fiducials, repeat=self.common_sheets)

    def episode_start(self) -> dict:
        """How the current episode began: the random stream's state before its reset, whether it drew new
        fiducials, and ``common_sheets`` (JSON-able; :meth:`restart_episode` takes it)."""
        if self._start is None:
            raise RuntimeError("episode_start: call reset() first")
        return dict(self._start)

    def restart_episode(self, start: dict) -> np.ndarray:
        """Start again, in every env, the episode that :meth:`episode_start` described: the same process
        noise, randomised sheets and (where it drew them) fiducials, for an env with the same options whose
        first reset had the same seed. Returns the first observations."""
        if not self._started:
            raise RuntimeError("restart_episode: call reset() first")
        try:
            self.np_random.bit_generator.state = start["rng"]
            self.common_sheets = int(start["common_sheets"])
            resample = bool(start["resample_fiducials"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"restart_episode: not an episode_start() record ({exc})") from None
        self._over = False
        self._ended[:] = False
        self._obs = self._reset_scene(resample)
        return self._obs

    def _resets_all(self, mask: Any) -> bool:
        """Whether ``options["reset_mask"]`` resets every env (True) or none (False); ``ValueError`` for a
        mask the one episode clock cannot honour (module docstring)."""
        mask = np.asarray(mask)
        if mask.shape != (self.num_envs,) or mask.dtype != bool:
            raise ValueError(
                f"reset: options['reset_mask'] must be a ({self.num_envs},) bool array, one flag per env "
                f"(got {mask.dtype} {mask.shape})"
            )
        if mask.all():
            return True
        if not self._started:
            raise ValueError("reset: the first reset resets every env; leave out options['reset_mask']")
        alive = mask & ~self._ended
        if alive.any():
            raise ValueError(
                f"reset: options['reset_mask'] names envs {np.flatnonzero(alive).tolist()} whose episode "
                "has not ended, but not every env; the envs share one episode clock and restart together: "
                "reset all of them (a mask of all True, or no options)"
            )
        return False

    @staticmethod
    def _final(obs: np.ndarray, ending: np.ndarray, final_info: dict[str, Any]) -> dict[str, Any]:
        """The same-step autoreset entries of the envs ``ending`` (B,) bool (module docstring)."""
        final_obs = np.empty(len(obs), dtype=object)
        for env in range(len(obs)):
            final_obs[env] = obs[env]
        return {
            "final_obs": final_obs,
            "_final_obs": ending.copy(),
            "final_info": final_info,
            "_final_info": ending.copy(),
        }


def batch_seed(seed: Any, num_envs: int) -> int | None:
    """The batch's one seed for a Gymnasium ``reset(seed=...)``: None, an int, or a list of ``num_envs``
    ints (or all None); ``ValueError`` naming ``seed`` otherwise (module docstring)."""
    if seed is None:
        return None
    if isinstance(seed, int | np.integer) and not isinstance(seed, bool):
        return int(seed)
    form = f"an int, a list of {num_envs} ints (one per env) or None"
    if isinstance(seed, str | bytes | bool | float) or not hasattr(seed, "__len__"):
        raise ValueError(f"reset: seed must be {form} (got {seed!r})")
    seeds = list(seed)
    if len(seeds) != num_envs:
        raise ValueError(f"reset: seed lists {len(seeds)} seeds for {num_envs} envs; give {form}")
    if all(s is None for s in seeds):
        return None
    if any(isinstance(s, bool) or not isinstance(s, int | np.integer) or s < 0 for s in seeds):
        raise ValueError(
            f"reset: seed {seeds} mixes non-negative ints with other values; give an int for every env, or "
            "None for all: the batch has one random stream"
        )
    seeds = [int(s) for s in seeds]
    if seeds == list(range(seeds[0], seeds[0] + num_envs)):
        return seeds[0]
    return int(np.random.SeedSequence(seeds).generate_state(1)[0])


def _autoreset_mode(mode: AutoresetMode | str) -> AutoresetMode:
    if isinstance(mode, AutoresetMode):
        return mode
    for candidate in AutoresetMode:
        if isinstance(mode, str) and mode.replace("-", "_").lower() in (
            candidate.value.lower(),
            candidate.name.lower(),
        ):
            return candidate
    names = ", ".join(f"AutoresetMode.{m.name}" for m in AutoresetMode)
    raise ValueError(f"autoreset_mode: choose one of {names} (or their values), got {mode!r}")
