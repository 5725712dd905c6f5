"""The learners warpcut trains policies with, by name: the one registry that training, the pipelines and the
command line read (torch-free).

Each algorithm has its folder, its config dataclass and its implementation:

- ``es`` (:mod:`agents.es`, the default): evolution strategies on the policy's weights, an rsl-rl algorithm
  (``class_name`` ``agents.es.algorithm:ES``) that rsl-rl's ``OnPolicyRunner`` drives, one whole cut per env
  an iteration;
- ``ppo`` (:mod:`agents.ppo`): rsl-rl's PPO with warpcut's speed-ups and a categorical policy that starts
  by holding still;
- ``apg`` (:mod:`agents.apg`): analytic policy gradients through the differentiable simulator, on a runner
  of its own (its episodes run under ``wp.Tape``, not through the env's step).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Algorithm:
    """A learner: what it is, the batch it trains with unless told otherwise, and the actions it plays."""

    name: str
    summary: str
    """One line for listings and ``--help``."""
    num_envs: int
    """Envs a run trains with where none are given."""
    iterations: int | None
    """Iterations where none are given; None: the algorithm's rule for the episode's length
    (:func:`default_iterations`)."""
    action_type: str
    """The env's actions it trains with unless told otherwise: ``"discrete"`` or ``"continuous"``."""
    continuous_only: bool
    """Whether it can train only continuous actions."""
    runner: str
    """``"module:Class"`` of its runner: warpcut's rsl-rl runner (:class:`agents.training.Runner`) or its
    own."""


ALGORITHMS = {
    "es": Algorithm(
        "es",
        "evolution strategies on the policy (an MLP plus feedback gains on the tracking error), whole cuts "
        "ranked by the path score",
        num_envs=256,
        iterations=None,
        action_type="continuous",
        continuous_only=True,
        runner="agents.training:Runner",
    ),
    "ppo": Algorithm(
        "ppo",
        "rsl-rl's PPO: 1 mm moves from a categorical policy that starts by holding still, a dense reward",
        num_envs=256,
        iterations=150,
        action_type="discrete",
        continuous_only=False,
        runner="agents.training:Runner",
    ),
    "apg": Algorithm(
        "apg",
        "analytic policy gradients: the path surrogate's gradient through the differentiable simulator",
        num_envs=16,
        iterations=30,
        action_type="continuous",
        continuous_only=True,
        runner="agents.apg.runner:ApgRunner",
    ),
}
"""Every learner, the default first."""

DEFAULT_ALGORITHM = "es"
"""The learner ``train``, ``run`` and ``evaluate`` use unless told otherwise: the best measured on the suite
(docs/results.md)."""


def algorithm(name: str) -> Algorithm:
    """The registry's entry for ``name``; ``ValueError`` naming ``algo`` for an unknown one."""
    if name not in ALGORITHMS:
        raise ValueError(f"train.algo: choose one of {', '.join(ALGORITHMS)} (got {name!r})")
    return ALGORITHMS[name]


def default_iterations(name: str, num_envs: int, episode_steps: int) -> int:
    """The iterations a run of ``name`` with ``num_envs`` envs on episodes of ``episode_steps`` trains for
    where none are given."""
    entry = algorithm(name)
    if entry.iterations is not None:
        return entry.iterations
    from agents.es.config import default_iterations as es_iterations

    return es_iterations(num_envs, episode_steps)
