"""The learners warpcut trains policies with, by name: the one registry that the settings, training, the
pipelines and the command line read (torch-free). Adding a learner is its folder and its entry here.

Each learner has its folder (``agents/NAME/``) with its settings dataclass (the ``train.NAME`` section of
:class:`agents.config.TrainConfig`) and its implementation:

- ``gps`` (:mod:`agents.gps`, the default): guided policy search from the contour's optimised plan: the
  student plays the teacher's plan as its feed-forward and learns a closed-loop correction by es, on sheets
  that differ from the nominal one;
- ``es`` (:mod:`agents.es`): evolution strategies on the policy's weights, an rsl-rl algorithm
  (``class_name`` ``agents.es.algorithm:ES``) that rsl-rl's ``OnPolicyRunner`` drives, one whole cut per env
  an iteration;
- ``ppo`` (:mod:`agents.ppo`): rsl-rl's PPO with warpcut's speed-ups and a categorical policy that starts
  by holding still;
- ``apg`` (:mod:`agents.apg`): analytic policy gradients through the differentiable simulator, on a runner
  of its own (its episodes run under ``wp.Tape``, not through the env's step);
- ``dagger`` (:mod:`agents.dagger`): supervised learning from a dataset of teachers (``warpcut teachers``) on
  the student's own states, the learner of a generalist (``warpcut generalist --teachers DIR``).

A settings class (``Algorithm.settings``) is a dataclass whose fields have defaults, with:

- ``check(num_envs=None)``: ``ValueError`` naming the first field out of range (``num_envs``: the batch, where
  the learner depends on it);
- ``feedback``: whether the actor has the linear feedback path on the tracking error
  (:class:`agents.models.FeedbackMLPModel`);
- ``rsl_rl(discrete, num_action_choices, episode_steps)``: the learner's part of rsl-rl's runner config, a
  dict with ``algorithm`` (the algorithm section), ``distribution`` (the actor's ``distribution_cfg``),
  ``num_steps_per_env``, and optionally ``critic_hidden_dims`` (default :data:`CRITIC_HIDDEN_DIMS`), ``actor``
  (entries that replace or add to the actor's section) and ``own`` (top-level sections the runner reads);
- optionally ``sheets(options)``: ``(training, validation)``, the env options the learner trains on and a list
  of those its held-out episodes are drawn from (default: the job's own for both;
  :func:`agents.training.learner_sheets`).
"""

from __future__ import annotations

import importlib
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
    """Iterations where none are given; None: whole cuts, as many as a share (:attr:`cut_budget`) of
    :data:`ENV_STEPS` (:func:`default_iterations`)."""
    action_type: str
    """The env's actions it trains with unless told otherwise: ``"discrete"`` or ``"continuous"``."""
    continuous_only: bool
    """Whether it can train only continuous actions."""
    runner: str
    """``"module:Class"`` of its runner: warpcut's rsl-rl runner (:class:`agents.runner.Runner`) or its
    own."""
    settings: str
    """``"module:Class"`` of its settings dataclass (a torch-free module): ``TrainConfig``'s section named
    after the learner (module docstring)."""
    cut_budget: float = 1.0
    """With ``iterations`` None: the share of :data:`ENV_STEPS` a run simulates in whole cuts."""
    fine_tunes: bool = False
    """Whether it can start from another run's policy (``train --set init=generalist|DIR``)."""
    fixed_sheet: str | None = None
    """Why it cannot train on randomised sheets or a relative reward, where it cannot (the refusal)."""

    def settings_class(self) -> type:
        """The class :attr:`settings` names."""
        module, _, name = self.settings.partition(":")
        return getattr(importlib.import_module(module), name)


ALGORITHMS = {
    "gps": Algorithm(
        "gps",
        "guided policy search: the contour's es-optimised plan as the feed-forward of a closed-loop policy "
        "whose correction es learns on sheets that differ",
        num_envs=256,
        iterations=None,
        action_type="continuous",
        continuous_only=True,
        runner="agents.gps.runner:GpsRunner",
        settings="agents.gps.config:GpsConfig",
        cut_budget=0.5,
    ),
    "es": Algorithm(
        "es",
        "evolution strategies on the policy (an MLP plus feedback gains on the tracking error), whole cuts "
        "ranked by the path score",
        num_envs=256,
        iterations=None,
        action_type="continuous",
        continuous_only=True,
        runner="agents.runner:Runner",
        settings="agents.es.config:EsConfig",
        fine_tunes=True,
    ),
    "ppo": Algorithm(
        "ppo",
        "rsl-rl's PPO: 1 mm moves from a categorical policy that starts by holding still, a dense reward",
        num_envs=256,
        iterations=150,
        action_type="discrete",
        continuous_only=False,
        runner="agents.runner:Runner",
        settings="agents.ppo.config:PpoConfig",
    ),
    "apg": Algorithm(
        "apg",
        "analytic policy gradients: the path surrogate's gradient through the differentiable simulator",
        num_envs=16,
        iterations=30,
        action_type="continuous",
        continuous_only=True,
        runner="agents.apg.runner:ApgRunner",
        settings="agents.apg.config:ApgConfig",
        fixed_sheet="env.randomize: APG differentiates one fixed sheet; train with es or ppo (--algo)",
    ),
    "dagger": Algorithm(
        "dagger",
        "DAgger from a teacher dataset (warpcut teachers): the student regresses onto its teachers' moves on "
        "its own states",
        num_envs=16,
        iterations=20,
        action_type="continuous",
        continuous_only=True,
        runner="agents.runner:Runner",
        settings="agents.dagger.config:DaggerConfig",
    ),
}
"""Every learner, the default first."""

DEFAULT_ALGORITHM = "gps"
"""The learner ``train``, ``run`` and ``evaluate`` use unless told otherwise: the best measured on the suite
(docs/results.md)."""


ENV_STEPS = 150 * 256 * 32
"""The env steps a run of whole cuts (es, gps) simulates where no iterations are given, times its
:attr:`Algorithm.cut_budget`: as many as PPO's default run simulates (150 iterations x 256 envs x 32 steps =
1,228,800). Such an iteration plays whole cuts, 41 to 380 steps on the suite, so a fixed count of iterations
would cost eight times more on the longest contour than on the shortest."""

MIN_ITERATIONS = 10
"""The fewest iterations :func:`default_iterations` gives a run of whole cuts (one validation after the
initial one)."""

CRITIC_HIDDEN_DIMS = (64, 64)
"""Hidden layer widths of the value MLP that rsl-rl's runner builds beside every actor (PPO trains it; the
others leave it untouched)."""

DETERMINISTIC_GAUSSIAN = {"class_name": "rsl_rl.modules:GaussianDistribution", "init_std": 1.0}
"""The actor's distribution for learners that play its deterministic output (the Gaussian's mean): kept so
that the actor, its checkpoints and its exports are those of a continuous PPO policy."""


def algorithm(name: str) -> Algorithm:
    """The registry's entry for ``name``; ``ValueError`` naming ``algo`` for an unknown one."""
    if name not in ALGORITHMS:
        raise ValueError(f"train.algo: choose one of {', '.join(ALGORITHMS)} (got {name!r})")
    return ALGORITHMS[name]


def default_iterations(name: str, num_envs: int, episode_steps: int) -> int:
    """The iterations a run of ``name`` with ``num_envs`` envs on episodes of ``episode_steps`` trains for
    where none are given: the learner's ``iterations``, or ``cut_budget`` of :data:`ENV_STEPS` over
    ``num_envs`` whole cuts of ``episode_steps``, at least :data:`MIN_ITERATIONS`."""
    entry = algorithm(name)
    if entry.iterations is not None:
        return entry.iterations
    return max(MIN_ITERATIONS, round(entry.cut_budget * ENV_STEPS / (num_envs * episode_steps)))
