"""gps's update: es (:class:`agents.es.algorithm.ES`) on the correction that the student adds to its teacher's
plan. Every perturbed policy plays the plan's move plus its own MLP's and feedback path's output, so es starts
from the teacher (the correction's output layer and gains are zero) and searches only what the plan leaves to
feedback."""

from __future__ import annotations

import torch
from tensordict import TensorDict

from agents.es.algorithm import ES


class GPS(ES):
    """es on a :class:`agents.gps.model.PlanFeedbackModel`'s correction; its plan is the feed-forward of
    every perturbed copy, as of the actor itself."""

    def _moves(self, obs: TensorDict) -> torch.Tensor:
        return super()._moves(obs) + self.actor.feedforward(obs)
