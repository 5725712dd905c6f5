"""DAgger from a teacher dataset, as an rsl-rl algorithm: rsl-rl's ``OnPolicyRunner`` drives it
(``class_name`` ``agents.dagger.algorithm:DAgger``) through the same ``act`` / ``process_env_step`` /
``update`` loop as es, one whole cut per env an iteration (:mod:`agents.dagger`; the settings:
:class:`agents.dagger.config.DaggerConfig`).

The label of a state is computed from its raw observation alone (:mod:`envs.observations`): the env's own
progress (entry 0) gives the step ``t`` of its contour's cut, and the grasp displacement (entries 1-3)
where the grasp is. The teacher's grasp after its move ``t`` is ``G[t + 1]`` (its plan's moves added up
under the simulator's limits: ``max_step_mm`` per axis a step, ``max_displacement_mm`` in all); the label
is the move that takes the grasp there, ``clip((G[t + 1] - g) / max_step_mm, -1, 1)``. On the teacher's own
states it is the teacher's move; off them it is the teacher's move plus the way back to its path, so the
student learns to recover from its own mistakes (DAgger's point), not only to replay moves."""

from __future__ import annotations

import numpy as np
import torch
from rsl_rl.env import VecEnv
from rsl_rl.models import MLPModel
from tensordict import TensorDict

from agents.learner import ActorOnly


def teacher_path(plan: np.ndarray, max_step: float, max_displacement: float) -> np.ndarray:
    """(T + 1, 3) the grasp displacement (mm) before each of the ``(T, 3)`` moves of ``plan`` and after the
    last, as the simulator moves the grasp (each axis clipped to ``max_step``, the total capped at
    ``max_displacement``; float32, in the kernel's order)."""
    limit, cap = np.float32(max_step), np.float32(max_displacement)
    path = np.zeros((len(plan) + 1, 3), dtype=np.float32)
    for t, move in enumerate(np.asarray(plan, dtype=np.float32)):
        u = path[t] + np.clip(move, -limit, limit)
        norm = np.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
        path[t + 1] = u * (cap / norm) if norm > cap else u
    return path


class DAgger(ActorOnly):
    """DAgger on a teacher dataset (module docstring), in rsl-rl's algorithm interface.

    Args:
        actor: The student (rsl-rl's ``MLPModel`` or :class:`agents.models.FeedbackMLPModel`).
        env: The env it trains on (warpcut's rsl-rl adapter): every env's contour has a teacher in
            ``teachers``, at the env's pinch point.
        teachers, beta, learning_rate, updates, minibatch, buffer, stride: :class:`agents.dagger.config.
            DaggerConfig`'s.
        seed: Seed of the teacher draws and the minibatches.
        device: Torch device of the actor.
    """

    def __init__(
        self,
        actor: MLPModel,
        env: VecEnv,
        teachers: str,
        beta: float,
        learning_rate: float,
        updates: int,
        minibatch: int,
        buffer: int,
        stride: int,
        horizon: int = 1,
        seed: int = 0,
        device: str = "cpu",
        multi_gpu_cfg: dict | None = None,
    ) -> None:
        super().__init__(actor, env, learning_rate, "dagger", device, multi_gpu_cfg)
        self.beta, self.updates, self.minibatch = float(beta), int(updates), int(minibatch)
        self.capacity, self.stride, self.horizon = int(buffer), int(stride), int(horizon)
        self.optimizer = torch.optim.Adam(self.actor.parameters(), lr=learning_rate)
        self.rng = np.random.default_rng(seed)
        self.generator = torch.Generator().manual_seed(int(seed))
        self._path, self._steps = self._teacher_paths(env, teachers)
        config = env.cfg.config()
        self.max_step, self.max_displacement = float(config.max_step_mm), float(config.max_displacement_mm)
        self.iteration = 0
        self.data = torch.zeros(0, 0)
        self.targets = torch.zeros(0, 0)
        self._step = 0
        self._follow = torch.zeros(env.num_envs, dtype=torch.bool)
        self._new: list[tuple[torch.Tensor, torch.Tensor]] = []
        self._rng_start = self.rng.bit_generator.state

    @staticmethod
    def _teacher_paths(env: VecEnv, source: str) -> tuple[torch.Tensor, torch.Tensor]:
        """Each env's teacher path (B, T_max + 1, 3), mm, padded with its last point, and its steps (B,)."""
        from agents.teachers import load_teachers

        options = getattr(env, "cfg", None)
        if options is None or not hasattr(options, "per_env"):
            raise ValueError("dagger: trains on warpcut's env (its contours' teachers)")
        config = options.config()
        teachers = {t.contour.name: t for t in load_teachers(source, config)}
        contours, pinches, _ = options.per_env(env.num_envs)
        paths: dict[str, np.ndarray] = {}
        for contour, pinch in zip(contours, pinches, strict=True):
            teacher = teachers.get(contour.name)
            if teacher is None:
                raise ValueError(
                    f"train.dagger.teachers: {source} has no teacher for {contour.name}; train on its "
                    "contours (warpcut generalist --teachers DIR), or add it (warpcut teachers)"
                )
            if not np.allclose(teacher.pinch, pinch, atol=1e-6):
                raise ValueError(
                    f"train.dagger.teachers: the teacher of {contour.name} pinches at "
                    f"{teacher.pinch.tolist()}, the env at {np.asarray(pinch).tolist()}; train at the "
                    "teacher's pinch point"
                )
            if contour.name not in paths:
                paths[contour.name] = teacher_path(
                    teacher.plan, config.max_step_mm, config.max_displacement_mm
                )
        longest = max(len(p) for p in paths.values())
        padded = {n: np.concatenate([p, np.repeat(p[-1:], longest - len(p), 0)]) for n, p in paths.items()}
        path = torch.as_tensor(np.stack([padded[c.name] for c in contours]))
        steps = torch.as_tensor([len(paths[c.name]) - 1 for c in contours])
        return path, steps

    def teacher_moves(self, raw: torch.Tensor) -> torch.Tensor:
        """(B, 3) the teacher's moves (action units) for the (B, D) raw observations of the batch's envs
        (module docstring)."""
        steps = self._steps.to(raw.device)
        t = torch.minimum(torch.round(raw[:, 0].double() * steps).long().clamp(min=0), steps)
        ahead = torch.minimum(t + self.horizon, steps)
        target = self._path.to(raw.device)[torch.arange(len(raw)), ahead]
        grasp = raw[:, 1:4] * self.max_displacement
        span = torch.clamp(ahead - t, min=1).unsqueeze(-1).to(raw.dtype)
        return torch.clamp((target - grasp) / (span * self.max_step), -1.0, 1.0)

    # rsl-rl's algorithm interface ----------------------------------------------------------------------

    def act(self, obs: TensorDict) -> torch.Tensor:
        """Each env's move: its teacher's (the iteration's share of envs) or the student's; every kept step's
        raw observation is labelled."""
        if self._step == 0:
            self._rng_start = self.rng.bit_generator.state  # a save mid-iteration draws it again
            share = self.beta**self.iteration
            self._follow = torch.as_tensor(self.rng.random(self.env.num_envs) < share)
        raw = torch.cat([obs[group] for group in self.actor.obs_groups], dim=-1)
        labels = self.teacher_moves(raw)
        with torch.inference_mode():
            student = self.actor(obs)
        if self._step % self.stride == 0:
            live = (raw[:, 0] < 1.0) & raw.abs().sum(-1).gt(0)  # cutting, not diverged (zeroed)
            self._new.append((raw[live].detach().cpu().clone(), labels[live].detach().cpu().clone()))
        self._step += 1
        moves = torch.where(self._follow.to(raw.device).unsqueeze(-1), labels.to(student.dtype), student)
        return torch.clamp(moves, -1.0, 1.0)

    def process_env_step(
        self, obs: TensorDict, rewards: torch.Tensor, dones: torch.Tensor, extras: dict
    ) -> None:
        """Nothing to keep: the labels come from the observations."""

    def compute_returns(self, obs: TensorDict) -> None:
        """Nothing to do: no returns."""

    def update(self) -> dict[str, float]:
        """Aggregate the iteration's labelled states and regress the student onto the aggregate."""
        follow = float(self._follow.float().mean())
        new_obs = torch.cat([o for o, _ in self._new]) if self._new else torch.zeros(0, self.data.shape[-1])
        new_labels = torch.cat([a for _, a in self._new]) if self._new else torch.zeros(0, 3)
        self._new, self._step = [], 0
        if self.actor.obs_normalization and len(new_obs):
            self.actor.obs_normalizer.update(new_obs.to(self.device))
        if self.data.numel():  # the aggregate, the oldest dropped first
            new_obs, new_labels = torch.cat([self.data, new_obs]), torch.cat([self.targets, new_labels])
        self.data, self.targets = new_obs[-self.capacity :], new_labels[-self.capacity :]
        self.iteration += 1
        losses = []
        for _ in range(self.updates):
            index = torch.randint(
                len(self.data), (min(self.minibatch, len(self.data)),), generator=self.generator
            )
            loss = torch.nn.functional.mse_loss(self._student(self.data[index]), self.targets[index])
            self.optimizer.zero_grad()
            loss.backward()
            self.optimizer.step()
            losses.append(float(loss.detach()))
        return {
            "imitation_loss": float(np.mean(losses[-max(1, self.updates // 10) :])),
            "teacher_share": follow,
            "dataset": float(len(self.data)),
        }

    def _student(self, raw: torch.Tensor) -> torch.Tensor:
        """The student's deterministic moves for raw observations (differentiable)."""
        out = self.actor.mlp(self.actor.obs_normalizer(raw.to(self.device)))
        return out if self.actor.distribution is None else self.actor.distribution.deterministic_output(out)

    def save(self) -> dict:
        return {
            "actor_state_dict": self.actor.state_dict(),
            "optimizer_state_dict": {
                "adam": self.optimizer.state_dict(),
                "iteration": self.iteration,
                # mid-iteration (Ctrl-C): the stream as the iteration began; a resume draws it again
                "rng": self._rng_start if self._step else self.rng.bit_generator.state,
                "generator": self.generator.get_state(),
                "obs": self.data.clone(),
                "labels": self.targets.clone(),
            },
        }

    def load(self, loaded_dict: dict, load_cfg: dict | None, strict: bool) -> bool:
        self.actor.load_state_dict(loaded_dict["actor_state_dict"], strict=strict)
        state = loaded_dict.get("optimizer_state_dict") or {}
        if "labels" not in state:
            raise ValueError("not a dagger checkpoint (no labelled states); resume it with its own algo")
        self.optimizer.load_state_dict(state["adam"])
        self.iteration = int(state["iteration"])
        self.rng.bit_generator.state = state["rng"]
        self._rng_start = self.rng.bit_generator.state
        self.generator.set_state(state["generator"])
        self.data, self.targets = state["obs"], state["labels"]
        return True
