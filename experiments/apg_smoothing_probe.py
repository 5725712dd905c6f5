"""APG with its tape gradient smoothed by Gaussian perturbations of the moves: does randomised smoothing help
APG (it trains without)? Every training move of every env gets independent noise of SIGMA mm, outside the
gradient's path. The tape gradient at the perturbed moves, chained into the weights and averaged over the
envs, then estimates the gradient of the smoothed surrogate (the first-order randomised-smoothing estimator,
Suh et al. 2022). Runs any ``warpcut`` command with APG so patched; validation and evaluation play the policy
unperturbed. Compare with the same command without the probe (or SIGMA=0).

Run: SIGMA=0.15 python experiments/apg_smoothing_probe.py evaluate --contours fls-circle --algo apg \\
         --methods none,fixed,rl --trials 10 --out DIR
NOISE_SEED seeds the perturbations (default 0); SIGMA defaults to 0.05 mm.
"""

from __future__ import annotations

import os
import sys

import numpy as np

from agents.apg import runner as apg

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
    if len(sys.argv) < 2 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0)
    apg.ApgRunner._policy = smoothed_policy
    print(f"APG with its training moves perturbed by N(0, {SIGMA} mm)", flush=True)
    from agents.cli import main

    main(sys.argv[1:], standalone_mode=True)
