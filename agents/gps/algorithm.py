"""gps's update: es (:class:`agents.es.algorithm.ES`) on the correction that the student adds to its teacher's
plan. Every perturbed policy plays the plan's move plus its own correction, centred on the plan's nominal
observations (:mod:`agents.gps.model`), so es starts from the teacher (the correction's output layer and gains
are zero) and searches only what the plan leaves to feedback.

A fresh run's first iteration plays the plan unchanged in every env (es's warm-up iteration, here whether or
not the observations are normalised) and records the mean observation of each step: the nominal trajectory the
correction is centred on."""

from __future__ import annotations

import torch
from tensordict import TensorDict

from agents.es.algorithm import ES


class GPS(ES):
    """es on a :class:`agents.gps.model.PlanFeedbackModel`'s correction; its plan is the feed-forward of
    every perturbed copy, as of the actor itself (module docstring)."""

    def __init__(self, actor, env, *args, **kwargs) -> None:
        super().__init__(actor, env, *args, **kwargs)
        self._nominal_seen: list[torch.Tensor] = []
        self._warm_up = self._warm_up or not self._centred  # the first iteration records the nominal

    @property
    def _centred(self) -> bool:
        return bool(self.actor.nominal.centred)

    def act(self, obs: TensorDict) -> torch.Tensor:
        moves = super().act(obs)
        if self._eps is None and not self._centred:  # the warm-up: every env plays the plan
            self._nominal_seen.append(self.actor.raw(obs).detach().clone())
        return moves

    def update(self) -> dict[str, float]:
        seen, self._nominal_seen = self._nominal_seen, []
        if self._eps is None and not self._centred and seen and self._costs is not None:
            self.actor.record_nominal(seen)
        return super().update()

    def load(self, loaded_dict: dict, load_cfg: dict | None, strict: bool) -> bool:
        loaded = super().load(loaded_dict, load_cfg, strict)
        self._warm_up = self._warm_up or not self._centred  # saved before its warm-up ended (Ctrl-C)
        return loaded

    def _moves(self, obs: TensorDict) -> torch.Tensor:
        moves = super()._moves(obs) + self.actor.feedforward(obs)
        if self._centred:  # each perturbed correction at the plan's own observation
            moves = moves - self._forward(self.actor.nominal_latent(obs))
        return moves
