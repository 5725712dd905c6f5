"""Action distributions that rsl-rl lacks, pluggable through a model's ``distribution_cfg``.

rsl-rl 5.5.1 builds an actor's output distribution from ``{"class_name": ..., **kwargs}`` as
``cls(output_dim, **kwargs)``, where ``output_dim`` is the env's ``num_actions``. Select the one here with::

    "distribution_cfg": {"class_name": "agents.ppo.distributions:Categorical", "num_choices": K}
"""

from __future__ import annotations

import torch
import torch.nn as nn
from rsl_rl.modules.distribution import Distribution


class Categorical(Distribution):
    """Independent categorical distributions over ``num_choices`` options for each of ``output_dim`` actions.

    The actor's MLP outputs logits of shape ``(..., output_dim, num_choices)``. Sampled and deterministic
    actions are choice indices stored as floats, shape ``(..., output_dim)``, because rsl-rl's rollout storage
    and PPO keep actions in a float tensor of shape ``(num_envs, num_actions)``; the env casts them back with
    ``actions.long()``. One discrete action per env is ``output_dim == num_actions == 1``.
    """

    def __init__(
        self,
        output_dim: int,
        num_choices: int,
        init_logit_scale: float = 0.01,
        init_choice: int | None = None,
        init_choice_prob: float = 0.0,
    ) -> None:
        """Initialize the categorical distribution module.

        Args:
            output_dim: Number of independent discrete actions (the env's ``num_actions``).
            num_choices: Number of options per action.
            init_logit_scale: Scale of the logit layer's initial weights; small values start the policy near
                uniform, i.e. at maximum entropy.
            init_choice: Option the initial policy prefers (for warpcut: 0, "stay"), or None for none.
            init_choice_prob: Initial probability of ``init_choice``, in [1 / num_choices, 1); the others
                share the rest evenly. The initial deterministic (argmax) policy is ``init_choice``.
        """
        super().__init__(output_dim)
        if num_choices < 2:
            raise ValueError(f"A categorical action needs at least 2 choices, got {num_choices}.")
        if init_choice is not None:
            if not 0 <= init_choice < num_choices:
                raise ValueError(f"init_choice: must index one of {num_choices} choices, got {init_choice}.")
            if not 1.0 / num_choices <= init_choice_prob < 1.0:
                raise ValueError(
                    f"init_choice_prob: must lie in [1/{num_choices}, 1), got {init_choice_prob}."
                )
        self.num_choices = num_choices
        self.init_logit_scale = init_logit_scale
        self.init_choice = init_choice
        self.init_choice_prob = init_choice_prob
        self._logits = torch.empty(0)
        self._probs = torch.empty(0)

    def update(self, mlp_output: torch.Tensor) -> None:
        """Update the distribution from logits of shape ``(..., output_dim, num_choices)``.

        Log-probabilities and probabilities are computed once per update from a few elementwise ops: rsl-rl
        asks for the sample, log-probability, parameters and entropy at every env step and minibatch, and
        torch's CPU softmax over a short last dimension costs ~60 us for 512 x 7 logits where these cost ~10
        (docs/performance.md, section 6)."""
        shifted = mlp_output - mlp_output.amax(dim=-1, keepdim=True)
        self._logits = shifted - shifted.exp().sum(dim=-1, keepdim=True).log()
        self._probs = self._logits.exp()

    def sample(self) -> torch.Tensor:
        """Sample choice indices by inverting the cumulative distribution at one uniform draw per action, as
        floats of shape ``(..., output_dim)``."""
        u = torch.rand(self._probs.shape[:-1] + (1,), device=self._probs.device, dtype=self._probs.dtype)
        below = (self._probs.cumsum(dim=-1) < u).sum(dim=-1)
        return below.clamp_(max=self.num_choices - 1).float()

    def deterministic_output(self, mlp_output: torch.Tensor) -> torch.Tensor:
        """Return the most likely choice indices, as floats of shape ``(..., output_dim)``."""
        return mlp_output.argmax(dim=-1).float()

    def as_deterministic_output_module(self) -> nn.Module:
        """Return an export-friendly module that takes the argmax of the logits."""
        return _ArgmaxDeterministicOutput()

    @property
    def input_dim(self) -> list[int]:
        """Return the MLP output shape ``[output_dim, num_choices]`` (one row of logits per action)."""
        return [self.output_dim, self.num_choices]

    @property
    def probs(self) -> torch.Tensor:
        """Return the choice probabilities, shape ``(..., output_dim, num_choices)``."""
        return self._probs

    @property
    def mean(self) -> torch.Tensor:
        """Return the expected choice index."""
        return (self._probs * self._choice_indices()).sum(dim=-1)

    @property
    def std(self) -> torch.Tensor:
        """Return the standard deviation of the choice index (rsl-rl logs it as ``Policy/mean_std``)."""
        deviation = self._choice_indices() - self.mean.unsqueeze(-1)
        return (self._probs * deviation.square()).sum(dim=-1).sqrt()

    @property
    def entropy(self) -> torch.Tensor:
        """Return the entropy, summed over the actions."""
        logits = self._logits.clamp(min=torch.finfo(self._logits.dtype).min)
        return -(logits * self._probs).sum(-1).sum(dim=-1)

    @property
    def params(self) -> tuple[torch.Tensor, ...]:
        """Return ``(logits,)``, normalized so that they are log-probabilities."""
        return (self._logits,)

    def log_prob(self, outputs: torch.Tensor) -> torch.Tensor:
        """Compute the log probability of choice indices (floats), summed over the actions."""
        return self._logits.gather(-1, outputs.long().unsqueeze(-1)).squeeze(-1).sum(dim=-1)

    def kl_divergence(
        self, old_params: tuple[torch.Tensor, ...], new_params: tuple[torch.Tensor, ...]
    ) -> torch.Tensor:
        """Compute KL(old || new) of two :attr:`params` (log-probabilities), summed over the actions. As in
        ``torch.distributions``' categorical KL, a choice the new policy cannot take costs infinity and one
        the old could not take nothing."""
        old, new = old_params[0], new_params[0]
        p_old = old.exp()
        t = (p_old * (old - new)).masked_fill(new == -torch.inf, torch.inf).masked_fill(p_old == 0, 0.0)
        return t.sum(-1).sum(dim=-1)

    def init_mlp_weights(self, mlp: nn.Module) -> None:
        """Shrink the logit layer so that the initial policy is close to uniform, or, with ``init_choice``,
        close to ``init_choice_prob`` on that option and uniform over the others."""
        # rsl-rl's MLP ends with Linear then Unflatten when the output has a shape, as here.
        logit_layer = mlp[-2]  # type: ignore
        with torch.no_grad():
            logit_layer.weight.mul_(self.init_logit_scale)
            logit_layer.bias.zero_()
            if self.init_choice is not None:
                # p / ((1 - p) / (K - 1)) = exp(bias): the odds of init_choice against each other option.
                odds = self.init_choice_prob * (self.num_choices - 1) / (1.0 - self.init_choice_prob)
                bias = logit_layer.bias.view(self.output_dim, self.num_choices)
                bias[:, self.init_choice] = float(torch.log(torch.tensor(odds)))

    def _choice_indices(self) -> torch.Tensor:
        return torch.arange(self.num_choices, device=self._logits.device, dtype=self._logits.dtype)


class _ArgmaxDeterministicOutput(nn.Module):
    """Exportable module that returns the most likely choice index of each action, as a float."""

    def forward(self, mlp_output: torch.Tensor) -> torch.Tensor:
        return mlp_output.argmax(dim=-1).float()
