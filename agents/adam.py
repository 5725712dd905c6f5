"""Adam on NumPy arrays: the optimiser of es (:mod:`agents.es.algorithm`) and of the open-loop plans
(:mod:`agents.plan_optimizer`), whose gradients are estimated outside torch."""

from __future__ import annotations

import numpy as np


class Adam:
    """Adam on a NumPy array (minimising), with the usual bias correction; ``learning_rate`` is a number or
    an array of ``shape`` (a step per parameter)."""

    def __init__(self, shape: tuple[int, ...], learning_rate: float, betas=(0.9, 0.999), eps: float = 1e-8):
        self.m, self.v = np.zeros(shape), np.zeros(shape)
        self.learning_rate, self.betas, self.eps, self.steps = learning_rate, betas, eps, 0

    def state(self) -> dict:
        return {"m": self.m.tolist(), "v": self.v.tolist(), "steps": self.steps}

    def load(self, state: dict) -> None:
        self.m, self.v = np.asarray(state["m"]), np.asarray(state["v"])
        self.steps = int(state["steps"])

    def step(self, grad: np.ndarray) -> np.ndarray:
        """The change to add to the parameters for ``grad``."""
        b1, b2 = self.betas
        self.steps += 1
        self.m = b1 * self.m + (1 - b1) * grad
        self.v = b2 * self.v + (1 - b2) * grad * grad
        m_hat, v_hat = self.m / (1 - b1**self.steps), self.v / (1 - b2**self.steps)
        return -self.learning_rate * m_hat / (np.sqrt(v_hat) + self.eps)
