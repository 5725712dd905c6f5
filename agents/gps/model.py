"""The gps student's network: a teacher's plan as feed-forward, plus es's MLP and feedback path on top.

``move = plan[t] + mlp(x) + K x[tracking]``, with ``t = round(time_index * plan_steps)`` read from the raw
(unnormalised) observation's time index (:mod:`envs.observations`, entry 0: ``step / num_steps``). The plan is
a buffer in the actor's state dict, in the env's action units (moves / ``max_step_mm``), so checkpoints,
evaluation and the TorchScript and ONNX exports carry it: an exported student needs nothing besides its file.
"""

from __future__ import annotations

import torch
from tensordict import TensorDict

from agents.models import FeedbackMLPModel

__all__ = ["PlanFeedbackModel", "PlanLookup"]


class PlanLookup(torch.nn.Module):
    """``plan[round(time * steps)]``: the plan's move at the step a time index ``step / steps`` names; zero
    past the plan's end (a plan of zeros is the still grasp)."""

    def __init__(self, steps: int, actions: int) -> None:
        super().__init__()
        self.register_buffer("plan", torch.zeros(int(steps), int(actions)))

    def forward(self, time: torch.Tensor) -> torch.Tensor:
        steps = self.plan.shape[0]
        index = torch.round(time * steps).long()
        inside = ((index >= 0) & (index < steps)).unsqueeze(-1).to(self.plan.dtype)
        return self.plan[torch.clamp(index, 0, steps - 1)] * inside


class _WithPlan(torch.nn.Module):
    """An exported actor (rsl-rl's TorchScript or ONNX wrapper, fed the raw observation) plus the plan's
    feed-forward."""

    is_recurrent: bool = False

    def __init__(self, inner: torch.nn.Module, lookup: PlanLookup, time_index: int) -> None:
        super().__init__()
        self.inner = inner
        self.lookup = PlanLookup(*lookup.plan.shape)
        self.lookup.load_state_dict(lookup.state_dict())
        self.time_index = int(time_index)
        self.input_size = int(getattr(inner, "input_size", 0))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.inner(x) + self.lookup(x[:, self.time_index])

    @torch.jit.export
    def reset(self) -> None:
        """Nothing to reset: no recurrent state."""

    def get_dummy_inputs(self) -> tuple[torch.Tensor]:
        return (torch.zeros(1, self.input_size),)

    @property
    def input_names(self) -> list[str]:
        return ["obs"]

    @property
    def output_names(self) -> list[str]:
        return ["actions"]


class PlanFeedbackModel(FeedbackMLPModel):
    """:class:`agents.models.FeedbackMLPModel` plus a plan's feed-forward (module docstring).

    Args:
        plan_steps: The plan's steps (the episode's); its moves start at zero (the still grasp) until a
            teacher's are set (:meth:`set_plan`) or a checkpoint's loaded.
        the rest: :class:`~agents.models.FeedbackMLPModel`'s.
    """

    TIME_INDEX = 0
    """Where the time index (``step / num_steps``) lies in the observation (:mod:`envs.observations`)."""

    def __init__(self, obs: TensorDict, obs_groups, obs_set, output_dim, *args, plan_steps: int, **kwargs):
        super().__init__(obs, obs_groups, obs_set, output_dim, *args, **kwargs)
        if isinstance(plan_steps, bool) or not isinstance(plan_steps, int) or plan_steps < 1:
            raise ValueError(f"plan_steps: must be an integer >= 1 (got {plan_steps!r})")
        self.lookup = PlanLookup(plan_steps, output_dim)

    def set_plan(self, moves: torch.Tensor) -> None:
        """Play ``moves`` ((steps, >= actions), in the env's action units) as the feed-forward; their first
        ``actions`` columns, zero-padded or cut to the plan's steps."""
        moves = torch.as_tensor(moves, dtype=self.lookup.plan.dtype).reshape(len(moves), -1)
        steps, actions = self.lookup.plan.shape
        plan = torch.zeros(steps, actions, dtype=moves.dtype)
        plan[: min(steps, len(moves))] = moves[:steps, :actions]
        with torch.no_grad():
            self.lookup.plan.copy_(plan.to(self.lookup.plan.device))

    def feedforward(self, obs: TensorDict) -> torch.Tensor:
        """The plan's moves at each env's step, from the raw observation's time index."""
        raw = torch.cat([obs[group] for group in self.obs_groups], dim=-1)
        return self.lookup(raw[..., self.TIME_INDEX])

    def forward(self, obs: TensorDict, masks=None, hidden_state=None, stochastic_output: bool = False):
        return super().forward(obs, masks, hidden_state, stochastic_output) + self.feedforward(obs)

    def as_jit(self) -> torch.nn.Module:
        return _WithPlan(super().as_jit(), self.lookup, self.TIME_INDEX)

    def as_onnx(self, verbose: bool) -> torch.nn.Module:
        return _WithPlan(super().as_onnx(verbose), self.lookup, self.TIME_INDEX)
