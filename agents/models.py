"""The tensioning policy's network beyond rsl-rl's MLP: a linear feedback path from the tracking error.

:class:`FeedbackMLPModel` is rsl-rl's :class:`~rsl_rl.models.MLPModel` whose MLP output gets a linear map of
the (normalised) tracking error added, ``mlp(x) + K x[tracking]``, ``K`` (actions x 3) zero at the start.
It is the structure of the plan optimiser's feedback gains (``warpcut optimize --set
grad.es_feedback_only=true``: a still grasp that moves by a gain matrix times the tracking error) inside the
neural policy: the network can still use every observation, and the gains need not be found through two
tanh layers. es's policy has it (:attr:`agents.es.config.EsConfig.feedback`). The path lives inside
``model.mlp`` (:class:`FeedbackMLP`), so rsl-rl's PPO, the TorchScript and ONNX exports and everything else
that calls ``model.mlp`` use it unchanged.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import torch
from rsl_rl.models import MLPModel
from tensordict import TensorDict

from envs.observations import TRACKING_ERROR, observation_names

__all__ = ["FeedbackMLP", "FeedbackMLPModel", "feedback_inputs", "scale_moves_", "torch_threads"]


class FeedbackMLP(torch.nn.Module):
    """``body(x) + feedback(x[..., start : start + size])``: an MLP (``body``, rsl-rl's) plus a bias-free
    linear map of ``size`` of its inputs to its last linear layer's outputs (reshaped as the body's output),
    zero-initialised.

    With ``scheduled`` the gains also depend on the observation (gain scheduling): the body's last layer
    grows to ``A * (1 + size)`` outputs, the first ``A`` the move as before and the rest a matrix ``G(x)``
    (A x size) added to the static gains, ``move = body(x)[:A] + (K + G(x)) e`` with ``e`` the ``size``
    inputs at ``start``. A policy for many contours needs it: the gains that suit a contour depend on its
    shape ahead and on where the grasp is (continuous moves only)."""

    def __init__(self, body: torch.nn.Sequential, start: int, size: int, scheduled: bool = False) -> None:
        super().__init__()
        last = [m for m in body.modules() if isinstance(m, torch.nn.Linear)][-1]
        out = last.out_features
        self.start, self.size, self.scheduled, self.actions = int(start), int(size), bool(scheduled), out
        if self.scheduled:  # the last layer also gives the scheduled gains G(x)
            index = next(i for i, m in enumerate(body) if m is last)
            body[index] = torch.nn.Linear(last.in_features, out * (1 + self.size))
        self.body = body
        self.feedback = torch.nn.Linear(self.size, out, bias=False)
        with torch.no_grad():
            self.feedback.weight.zero_()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = self.body(x)  # for discrete moves shaped (..., actions, choices) by the MLP's last module
        error = x[..., self.start : self.start + self.size]
        if self.scheduled:
            gains = out[..., self.actions :].unflatten(-1, (self.actions, self.size))
            out = out[..., : self.actions] + (gains @ error.unsqueeze(-1)).squeeze(-1)
        return out + self.feedback(error).reshape(out.shape)


class FeedbackMLPModel(MLPModel):
    """rsl-rl's :class:`~rsl_rl.models.MLPModel` with a :class:`FeedbackMLP` (module docstring).

    Args:
        feedback_inputs: ``(start, size)``: where in the model's concatenated observation the tracking
            error lies (:func:`feedback_inputs`); the rest as :class:`~rsl_rl.models.MLPModel`'s.
        scheduled: Schedule the gains on the observation (:class:`FeedbackMLP`).
    """

    def __init__(
        self,
        obs: TensorDict,
        obs_groups: dict[str, list[str]],
        obs_set: str,
        output_dim: int,
        *args,
        feedback_inputs: tuple[int, int] | list[int],
        scheduled: bool = False,
        **kwargs,
    ) -> None:
        super().__init__(obs, obs_groups, obs_set, output_dim, *args, **kwargs)
        start, size = (int(v) for v in feedback_inputs)
        if not (0 <= start and size > 0 and start + size <= self.obs_dim):
            raise ValueError(
                f"feedback_inputs: ({start}, {size}) is not a slice of the {self.obs_dim} observations"
            )
        self.mlp = FeedbackMLP(self.mlp, start, size, scheduled)


def feedback_inputs(env) -> tuple[int, int]:
    """``(start, size)`` of the tracking error in the observation of warpcut's env ``env`` (an rsl-rl
    adapter, whose ``cfg`` is its :class:`~envs.options.PatternCutOptions`, or the batched env itself).

    Raises:
        ValueError: ``env`` is not warpcut's, or its policy does not observe the tracking error.
    """
    from envs.options import PatternCutOptions

    options = getattr(env, "cfg", None)
    options = options if isinstance(options, PatternCutOptions) else getattr(env, "options", None)
    if not isinstance(options, PatternCutOptions):
        raise ValueError("feedback: the actor's feedback path needs warpcut's env (its tracking error)")
    if not options.contour_features:
        raise ValueError(
            "feedback: the policy observes no tracking error (env.contour_features=false); observe the "
            "contour, or train without the feedback path (train.es.feedback=false)"
        )
    names = observation_names(options.num_fiducials, options.contour_features)
    return names.index(TRACKING_ERROR[0]), len(TRACKING_ERROR)


def scale_moves_(mlp: torch.nn.Module, gain: float) -> None:
    """Multiply what ``mlp`` (an actor's MLP: rsl-rl's, or a :class:`FeedbackMLP`) outputs by ``gain``, in
    place: its last linear layer's weights and bias, and the feedback path's gains, scaled. Its output is
    linear in them, so a continuous policy's move becomes ``gain`` times its move, exactly."""
    layers = [m for m in mlp.modules() if isinstance(m, torch.nn.Linear)]
    feedback = getattr(mlp, "feedback", None)
    last = [m for m in layers if m is not feedback][-1]
    with torch.no_grad():
        for layer in (last, feedback):
            if layer is not None:
                for parameter in layer.parameters():
                    parameter.mul_(gain)


@contextlib.contextmanager
def torch_threads(count: int) -> Iterator[None]:
    """torch's CPU ops on ``count`` threads inside the block, as many as before after it. The policy is a
    small MLP that gains nothing from threads, while the simulator steps the batch on threads of its own:
    torch's idle OpenMP threads spinning beside them slow both (a 2 x 32 MLP's batch of 720 took 0.3 ms on
    one thread, 2-5 ms on two beside a busy simulator; docs/performance.md)."""
    before = torch.get_num_threads()
    torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(before)
