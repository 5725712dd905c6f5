"""A batch of gauze sheets stepped by Warp kernels.

One :class:`Simulator` holds ``num_envs`` independent sheets of the same resolution. Each env may have
its own physical parameters (see :class:`~warpcut.sim.config.SimConfig`), its own grasp (pinch point) and
its own scissor tip. One *update* is: integrate, relax every spring colour ``sweeps`` times, cut.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor, wait

import numpy as np

from warpcut.cores import cpu_cores
from warpcut.sim import kernels
from warpcut.sim._warp import LaunchRecords, launch, wp
from warpcut.sim.checks import DIVERGENCE_REASONS, check_pinch_points
from warpcut.sim.config import PHYSICAL_PARAMETERS, SheetGrid, SimConfig, SimulationDiverged
from warpcut.sim.devices import resolve_device
from warpcut.sim.memory import check_batch_memory
from warpcut.sim.reads import StateReads
from warpcut.sim.settling import SETTLE_PARAMETERS, SettledSheets
from warpcut.sim.simd import SimdModel, SimdState
from warpcut.sim.springs import spring_colours
from warpcut.sim.tracing import PathTracing
from warpcut.validation import check_choice, check_flag, check_instance, check_integer, check_text

__all__ = [
    "DIVERGENCE_REASONS",
    "SimulationDiverged",
    "Simulator",
    "check_pinch_points",
]

NOISE_SEEDS = 2_147_483_647
"""How many distinct noise seeds there are: the noise kernels key each update's stream on the seed modulo
this prime (an int32), so seed ``s + NOISE_SEEDS`` would replay seed ``s``'s noise bit for bit; a seed is
one of ``0 .. NOISE_SEEDS - 1``."""

BACKENDS = ("auto", "simd", "colours")


class Simulator(StateReads, PathTracing):
    """``num_envs`` sheets on one device.

    Args:
        config: The simulation parameters (validated here).
        num_envs: Batch size B.
        device: ``cpu``, ``cuda`` or ``cuda:N``; default: :func:`default_device`.
        seed: Seed of the process noise (the only randomness in the physics).
        backend: ``simd`` (CPU only: one launch per update, one thread per block of 8 envs stepped in
            lockstep in SIMD lanes, :mod:`warpcut.sim.kernels_simd`), ``colours`` (one launch per stage and
            spring colour, one thread per vertex: suits GPUs and is the differentiable path), or ``auto``
            (simd on CPU, colours on CUDA). Both give bit-identical results; ``update(tape_mode=True)``
            always uses ``colours``.
        threads: CPU threads that step disjoint slices of the batch's blocks (``simd``; ``colours`` runs
            on one); default: the number of cores, at most the number of blocks. ``wp.launch`` releases
            the GIL.
        capture: Record the ``colours`` update (its ~2 + sweeps x colours launches) once into a Warp
            graph (``wp.ScopedCapture``) and replay it, which removes the per-launch overhead; a graph is
            kept per arrangement of the ping-pong buffers (at most 6). Default: on for ``colours`` on CUDA,
            off elsewhere. Works on CPU too (same results bit for bit). Updates with ``tape_mode``, or
            while a displacement array of the caller's is plugged in, are launched one by one.

    Every update also watches each env for divergence: a vertex with a non-finite coordinate, or one
    beyond :attr:`SimConfig.runaway_bounds` (flung far from the sheet). :meth:`diverged` says which envs
    did since the last reset, :meth:`divergence` why; a settled sheet that diverged (or hangs more than
    :data:`~warpcut.sim.config.SETTLED_REACH_SHEETS` sheet sizes from its rest outline) raises
    :class:`SimulationDiverged`. A batch that would not fit in memory is refused before it is allocated
    (:func:`warpcut.sim.memory.check_batch_memory`).
    """

    def __init__(
        self,
        config: SimConfig,
        num_envs: int,
        device: str | None = None,
        seed: int = 0,
        backend: str = "auto",
        threads: int | None = None,
        capture: bool | None = None,
    ):
        check_instance("Simulator.config", config, SimConfig, "a SimConfig")
        num_envs = check_integer("Simulator.num_envs", num_envs, 1)
        check_text("Simulator.device", device, optional=True, note="the default device")
        backend = check_choice("Simulator.backend", backend, BACKENDS)
        threads = check_integer("Simulator.threads", threads, 1, optional=True, note="one per core")
        if capture is not None:
            check_flag("Simulator.capture", capture)
        config = config.validated()
        device = resolve_device(device)
        check_batch_memory(num_envs, config.nx * config.ny, device=device)
        self._build(config, num_envs, device, _checked_seed(seed), backend, threads, capture)

    @classmethod
    def checked(
        cls, config: SimConfig, num_envs: int, device: str, seed: int, backend: str, threads: int | None
    ) -> Simulator:
        """A simulator of arguments checked already, as :class:`~warpcut.task.CuttingTask` checks its own
        (a validated config, a resolved device, a batch whose memory was checked with its episode)."""
        sim: Simulator = cls.__new__(cls)
        sim._build(config, num_envs, device, seed, backend, threads, None)
        return sim

    def _build(
        self,
        config: SimConfig,
        num_envs: int,
        device: str,
        seed: int,
        backend: str,
        threads: int | None,
        capture: bool | None,
    ) -> None:
        """Allocate the batch from checked arguments (:meth:`checked`)."""
        self.config, self.num_envs, self.device = config, num_envs, device
        self._seed_base = wp.zeros(1, dtype=wp.int32, device=self.device)
        self._set_seed(seed)
        self.grid = SheetGrid.from_config(self.config)
        self.colours = spring_colours(self.config.springs)
        self.params = {name: self.config.per_env(name, num_envs) for name in PHYSICAL_PARAMETERS}
        self._wp_params = {k: wp.array(v, dtype=float, device=self.device) for k, v in self.params.items()}
        self.fixture = self.grid.fixture_mask(self.config.fixture)
        self.update_count = 0
        self._settled: np.ndarray | None = None
        self._settle_cache = SettledSheets(Simulator)  # what set_params brings back is not settled again
        n = self.grid.num_vertices * num_envs
        self._buffers = [wp.zeros(n, dtype=wp.vec3, device=self.device) for _ in range(3)]
        self._alive = [wp.zeros(n, dtype=wp.int32, device=self.device) for _ in range(2)]
        self.pin = wp.zeros(n, dtype=wp.int32, device=self.device)
        self.anchor = wp.zeros(n, dtype=wp.vec3, device=self.device)
        self.displacement = wp.zeros(num_envs, dtype=wp.vec3, device=self.device)
        self.tip = wp.zeros(num_envs, dtype=wp.vec4, device=self.device)
        self._action = wp.zeros(num_envs, dtype=wp.vec3, device=self.device)
        self._displacement_own = self.displacement
        # The update count on the device: the colours path reads its noise seed from it (graph replays).
        self._update_counter = wp.zeros(1, dtype=wp.int32, device=self.device)
        self._status = wp.zeros((2, num_envs), dtype=wp.int32, device=self.device)
        """Divergence flags since the last reset: row 0 non-finite, row 1 beyond the bounds (set by the
        cut stage of every update, ``kernels.cut_kernel``)."""
        lower, upper = self.config.runaway_bounds
        self._lower, self._upper = wp.vec3(*lower), wp.vec3(*upper)
        self._counter_synced = True
        self._graphs: dict[tuple, tuple] = {}
        self._host_views: dict[int, np.ndarray] = {}
        self._first_noise_stream = 0
        self.path: wp.array | None = None
        """(B, T) ``vec3`` while tracing (:meth:`trace_path`): per update, the tip in material coordinates and
        its status (``kernels.PATH_MAPPED``, ``PATH_DROPPED``, ``PATH_IDLE``)."""
        self._removed_at: wp.array | None = None
        self._search: kernels.TipSearch | None = None
        self.grasped = np.zeros(num_envs, dtype=bool)
        self.x, self.x_prev, self._spare = self._buffers
        self.alive = self._alive[0]
        is_cpu = self._is_cpu = wp.get_device(self.device).is_cpu
        self.backend = ("simd" if is_cpu else "colours") if backend == "auto" else backend
        if self.backend == "simd" and not is_cpu:
            raise ValueError(f"backend: 'simd' runs on the CPU only; use 'colours' on {self.device}")
        self._simd: SimdState | None = None
        chebyshev = self.config.chebyshev_rho > 0
        colours_chebyshev = chebyshev and self.backend == "colours"
        self._older = [
            wp.zeros(n, dtype=wp.vec3, device=self.device) if colours_chebyshev else None for _ in range(2)
        ]
        """The colours path's positions two sweeps back, by parity (Chebyshev sweeps only)."""
        # Which copy of the state is current: the env-major arrays (``x``...) and/or the SIMD blocks.
        self._flat_current, self._packed_current = True, False
        blocks = 1
        if self.backend == "simd":
            self._simd_model = SimdModel.from_config(self.config, self.grid, self.device)
            self._simd = SimdState(num_envs, self.grid.num_vertices, device=self.device, chebyshev=chebyshev)
            blocks = self._simd.blocks
        if capture is None:
            capture = self.backend == "colours" and not is_cpu
        if capture and self.backend != "colours":
            raise ValueError(
                f"capture: graph capture applies to the 'colours' backend (got backend {self.backend!r}); "
                "pass backend='colours' or capture=False"
            )
        self.capture = bool(capture)
        self.threads = max(1, min(threads or cpu_cores(), blocks))
        self._slices = [(len(c), int(c[0])) for c in np.array_split(np.arange(blocks), self.threads)]
        # The calling thread steps the first slice itself; the pool's threads step the others (a handoff
        # and a wake-up fewer per update than a pool of one thread per slice).
        self._pool = ThreadPoolExecutor(self.threads - 1) if self.threads > 1 else None
        self._launches = LaunchRecords()  # replayed: the grasp moves, the simd update's tip tracing per slice

    @property
    def first_noise_stream(self) -> int:
        """The noise stream env 0 draws; env ``e`` draws stream ``first_noise_stream + e`` (default 0). A
        batch that sets it to ``k`` sees the same noise as envs ``k, k + 1, ...`` of another batch with the
        same seed: paired trials across batches laid out differently (``agents.policies.policy_errors``)."""
        return self._first_noise_stream

    @first_noise_stream.setter
    def first_noise_stream(self, value: int) -> None:
        if not isinstance(value, int | np.integer) or value < 0:
            raise ValueError(f"first_noise_stream: must be a non-negative integer (got {value!r})")
        self._first_noise_stream = int(value)
        self._graphs.clear()  # captured updates hold the old value

    @property
    def seed(self) -> int:
        """Seed of the process noise; may be changed between episodes (``CuttingTask.reset(seed=...)``)."""
        return self._seed

    @seed.setter
    def seed(self, value: int) -> None:
        self._set_seed(_checked_seed(value))

    def _set_seed(self, value: int) -> None:
        self._seed = value
        # The colours path (and its captured graphs) reads the seed from device memory.
        self._seed_base.assign(np.array([self._noise_seed_base()], dtype=np.int32))

    # ------------------------------------------------------------------ settling
    def settle_groups(self) -> tuple[np.ndarray, np.ndarray]:
        """Envs that share physical parameters share a settled sheet.

        Returns:
            ``(group_params, env_group)``: (G, 4) parameters of each distinct sheet and (B,) group index.
        """
        columns = [np.broadcast_to(self.params[k], (self.num_envs,)) for k in SETTLE_PARAMETERS]
        table = np.stack(columns, axis=1)
        group_params, env_group = np.unique(table, axis=0, return_inverse=True)
        return group_params, env_group.reshape(-1)

    def settled_positions(self) -> np.ndarray:
        """(B, N, 3) sheet positions after ``settle_updates`` under gravity, without grasp or scissors.

        Each distinct parameter set is settled once, noise-free, and copied to every env that shares it;
        settled sheets are kept, so parameters that come back (:meth:`set_params`) are not settled again.
        """
        if self._settled is None:
            group_params, env_group = self.settle_groups()
            self._settled = self._settle_cache.sheets(self.config, group_params, self.device)[env_group]
        return self._settled

    def set_params(self, **values) -> None:
        """Change physical parameters between episodes; they apply from the next :meth:`reset`.

        Args:
            **values: Any of ``damping``, ``dt``, ``gravity``, ``elasticity``, ``noise_std``: one value for
                every env or one per env, validated as :class:`SimConfig` validates them (domain
                randomisation: :class:`envs.options.PatternCutOptions` ``randomize``).

        Raises:
            ValueError: an unknown parameter; :class:`~warpcut.sim.config.ConfigError` for a bad value.
        """
        unknown = sorted(set(values) - set(PHYSICAL_PARAMETERS))
        if unknown:
            choices = ", ".join(PHYSICAL_PARAMETERS)
            raise ValueError(f"set_params: unknown {', '.join(unknown)}; choose from {choices}")
        self.config = self.config.replace(**values).validated()
        for name in values:
            new = self.config.per_env(name, self.num_envs)
            if new.shape == self.params[name].shape:
                self._wp_params[name].assign(new)  # in place: recorded graphs keep reading it
            else:
                self._wp_params[name] = wp.array(new, dtype=float, device=self.device)
                self._graphs.clear()
            self.params[name] = new
        if set(values) & set(SETTLE_PARAMETERS):
            self._settled = None
        self._sync_flat()
        self._packed_current = False  # the SIMD blocks re-pack the parameters (and the state)

    # ------------------------------------------------------------------ episode
    def reset_flat(self) -> None:
        """Put every sheet flat at rest (z = 0), uncut, held only by the fixture."""
        rest = np.zeros((self.num_envs, self.grid.num_vertices, 3), dtype=np.float32)
        rest[:, :, :2] = self.grid.material
        self._load(rest, pinch_points=None)

    def reset(self, pinch_points: np.ndarray | None = None) -> None:
        """Start a cut: settled sheets, uncut; grasp the disc around each env's pinch point.

        Args:
            pinch_points: (B, 2) material coordinates (mm) of each env's pinch point; a row of NaN (or
                ``None`` for all) means that env is not grasped; any other non-finite value is a
                ``ValueError`` (:func:`check_pinch_points`).
        """
        self._load(self.settled_positions(), pinch_points)

    def _load(self, positions: np.ndarray, pinch_points: np.ndarray | None) -> None:
        b, n = self.num_envs, self.grid.num_vertices
        pin = np.broadcast_to(self.fixture.astype(np.int32) * kernels.PIN_FIXTURE, (b, n)).copy()
        self.grasped = np.zeros(b, dtype=bool)
        if pinch_points is not None:
            pinch_points = np.asarray(pinch_points, dtype=np.float64).reshape(-1, 2)
            if pinch_points.shape[0] != b:
                raise ValueError(f"pinch_points: expected shape ({b}, 2), got {pinch_points.shape}")
            check_pinch_points(pinch_points)
            discs: dict[bytes, np.ndarray] = {}  # by pinch point: a batch mostly shares a few
            for env, point in enumerate(pinch_points):
                if np.all(np.isfinite(point)):
                    disc = discs.get(point.tobytes())
                    if disc is None:
                        disc = self.grid.disc_mask(point, self.config.grasp_radius) & ~self.fixture
                        discs[point.tobytes()] = disc
                    pin[env, disc] = kernels.PIN_GRASP
                    self.grasped[env] = bool(disc.any())
        flat = positions.reshape(-1, 3).astype(np.float32)
        # Back to the simulator's own arrays (a taped update leaves fresh ones in their place; a caller may
        # have plugged in a displacement array of its own).
        self.x, self.x_prev, self._spare = self._buffers
        self.alive = self._alive[0]
        self.displacement = self._displacement_own
        for buffer in (self.x, self.x_prev):
            buffer.assign(flat)
        self.anchor.assign(flat)
        self.pin.assign(pin.reshape(-1))
        self.alive.fill_(1)
        self.displacement.zero_()
        self.tip.zero_()
        if self.path is not None:
            self._removed_at.fill_(-1)
            self.path.fill_(wp.vec3(0.0, 0.0, kernels.PATH_IDLE))
        self.update_count = 0
        self._update_counter.zero_()
        self._status.zero_()
        self._counter_synced = True
        self._flat_current, self._packed_current = True, False

    # ------------------------------------------------------------------ stepping
    def move_grasp(self, action: np.ndarray) -> None:
        """Move each env's grasp by ``action`` (B, 3) mm: clipped to ``max_step_mm`` per axis, and the
        total displacement to ``max_displacement_mm``. Envs without a grasp ignore it."""
        action = np.asarray(action, dtype=np.float32).reshape(self.num_envs, 3)
        if not np.all(np.isfinite(action)):
            raise ValueError("action: contains NaN or infinite values; give finite moves in mm")
        self._upload(self._action, np.where(self.grasped[:, None], action, 0.0))
        # In place (a captured update graph keeps reading the same array; each thread reads and writes
        # only its env's entry), unless the displacement is being differentiated: then a new array, so
        # that wp.Tape keeps the history.
        taped = self.displacement.requires_grad
        out = wp.empty_like(self.displacement) if taped else self.displacement
        (launch if taped else self._launches["move_grasp"])(  # a replay is not on the tape
            kernels.move_grasp_kernel,
            dim=self.num_envs,
            inputs=[
                self.config.max_step_mm,
                self.config.max_displacement_mm,
                self.displacement,
                self._action,
            ],
            outputs=[out],
            device=self.device,
        )
        self.displacement = out

    def set_tip(self, tip: np.ndarray) -> None:
        """Scissor tips for the next updates: (B, 4) ``(x, y, z, cutting)`` in world mm."""
        self._upload(self.tip, np.asarray(tip, dtype=np.float32).reshape(self.num_envs, 4))

    def _upload(self, array: wp.array, values: np.ndarray) -> None:
        """``array.assign(values)``; on the CPU through a zero-copy view kept per array (what an env step
        uploads every update: a view's copy costs microseconds, ``assign`` ~0.1 ms of Python)."""
        if not self._is_cpu:
            array.assign(values)
            return
        view = self._host_views.get(id(array))
        if view is None:
            view = self._host_views[id(array)] = array.numpy()
        view[...] = values

    def update(self, tape_mode: bool = False) -> None:
        """One update of every env: integrate, ``sweeps`` relaxation sweeps, cut at the tip.

        Args:
            tape_mode: Allocate fresh output arrays for every kernel so that the whole history stays
                available to ``wp.Tape`` (slower, uses memory per update).
        """
        if self.backend == "simd" and not tape_mode:
            self._update_simd()
            self._counter_synced = False
        else:
            self._sync_flat()
            if not self._counter_synced:
                self.sync_update_counter()
            if self.capture and not tape_mode and self._own_arrays():
                self._update_captured()
            else:
                self._update_colours(tape_mode)
            if self._tracing() and not tape_mode:
                self._map_flat()
            self._packed_current = False
        self.update_count += 1

    def sync_update_counter(self) -> None:
        """Copy :attr:`update_count` to the device counter the ``colours`` kernels draw their noise stream
        from (:meth:`update` does it when needed; a recorded graph that replays updates needs it before)."""
        self._update_counter.assign(np.array([self.update_count], dtype=np.int32))
        self._counter_synced = True

    def _update_simd(self) -> None:
        state = self._simd
        if not self._packed_current:
            state.load(self.x, self.x_prev, self.alive, self.pin, self.anchor)
            p = self._wp_params
            state.load_params(p["damping"], p["dt"], p["gravity"], p["noise_std"], p["elasticity"])
            self._packed_current = True
        state.load_controls(self.displacement, self.tip)
        seed = self._noise_seed()
        tracing = self._tracing()

        def step_part(part: tuple[int, int]) -> None:
            count, offset = part
            state.step(
                self._simd_model,
                seed,
                block_offset=offset,
                block_count=count,
                first_stream=self.first_noise_stream,
                status=self._status,
            )
            if tracing:
                self._launches["map_tip", offset](
                    state.kernels.map_tip,
                    dim=count,
                    inputs=[
                        self._search,
                        offset,
                        self.num_envs,
                        self.update_count,
                        state.vert,
                        self.tip,
                    ],
                    outputs=[self._removed_at, self.path],
                    device=self.device,
                )

        others = [] if self._pool is None else [self._pool.submit(step_part, s) for s in self._slices[1:]]
        try:
            step_part(self._slices[0])
        finally:  # the other slices finish before anything reads the state; this slice's error comes first
            if others:
                wait(others)
        for future in others:
            future.result()
        self._flat_current = False

    def _sync_flat(self) -> None:
        """Unpack the SIMD blocks into the env-major arrays if they are behind."""
        if not self._flat_current:
            self._simd.store(self.x, self.x_prev, self.alive)
            self._flat_current = True

    def _noise_seed(self) -> int:
        # A distinct stream per update; kept in int32 range for the kernel argument. The colours path
        # computes the same on the device from _noise_seed_base() and its update counter.
        return (self._noise_seed_base() + self.update_count) % NOISE_SEEDS

    def _noise_seed_base(self) -> int:
        return (self.seed * 1_000_003) % NOISE_SEEDS

    def _own_arrays(self) -> bool:
        """Whether the update reads and writes only the simulator's own arrays, the ones graphs are
        recorded with (not so after a taped update, or while a user's displacement array is plugged in)."""
        own = {id(a) for a in self._buffers}
        return (
            {id(self.x), id(self.x_prev), id(self._spare)} == own
            and any(self.alive is a for a in self._alive)
            and self.displacement is self._displacement_own
        )

    def _update_captured(self) -> None:
        """Replay the recorded colours update for the current buffer arrangement (record it first)."""
        key = (id(self.x), id(self.x_prev), id(self.alive))
        entry = self._graphs.get(key)
        if entry is None:
            before = (self.x, self.x_prev, self._spare, self.alive)
            try:
                with wp.ScopedCapture(device=self.device) as capture:
                    self._update_colours(tape_mode=False)
                after = (self.x, self.x_prev, self._spare, self.alive)
            finally:
                self.x, self.x_prev, self._spare, self.alive = before  # recording did not run the update
            entry = self._graphs[key] = (capture.graph, after)
        graph, after = entry
        wp.capture_launch(graph)
        self.x, self.x_prev, self._spare, self.alive = after

    def _update_colours(self, tape_mode: bool) -> None:
        b, n = self.num_envs, self.grid.num_vertices
        nx, ny = self.grid.nx, self.grid.ny
        p = self._wp_params
        spacing = self.grid.spacing_mm
        out = _fresh(self.x) if tape_mode else self._spare
        launch(
            kernels.integrate_kernel,
            dim=(b, n),
            inputs=[
                n,
                p["damping"],
                p["dt"],
                p["gravity"],
                p["noise_std"],
                int(self.config.first_order_z),
                self._seed_base,
                self._update_counter,
                self.first_noise_stream,
                self.x,
                self.x_prev,
                self.alive,
                self.pin,
                self.anchor,
                self.displacement,
            ],
            outputs=[out],
            device=self.device,
        )
        new_prev, work = self.x, out
        spare = None if tape_mode else self.x_prev
        weights = self.config.sweep_weights
        chebyshev = self.config.chebyshev_rho > 0
        # The positions two sweeps back, by sweep parity: under the tape the (never overwritten) arrays
        # themselves; otherwise copies in two buffers of their own, as the sweeps ping-pong theirs.
        older = [work, None] if tape_mode else self._older
        if chebyshev and not tape_mode:
            self._chebyshev(1.0, True, True, work, work, work, older[0])
        for k, weight in enumerate(weights, start=1):
            for colour in self.colours:
                dest = _fresh(work) if tape_mode else spare
                launch(
                    kernels.relax_colour_kernel,
                    dim=(b, n),
                    inputs=[
                        nx,
                        ny,
                        p["elasticity"],
                        colour.di,
                        colour.dj,
                        colour.rest_length(spacing),
                        int(colour.on_rows),
                        colour.divisor,
                        colour.parity,
                        work,
                        self.alive,
                        self.pin,
                    ],
                    outputs=[dest],
                    device=self.device,
                )
                work, spare = dest, work
            if not chebyshev:
                continue
            if tape_mode:
                if k > 1:
                    extrapolated = _fresh(work)
                    self._chebyshev(weight, False, False, work, older[k % 2], extrapolated, extrapolated)
                    work = extrapolated
                older[k % 2] = work
            else:
                save = k < len(weights) - 1  # the last two sweeps' positions are never read back
                if k > 1 or save:
                    self._chebyshev(weight, k == 1, save, work, older[k % 2], work, older[k % 2])
        if tape_mode:
            alive_out = wp.empty_like(self.alive)
        else:
            alive_out = self._alive[1] if self.alive is self._alive[0] else self._alive[0]
        launch(
            kernels.cut_kernel,
            dim=(b, n),
            inputs=[
                n,
                self.config.cut_radius,
                self.config.cut_height,
                self._lower,
                self._upper,
                work,
                self.alive,
                self.tip,
            ],
            outputs=[alive_out, self._status],
            device=self.device,
        )
        launch(kernels.count_update_kernel, dim=1, inputs=[self._update_counter], device=self.device)
        self.x_prev, self.x, self.alive = new_prev, work, alive_out
        if not tape_mode:
            self._spare = spare

    def _chebyshev(self, weight, first: bool, save: bool, x, older, x_out, saved_out) -> None:
        """One Chebyshev extrapolation of the whole batch (:func:`kernels.chebyshev_kernel`)."""
        launch(
            kernels.chebyshev_kernel,
            dim=self.num_envs * self.grid.num_vertices,
            inputs=[float(weight), int(first), int(save), x, older],
            outputs=[x_out, saved_out],
            device=self.device,
        )


def _checked_seed(value: int) -> int:
    return check_integer("Simulator.seed", value, 0, NOISE_SEEDS - 1)


def _fresh(like: wp.array) -> wp.array:
    """A new array shaped like ``like`` that records gradients (for taped rollouts)."""
    return wp.empty_like(like, requires_grad=True)
