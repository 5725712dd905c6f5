"""Probe (issue 19, docs/learning.md "Session 28: randomised smoothing of the tape gradient"): APG with the
tape gradient smoothed by Gaussian perturbations of the moves. Every training move of every env gets
independent noise of SIGMA mm, outside the gradient's path. The tape gradient at the perturbed moves, chained
into the weights and averaged over the envs, then estimates the gradient of the smoothed surrogate (the
first-order randomised-smoothing estimator, Suh et al. 2022). Runs ``warpcut`` with APG so patched:

    SIGMA=0.15 python scripts/apg_smoothing_probe.py evaluate --contours fls-circle --recipe apg \\
        --methods none,fixed,rl --trials 10 --out logs/probe-smooth

NOISE_SEED seeds the perturbations (default 0). Validation and evaluation play the policy unperturbed.
"""

from __future__ import annotations

import os
import sys

import numpy as np

from agents import apg

SIGMA = float(os.environ.get("SIGMA", "0.05"))
RNG = np.random.default_rng(int(os.environ.get("NOISE_SEED", "0")))
_policy = apg.ApgRunner._policy


def smoothed_policy(self, moves, observations):
    """The runner's policy, its training moves (those with a graph) perturbed by N(0, SIGMA) per axis."""
    inner = _policy(self, moves, observations)
    if moves is None or SIGMA == 0:
        return inner
    step = self.scene.config.max_step_mm

    def policy(task) -> np.ndarray:
        move = inner(task)
        noise = SIGMA * RNG.standard_normal(move.shape).astype(np.float32)
        return np.clip(move + noise, -step, step)

    return policy


if __name__ == "__main__":
    apg.ApgRunner._policy = smoothed_policy
    print(f"APG with its training moves perturbed by N(0, {SIGMA} mm)", flush=True)
    from agents.cli import main

    main(sys.argv[1:], standalone_mode=True)
