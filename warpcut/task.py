"""The cutting task over a batch: settled sheets, open-loop scissor trajectories, grasps, scoring.

:class:`CuttingTask` is what the Gymnasium envs, the baseline tensioners and the CLI drive. One *step*
is one tensioning action followed by ``updates_per_step`` simulator updates, each advancing every
scissor tip by ``trajectory_spacing_mm`` along its trajectory.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
import shapely

from warpcut.contours import Contour, check_resolution, ring
from warpcut.scoring import Score, score_cut
from warpcut.sim.checks import DIVERGENCE_REASONS, checked_pinch_points
from warpcut.sim.config import SimConfig, SimulationDiverged
from warpcut.sim.devices import resolve_device
from warpcut.sim.material import interpolate, interpolate_corners, material_cells, material_to_world
from warpcut.sim.memory import check_batch_memory
from warpcut.sim.simulator import BACKENDS, NOISE_SEEDS, Simulator
from warpcut.trajectory import (
    MAX_TRAJECTORY_STRETCH,
    Trajectory,
    checked_segments,
    default_segments,
    estimate_horizon,
    segments_key,
)
from warpcut.validation import check_choice, check_flag, check_instance, check_integer, check_text, fail

if TYPE_CHECKING:
    from warpcut.fiducials import Fiducials
    from warpcut.planning.feasibility import ArmModel

__all__ = [
    "CuttingTask",
    "SimulationDiverged",
    "interpolate",
    "material_cells",
    "material_to_world",
]


StepCallback = Callable[["CuttingTask", "np.ndarray | None"], None]
"""``on_step(task, moves)``: called after a task's reset (moves None) and after every step with the (B, 3)
grasp moves (mm), e.g. to record or plot a rollout."""


class CuttingTask:
    """B sheets being cut, each along its own contour's trajectory, each with its own grasp.

    Args:
        config: Simulation parameters.
        contours: One contour for every env, or one per env.
        num_envs: Batch size, >= 1; default ``len(contours)`` (1 for a single contour).
        pinch_points: (B, 2) or (2,) material coordinates of the pinch point (mm), finite; a row of
            NaN in a (B, 2) array, or ``None`` for all: no grasp (the no-tension case). Anything else not
            finite (an inf, a half-NaN row, a NaN (2,) point) is a ``ValueError``.
        segments: Per env, the material polylines cut in order; default :func:`default_segments`.
        device: Warp device.
        seed: Process-noise seed.
        backend: Simulator backend (``auto``, ``simd`` or ``colours``; see :class:`Simulator`).
        threads: CPU threads stepping the batch (default: all cores).
        trace_path: Trace the cut path (:meth:`Simulator.trace_path`) for the path score; without it
            :meth:`score` has only the separated-material score (its path fields are NaN), a little faster.
        arm: The cutting arm whose footprint a pinch point must avoid
            (:class:`~warpcut.planning.ArmModel`; default: the paper's, along the whole sheet).
        allow_infeasible_pinch: Run pinch points the gripper could not hold (on or near the cut line, under
            the cutting arm, ...: :func:`warpcut.planning.pinch_problems`) instead of refusing them
            (:class:`~warpcut.planning.InfeasiblePinch`, a ``ValueError`` naming the rule);
            :attr:`pinch_problems` says which envs they are, for their results to say so.

    Every argument is checked first (:mod:`warpcut.validation`): a wrong type or value is a
    :class:`~warpcut.validation.ConfigError` naming ``CuttingTask.<argument>``. A batch that would not fit in
    memory is refused before anything is allocated (``ValueError`` naming
    ``num_envs``; :mod:`warpcut.sim.memory`); so is a sheet that does not settle (:class:`SimulationDiverged`,
    naming the parameters to change). An env that diverges during the cut (:meth:`diverged`) is scored
    NaN (:meth:`score`).
    """

    def __init__(
        self,
        config: SimConfig,
        contours: Contour | Sequence[Contour],
        num_envs: int | None = None,
        pinch_points: np.ndarray | None = None,
        segments: Sequence[Sequence[np.ndarray]] | None = None,
        device: str | None = None,
        seed: int = 0,
        backend: str = "auto",
        threads: int | None = None,
        trace_path: bool = True,
        arm: ArmModel | None = None,
        allow_infeasible_pinch: bool = False,
    ):
        from warpcut.planning.feasibility import ArmModel, InfeasiblePinch, pinch_problems_per_env

        check_instance("CuttingTask.config", config, SimConfig, "a SimConfig")
        num_envs = check_integer("CuttingTask.num_envs", num_envs, 1, optional=True, note="one per contour")
        if isinstance(contours, Contour):
            contours = [contours] * (num_envs or 1)
        many = isinstance(contours, list | tuple) and contours
        if not (many and all(isinstance(c, Contour) for c in contours)):
            fail(
                "CuttingTask.contours",
                "a Contour (load_contour(...)), or a list of them, one per env",
                contours,
            )
        contours = list(contours)
        num_envs = num_envs or len(contours)
        if len(contours) != num_envs:
            raise ValueError(
                f"CuttingTask.contours: got {len(contours)} for {num_envs} envs; give one or one per env"
            )
        seed = check_integer("CuttingTask.seed", seed, 0, NOISE_SEEDS - 1)
        check_text("CuttingTask.device", device, optional=True, note="the default device")
        backend = check_choice("CuttingTask.backend", backend, BACKENDS)
        threads = check_integer("CuttingTask.threads", threads, 1, optional=True, note="one per core")
        check_flag("CuttingTask.trace_path", trace_path)
        check_flag("CuttingTask.allow_infeasible_pinch", allow_infeasible_pinch)
        if arm is not None:
            check_instance("CuttingTask.arm", arm, ArmModel, "an ArmModel, or None for the default arm")
        config = config.validated()
        if not trace_path and config.score == "path":
            raise ValueError(
                "trace_path: the path score needs the traced path; keep trace_path=True or score='separated'"
            )
        try:
            device = resolve_device(device)
        except ValueError as exc:
            raise ValueError(f"CuttingTask.{exc}") from None
        segments = checked_segments(segments)
        self.segments = (
            [list(s) for s in segments] if segments is not None else [default_segments(c) for c in contours]
        )
        if len(self.segments) != num_envs:
            raise ValueError(f"CuttingTask.segments: got {len(self.segments)} lists for {num_envs} envs")
        estimate = estimate_horizon(contours, segments, config)
        self._longest_updates = estimate_horizon(contours, segments, config, margin=MAX_TRAJECTORY_STRETCH)
        """The updates beyond which a trajectory is stretched like no gauze (:data:`MAX_TRAJECTORY_STRETCH`):
        refused, on every sheet the task lays its trajectories out on."""
        check_batch_memory(num_envs, config.nx * config.ny, estimate, device=device)
        for contour in {id(c): c for c in contours}.values():
            check_resolution(contour, config.spacing_mm)  # a contour the grid cannot resolve: refused
        # The grasps, judged before any sheet is settled: a refusal costs nothing.
        self.pinch_points = checked_pinch_points(pinch_points, num_envs, config.width_mm, config.height_mm)
        self.pinch_problems = pinch_problems_per_env(self.pinch_points, contours, self.segments, config, arm)
        """Per env, why its pinch point is not a feasible grasp (one line naming the rule), or None: feasible,
        or no grasp. Only ``allow_infeasible_pinch`` lets one through."""
        first = next((env for env, problem in enumerate(self.pinch_problems) if problem), None)
        if first is not None and not allow_infeasible_pinch:
            raise InfeasiblePinch(self.pinch_points[first], contours[first], self.pinch_problems[first])
        self.sim = Simulator.checked(config, num_envs, device, seed, backend, threads)
        self.config, self.grid, self.num_envs = self.sim.config, self.sim.grid, num_envs
        self.contours = contours
        self._trajectory_cache: dict[tuple, Trajectory] = {}
        self._arc_cache: dict[tuple[int, int], np.ndarray] = {}
        self._trace = trace_path
        self._lay_out_trajectories()
        self.update_index = 0
        self.fiducials: Fiducials | None = None
        """The fiducials a camera tracks on the sheets, where an env observes them (it sets them here):
        recordings show them, and draw their own where this is None."""

    def _lay_out_trajectories(self) -> None:
        """Build each env's trajectory on its settled sheet, and the per-update tips and targets."""
        num_envs = self.num_envs
        self.trajectories = self._build_trajectories()
        self.trajectory_updates = np.array([len(t.tip) for t in self.trajectories])
        """(B,) updates of each env's own trajectory (the batch runs for the longest:
        :attr:`horizon_updates`)."""
        self.horizon_updates = int(self.trajectory_updates.max())
        if self.horizon_updates > self._longest_updates:
            p = self.sim.params
            raise SimulationDiverged(
                f"simulation diverged while settling the sheet: the scissors' path over it is "
                f"{self.horizon_updates} updates, more than {MAX_TRAJECTORY_STRETCH:g} times the contour's "
                f"length; the springs do not hold it (gravity {p['gravity'].max():g} mm/s^2, dt "
                f"{p['dt'].max():g} s): lower gravity or dt, or raise sweeps"
            )
        self._tips = np.zeros((num_envs, self.horizon_updates, 4), dtype=np.float32)
        self._targets = np.full((num_envs, self.horizon_updates, 2), np.nan)
        for env, trajectory in enumerate(self.trajectories):
            t = len(trajectory.tip)
            self._tips[env, :t] = trajectory.tip
            self._tips[env, t:, :3] = trajectory.tip[-1, :3]  # parked, not cutting, once done
            self._targets[env, :t] = trajectory.material
        self._targets.flags.writeable = False
        # What every update's target needs, once per layout (read every step: target_world, cut_deviation).
        self._target_finite = np.all(np.isfinite(self._targets), axis=2)
        vertices, weights = material_cells(np.nan_to_num(self._targets), self.grid)  # (B, horizon, 4) each
        self._target_cells = (vertices.astype(np.int32), weights)
        self._arc_mm = self._compute_target_arcs()
        if self._trace:
            self.sim.trace_path(self.horizon_updates)

    def set_params(self, **values) -> None:
        """Change physical parameters (``damping``, ``dt``, ``gravity``, ``elasticity``, ``noise_std``; one
        value or one per env) before the next :meth:`reset`: :meth:`Simulator.set_params`. A parameter
        that shapes the settled sheet lays the trajectories out again on it (open loop on the sheet as it
        hangs), so :attr:`num_steps` may change. Settled sheets and trajectories of parameters seen before
        are reused (domain randomisation draws from a finite set of levels for that reason)."""
        from warpcut.sim.settling import SETTLE_PARAMETERS

        self.sim.set_params(**values)
        self.config = self.sim.config
        if set(values) & set(SETTLE_PARAMETERS):  # each env's own sheet (kept trajectories make it cheap)
            self._lay_out_trajectories()
        self.update_index = self.num_steps * self.config.updates_per_step  # over: reset() next

    @property
    def num_steps(self) -> int:
        """Env steps in an episode: enough updates for the longest trajectory."""
        return math.ceil(self.horizon_updates / self.config.updates_per_step)

    @property
    def step_index(self) -> int:
        return self.update_index // self.config.updates_per_step

    @property
    def done(self) -> bool:
        return self.update_index >= self.num_steps * self.config.updates_per_step

    def _build_trajectories(self) -> list[Trajectory]:
        settled = self.sim.settled_positions()
        group_params, env_group = self.sim.settle_groups()
        # Envs sharing a settled sheet and segments share a trajectory: build each once, and keep it for
        # parameters that come back (set_params).
        cache = self._trajectory_cache
        if len(cache) > 4 * self.num_envs + 64:
            cache.clear()
            self._arc_cache.clear()
        trajectories = []
        for env in range(self.num_envs):
            key = (group_params[env_group[env]].tobytes(), segments_key(self.segments[env]))
            if key not in cache:
                cache[key] = Trajectory.from_segments(
                    self.segments[env], settled[env], self.grid, self.config.trajectory_spacing_mm
                )
            trajectories.append(cache[key])
        return trajectories

    def target_arcs(self) -> np.ndarray:
        """(B, horizon) arc length along each env's contour of the point each update meant to cut (NaN
        while travelling or parked): the order in which the cut path is closed (read-only)."""
        return self._arc_mm

    def target_points(self) -> np.ndarray:
        """(B, horizon, 2) the material point each update meant to cut (NaN while travelling or parked):
        what the cut path is compared with (read-only)."""
        return self._targets

    def _compute_target_arcs(self) -> np.ndarray:
        arcs = np.full(self._targets.shape[:2], np.nan)
        cache = self._arc_cache  # kept with the trajectories (their ids are stable while they are kept)
        for env, (contour, trajectory) in enumerate(zip(self.contours, self.trajectories, strict=True)):
            key = (id(contour), id(trajectory))
            if key not in cache:
                points = np.asarray(contour.points)
                line = shapely.LineString(ring(points, contour.closed))
                material = trajectory.material
                finite = np.all(np.isfinite(material), axis=1)
                arc = np.full(len(material), np.nan)
                arc[finite] = shapely.line_locate_point(line, shapely.points(material[finite]))
                cache[key] = arc
            arcs[env, : len(trajectory.material)] = cache[key]
        return arcs

    def reset(self, seed: int | None = None) -> None:
        """Settled, uncut sheets; grasps at the pinch points; scissors at their trajectories' starts.

        Args:
            seed: New process-noise seed (default: keep the current one).
        """
        if seed is not None:
            self.sim.seed = int(seed)
        self.sim.reset(self.pinch_points)
        self.update_index = 0

    def step(self, action: np.ndarray | None = None) -> None:
        """Move the grasps by ``action`` (B, 3) mm (clipped), then advance the scissors one step."""
        if self.done:
            raise RuntimeError("step: the episode is over; call reset() first")
        if action is not None:
            self.sim.move_grasp(action)
        for _ in range(self.config.updates_per_step):
            self.sim.set_tip(self.tip_positions())
            self.sim.update()
            self.update_index += 1

    def tip_positions(self, update_index: int | None = None) -> np.ndarray:
        """(B, 4) scissor tips ``(x, y, z, cutting)`` for an update (default: the next one). Past the end
        of its trajectory a tip stays parked at its last point and does not cut."""
        u = self.update_index if update_index is None else update_index
        tip = self._tips[:, min(u, self.horizon_updates - 1)].copy()
        if u >= self.horizon_updates:
            tip[:, 3] = 0.0
        return tip

    def target_world(self) -> np.ndarray:
        """(B, 3) current world position of the material point each tip is about to cut (NaN when
        travelling or finished): the contour as the sheet has moved it."""
        t = min(self.update_index, self.horizon_updates - 1)
        active = self._target_finite[:, t] & (self.update_index < self.horizon_updates)
        vertices, weights = self._target_cells
        corners = self.sim.gather(vertices[:, t])[:, None, :, :3]  # (B, 1, 4, 3): the cells' corners only
        world = interpolate_corners(corners, weights[:, t : t + 1])[:, 0]
        return np.where(active[:, None], world, np.nan)

    def lookahead(self, offsets: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
        """What lies ahead of the scissors, ``offsets`` (K,) updates after the next one (ints >= 0):
        ``(tips, targets)``, the planned tips (B, K, 4) (:meth:`tip_positions` of those updates: x, y, z,
        cutting) and the world positions (B, K, 3) of the material points they mean to cut, as the sheet
        lies now (:meth:`target_world` of those updates; NaN where the tip travels or is done)."""
        u = self.update_index + np.asarray(offsets, dtype=np.int64)
        t = np.minimum(u, self.horizon_updates - 1)
        tips = self._tips[:, t].copy()
        tips[:, u >= self.horizon_updates, 3] = 0.0
        active = self._target_finite[:, t] & (u < self.horizon_updates)[None, :]
        vertices, weights = self._target_cells
        b, k = self.num_envs, len(t)
        corners = self.sim.gather(vertices[:, t].reshape(b, k * 4)).reshape(b, k, 4, 4)[..., :3]
        world = interpolate_corners(corners, weights[:, t])
        return tips, np.where(active[..., None], world, np.nan)

    def tracking_error(self) -> np.ndarray:
        """(B, 3) ``target_world() - tip`` (mm) for the next update: where the contour point about to be cut
        lies from the scissor tip (what the analytic controller opposes); NaN while travelling or done."""
        return self.target_world() - self.tip_positions()[:, :3]

    def cut_path(self) -> np.ndarray | None:
        """(B, T, 3) the tips traced so far (:attr:`Simulator.path`): material x, y and status per update;
        None when the path is not traced."""
        return None if self.sim.path is None else self.sim.path.numpy()

    def cut_deviation(self, first_update: int, stop_update: int) -> tuple[np.ndarray, np.ndarray]:
        """Distance in material coordinates between where the scissors cut and where they meant to cut,
        over updates ``first_update .. stop_update - 1``: the path score's own increment.

        Returns:
            ``(mean_mm, count)``: (B,) mean distance over the mapped cutting updates (NaN where none) and
            (B,) how many there were.
        """
        if self.sim.path is None:
            raise RuntimeError("cut_deviation: the cut path is not traced (CuttingTask(trace_path=False))")
        stop_update = min(stop_update, self.horizon_updates)
        if stop_update <= first_update:
            return np.full(self.num_envs, np.nan), np.zeros(self.num_envs, dtype=np.int64)
        path = self.sim.path[:, first_update:stop_update].numpy()  # on a GPU only this slice is copied
        target = self._targets[:, first_update:stop_update]
        mapped = (path[..., 2] > 0.5) & self._target_finite[:, first_update:stop_update]
        offset = np.where(mapped[..., None], path[..., :2] - target, 0.0)
        # np.linalg.norm over the last axis, written out: the same values, bit for bit, without its overhead.
        distance = np.sqrt(offset[..., 0] * offset[..., 0] + offset[..., 1] * offset[..., 1])
        count = mapped.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(count > 0, distance.sum(axis=1) / count, np.nan)
        return mean, count

    def diverged(self) -> np.ndarray:
        """(B,) bool: envs whose simulation diverged since the reset (non-finite or runaway vertices;
        :meth:`Simulator.diverged`). Their score is NaN."""
        return self.sim.diverged()

    def divergence_reasons(self) -> list[str | None]:
        """Per env, why it diverged in words (e.g. ``"non-finite vertex positions"``), or None."""
        return [DIVERGENCE_REASONS.get(int(code)) for code in self.sim.divergence()]

    def score(self) -> Score:
        """Each env's error under both scores (:mod:`warpcut.scoring`); ``error_*`` follows
        ``config.score``. An env that diverged (:meth:`diverged`) is not scored: its errors and
        ``dropped_fraction`` are NaN, ``separated`` False and ``Score.diverged`` True."""
        diverged = self.diverged()
        paths, alive = self.cut_path(), self.sim.alive_mask()
        if diverged.any():  # score what is left as an idle, uncut sheet, then blank it
            if paths is not None:
                paths = paths.copy()  # on the CPU, a view of the simulator's own path
                paths[diverged] = (0.0, 0.0, -1.0)  # kernels.PATH_IDLE
            alive[diverged] = True
        score = score_cut(self.config.score, paths, self._arc_mm, alive, self.contours, self.grid)
        return score.mark_diverged(diverged)

    def run(self, policy, on_step: StepCallback | None = None) -> Score:
        """Reset, then step ``policy(task) -> (B, 3)`` (or ``None`` for no moves) to the end; score.

        Args:
            policy: Maps the task to (B, 3) grasp moves in mm, or returns ``None``; ``None``: no moves.
            on_step: Called as ``on_step(task, action)`` after the reset (action ``None``) and after every
                step, e.g. to record the episode; costs nothing when ``None``.
        """
        self.reset()
        if on_step is not None:
            on_step(self, None)
        while not self.done:
            action = policy(self) if policy is not None else None
            self.step(action)
            if on_step is not None:
                on_step(self, action)
        return self.score()


RELATIVE_REWARD_MAX_SCALE = 10.0
"""The largest factor a relative weighting scales an episode by (and 1 / it the smallest;
:meth:`NoTensionReference.scale`): a sheet that hangs flat has almost no no-tension error, and an unbounded
scale would let its episodes swamp the rest."""


class NoTensionReference:
    """No-tension errors, noise-free, cut once per (settle parameters, contour, segments) and kept: the
    reference that weighs each randomised sheet as much as the nominal one (the env's ``relative_reward``,
    the es estimator's ``es_randomize``)."""

    def __init__(self) -> None:
        self._errors: dict[tuple, float] = {}

    def scale(self, task: CuttingTask, nominal: SimConfig) -> np.ndarray:
        """(B,) the ``nominal`` sheet's no-tension error over that of each env's own sheet in ``task`` (as
        its parameters stand), clipped to ``[1 / RELATIVE_REWARD_MAX_SCALE, RELATIVE_REWARD_MAX_SCALE]``.
        Errors not met before are cut in one batch."""
        own_error, base_error = self.errors(task, nominal)
        scale = base_error / np.maximum(own_error, 1e-9)
        return np.clip(
            np.nan_to_num(scale, nan=1.0), 1.0 / RELATIVE_REWARD_MAX_SCALE, RELATIVE_REWARD_MAX_SCALE
        )

    def errors(self, task: CuttingTask, nominal: SimConfig) -> tuple[np.ndarray, np.ndarray]:
        """(B,) each env's no-tension error (mm^2, noise-free) on its own sheet in ``task`` (as its
        parameters stand) and on the ``nominal`` sheet, for its contour and segments. Errors not met before
        are cut in one batch."""
        from warpcut.sim.settling import SETTLE_PARAMETERS

        b = task.num_envs
        group_params, env_group = task.sim.settle_groups()
        own = group_params[env_group]
        base = np.stack([np.broadcast_to(nominal.per_env(k, b), (b,)) for k in SETTLE_PARAMETERS], axis=1)

        def key(row: np.ndarray, env: int) -> tuple:
            return row.astype(np.float32).tobytes(), id(task.contours[env]), segments_key(task.segments[env])

        missing: dict[tuple, tuple[np.ndarray, int]] = {}
        for env in range(b):
            for row in (own[env], base[env]):
                if key(row, env) not in self._errors:
                    missing.setdefault(key(row, env), (row, env))
        if missing:
            rows = np.array([row for row, _ in missing.values()])
            envs = [env for _, env in missing.values()]
            params = {k: rows[:, c].tolist() for c, k in enumerate(SETTLE_PARAMETERS)}
            probe = CuttingTask(
                nominal.replace(**params, noise_std=0.0), [task.contours[e] for e in envs],
                segments=[task.segments[e] for e in envs], device=task.sim.device,
            )  # fmt: skip
            errors = probe.run(None).error_mm2
            self._errors.update({k: float(err) for k, err in zip(missing, errors, strict=True)})
        own_error = np.array([self._errors[key(own[e], e)] for e in range(b)])
        base_error = np.array([self._errors[key(base[e], e)] for e in range(b)])
        return own_error, base_error


def divergence_error(
    contours: Sequence[Contour], diverged: np.ndarray, config: SimConfig, reasons: Sequence[str] = ()
) -> SimulationDiverged:
    """The error of a run whose (num_contours, trials) ``diverged`` trials are not all False: how many
    diverged per contour, why (``reasons``), and what to change."""
    counts = [
        f"{int(row.sum())} of {row.size} trials of {contour.name}"
        for contour, row in zip(contours, diverged, strict=True)
        if row.any()
    ]
    why = f" ({', '.join(reasons)})" if reasons else ""
    noise, gravity, dt = (float(np.max(getattr(config, k))) for k in ("noise_std", "gravity", "dt"))
    return SimulationDiverged(
        f"simulation diverged in {', '.join(counts)}{why}; their errors are not numbers: lower noise_std "
        f"(now {noise:g} mm per update), gravity ({gravity:g} mm/s^2) or dt ({dt:g} s), or raise sweeps"
    )
