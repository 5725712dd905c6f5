"""The gps student's network: a teacher's plan as feed-forward, plus a correction around the plan's own
trajectory.

``move = plan[t] + c(x) - c(x̄[t])``, with ``c(x) = mlp(x) + K x[tracking]`` (es's MLP and feedback path on
the normalised observation), ``x̄[t]`` the observation the plan itself meets at step ``t`` (the mean over the
sheets of the run's first iteration, which plays the plan unchanged) and ``t = round(time_index *
plan_steps)`` read from the raw (unnormalised) observation's time index (:mod:`envs.observations`, entry 0:
``step / num_steps``). Where the sheet does what the plan expects, the student plays the plan; it acts on how
the sheet differs from that (time-varying feedback around a nominal trajectory, as an LQR controller acts on
the deviation from the trajectory it linearised about). The correction cannot shift the plan itself by a
constant bias, the move that costs most on the nominal sheet and that es's perturbations of a network make
first.

The plan and the nominal observations are buffers in the actor's state dict, in the env's units (moves in
actions, ``max_step_mm``; raw observations), so checkpoints, evaluation and the TorchScript and ONNX exports
carry them: an exported student needs nothing besides its file. Until the nominal observations are recorded
(``centred`` 0), the correction is ``c(x)`` uncentred (zero for a fresh student either way).
"""

from __future__ import annotations

import torch
from tensordict import TensorDict

from agents.models import FeedbackMLPModel

__all__ = ["NominalLookup", "PlanFeedbackModel", "PlanLookup"]


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


class NominalLookup(torch.nn.Module):
    """The raw observation the plan meets at the step a time index names (:meth:`record`), and whether it
    has been recorded (``centred``, 1 or 0)."""

    def __init__(self, steps: int, size: int) -> None:
        super().__init__()
        self.register_buffer("obs", torch.zeros(int(steps), int(size)))
        self.register_buffer("centred", torch.zeros(()))

    def forward(self, time: torch.Tensor) -> torch.Tensor:
        steps = self.obs.shape[0]
        return self.obs[torch.clamp(torch.round(time * steps).long(), 0, steps - 1)]

    def record(self, seen: list[torch.Tensor], time_index: int) -> None:
        """Record the mean of the raw observations ``seen`` ((B, size) each) at each step their time index
        names; a step none of them reached keeps its nearest earlier step's (the last one the cut met)."""
        steps = self.obs.shape[0]
        raw = torch.cat(seen).to(self.obs)
        index = torch.clamp(torch.round(raw[:, time_index] * steps).long(), 0, steps - 1)
        sums = torch.zeros_like(self.obs).index_add_(0, index, raw)
        counts = torch.bincount(index, minlength=steps).to(raw.dtype)
        mean = sums / counts.clamp(min=1).unsqueeze(-1)
        for step in range(1, steps):
            if counts[step] == 0:
                mean[step] = mean[step - 1]
        with torch.no_grad():
            self.obs.copy_(mean)
            self.centred.fill_(1.0)


class _WithPlan(torch.nn.Module):
    """An exported actor (rsl-rl's TorchScript or ONNX wrapper, fed the raw observation) plus the plan's
    feed-forward, its correction centred on the plan's nominal observations."""

    is_recurrent: bool = False

    def __init__(self, inner: torch.nn.Module, lookup: PlanLookup, nominal: NominalLookup, time_index: int):
        super().__init__()
        self.inner = inner
        self.lookup = PlanLookup(*lookup.plan.shape)
        self.lookup.load_state_dict(lookup.state_dict())
        self.nominal = NominalLookup(*nominal.obs.shape)
        self.nominal.load_state_dict(nominal.state_dict())
        self.time_index = int(time_index)
        self.input_size = int(getattr(inner, "input_size", 0))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        time = x[:, self.time_index]
        return self.inner(x) - self.nominal.centred * self.inner(self.nominal(time)) + self.lookup(time)

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
        self.nominal = NominalLookup(plan_steps, self.obs_dim)

    def resize(self, steps: int) -> None:
        """Hold a plan of ``steps`` moves (and as many nominal observations), zero and uncentred: the table
        is the teacher's length, the nominal sheet's cut, which an env of randomised sheets (whose cut may be
        a step longer or shorter) does not know when it builds the actor."""
        device = self.lookup.plan.device
        self.lookup = PlanLookup(steps, self.lookup.plan.shape[1]).to(device)
        self.nominal = NominalLookup(steps, self.obs_dim).to(device)

    def set_plan(self, moves: torch.Tensor) -> None:
        """Play ``moves`` ((steps, >= actions), in the env's action units) as the feed-forward; their first
        ``actions`` columns, zero-padded or cut to the plan's steps."""
        moves = torch.as_tensor(moves, dtype=self.lookup.plan.dtype).reshape(len(moves), -1)
        steps, actions = self.lookup.plan.shape
        plan = torch.zeros(steps, actions, dtype=moves.dtype)
        plan[: min(steps, len(moves))] = moves[:steps, :actions]
        with torch.no_grad():
            self.lookup.plan.copy_(plan.to(self.lookup.plan.device))

    def upgrade_state(self, state: dict) -> dict:
        """A saved state of this network as it is now: a student saved before its correction was centred
        (no ``nominal.*``) plays as it did, uncentred (:func:`agents.policies.load_policy`)."""
        if "lookup.plan" not in state or "nominal.obs" in state:
            return state
        nominal = {"nominal.obs": torch.zeros_like(self.nominal.obs), "nominal.centred": torch.zeros(())}
        return {**state, **nominal}

    def raw(self, obs: TensorDict) -> torch.Tensor:
        """The raw (unnormalised) observation the network reads, its groups concatenated."""
        return torch.cat([obs[group] for group in self.obs_groups], dim=-1)

    def feedforward(self, obs: TensorDict) -> torch.Tensor:
        """The plan's moves at each env's step, from the raw observation's time index."""
        return self.lookup(self.raw(obs)[..., self.TIME_INDEX])

    def nominal_latent(self, obs: TensorDict) -> torch.Tensor:
        """The normalised nominal observation at each env's step (what the correction is centred on)."""
        return self.obs_normalizer(self.nominal(self.raw(obs)[..., self.TIME_INDEX]))

    def record_nominal(self, seen: list[torch.Tensor]) -> None:
        """Centre the correction on the raw observations ``seen`` (one batch a step of cuts that played the
        plan unchanged): their mean at each step (:class:`NominalLookup`)."""
        self.nominal.record(seen, self.TIME_INDEX)

    def forward(self, obs: TensorDict, masks=None, hidden_state=None, stochastic_output: bool = False):
        correction = super().forward(obs, masks, hidden_state, stochastic_output)
        if bool(self.nominal.centred):
            out = self.mlp(self.nominal_latent(obs))
            if self.distribution is not None:
                out = self.distribution.deterministic_output(out)
            correction = correction - out
        return correction + self.feedforward(obs)

    def as_jit(self) -> torch.nn.Module:
        return _WithPlan(super().as_jit(), self.lookup, self.nominal, self.TIME_INDEX)

    def as_onnx(self, verbose: bool) -> torch.nn.Module:
        return _WithPlan(super().as_onnx(verbose), self.lookup, self.nominal, self.TIME_INDEX)
