"""The settings of agents, torch-free so that the command line reads them without loading torch: how a policy
is trained (:class:`TrainConfig`, with each learner's own section) and the pipelines' presets
(:data:`BUDGETS`, trials, candidates).

Every default has its home here, in the learners' own configs (:mod:`agents.gps.config`,
:mod:`agents.es.config`, :mod:`agents.ppo.config`, :mod:`agents.apg.config`, :mod:`agents.dagger.config`) or
in the plan optimiser's (:mod:`agents.plan_optimizer.config`); the library, the command line and a run
directory's ``config.json`` all read them from there.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass, field

from agents.algorithms import (
    ALGORITHMS,
    CRITIC_HIDDEN_DIMS,
    DEFAULT_ALGORITHM,
    algorithm,
    default_iterations,
)
from agents.es.config import EsConfig
from warpcut.sim.config import PINCH_CANDIDATES
from warpcut.validation import (
    check_choice,
    check_flag,
    check_instance,
    check_integer,
    check_number,
    fail,
    is_integer,
)

SEED_RANGE = (0, 2**31 - 1 - 2**16)
"""``--seed``'s (and ``seed``'s) range: the seed and those derived from it (the seed plus an offset under
65536, e.g. validation's) stay distinct noise seeds (:data:`warpcut.sim.simulator.NOISE_SEEDS`: a larger one
would replay a small one's noise bit for bit), within the 32 bits NumPy's and torch's generators take."""

MAX_COUNT = 2**31 - 1
"""The largest count (envs, iterations, trials) a learner takes: beyond it a count overflows where it reaches
NumPy, torch or the logger, after the work has started."""

EVALUATION_TRIALS = 10
"""Seeded trials per method of an evaluation (the paper's Table I: 10)."""

VALIDATION_TRIALS = 16
"""Held-out episodes scoring a policy during training (model selection, ``best.pt``)."""

ACTIVATIONS = tuple("elu selu relu crelu lrelu tanh sigmoid softplus gelu swish mish identity".split())
"""The hidden activations of the MLPs (``TrainConfig.activation``): rsl-rl's names."""

TORCH_DEVICE = re.compile(r"cpu|cuda(:\d+)?|mps")
"""The torch devices a policy may train on (``TrainConfig.torch_device``): ``cpu``, ``cuda``, ``cuda:N``,
``mps``."""

OBS_GROUPS = {"actor": ["policy"], "critic": ["policy"]}
"""The observation groups of warpcut's env (:mod:`envs.rsl`) that feed the actor and the critic."""


@dataclass
class _TrainSettings:
    """How a policy is trained: the learner and its batch, the policy network, and model selection; each
    learner's own settings in its section (:class:`TrainConfig`)."""

    algo: str = DEFAULT_ALGORITHM
    """The learner (:data:`agents.algorithms.ALGORITHMS`): ``gps`` (the default), ``es``, ``ppo`` or
    ``apg``."""
    num_envs: int | None = None
    """Parallel envs. None: the learner's (256 for es, gps and PPO, 16 for APG)."""
    iterations: int | None = None
    """Learning iterations of the run, counting those before a resume. None: the learner's (PPO 150, APG 30;
    es as many whole cuts as PPO's 150 x 256 x 32 env steps, gps half as many, at least 10:
    :func:`agents.algorithms.default_iterations`)."""
    validation_trials: int = VALIDATION_TRIALS
    """Held-out episodes that score the deterministic policy before training and every
    ``validation_interval`` iterations; the best is the run's policy (``best.pt``). 0: no validation, the
    last policy is the run's (the paper's)."""
    validation_interval: int = 10
    """Iterations between validations."""
    selection_margin: float = 1.0
    """Model selection: a validated policy's score is its mean validation error plus this many standard
    errors of its episode-by-episode difference from the initial policy's (the same episodes); the lowest
    score is kept. 1: a trained policy must beat the initial one by more than one standard error; 0: the
    lowest mean, however noisy."""
    save_interval: int = 50
    """Save a checkpoint every this many iterations (and at the end, and on Ctrl-C)."""
    actor_hidden_dims: list[int] = field(default_factory=lambda: [32, 32])
    """Hidden layer widths of the policy MLP (the paper's 2 x 32)."""
    activation: str = "tanh"
    """Hidden activation of the MLPs (an rsl-rl name: elu, relu, tanh, ...)."""
    obs_normalization: bool = True
    """Normalise observations by their running mean and std (part of the exported policy)."""
    torch_device: str = "cpu"
    """Torch device of the policy and its updates; the simulator's Warp device is the env's own. The CPU by
    default, wherever the simulator runs: the policy is a small MLP fed NumPy observations every step."""

    def __post_init__(self) -> None:
        """Each field on its own, as it is given (a file and ``--set`` set one key at a time); what depends on
        several (the learner in its env, the population in the batch) is :meth:`check`'s."""
        where = "TrainConfig."
        if self.algo not in ALGORITHMS:
            fail(where + "algo", f"choose one of {', '.join(ALGORITHMS)}", self.algo)
        for name in ("num_envs", "iterations"):
            check_integer(
                where + name, getattr(self, name), 1, MAX_COUNT, optional=True, note="the learner's"
            )
        check_integer(
            where + "validation_trials", self.validation_trials, 0, MAX_COUNT, note="0: no validation"
        )
        for name in ("validation_interval", "save_interval"):
            check_integer(where + name, getattr(self, name), 1, MAX_COUNT)
        check_number(where + "selection_margin", self.selection_margin, 0, note="standard errors")
        dims = self.actor_hidden_dims
        if not (isinstance(dims, list | tuple) and dims and all(is_integer(d) and d >= 1 for d in dims)):
            fail(where + "actor_hidden_dims", "a non-empty list of layer widths, integers >= 1", dims)
        check_choice(where + "activation", self.activation, ACTIVATIONS)
        check_flag(where + "obs_normalization", self.obs_normalization)
        if not (isinstance(self.torch_device, str) and TORCH_DEVICE.fullmatch(self.torch_device)):
            fail(where + "torch_device", "a torch device: cpu, cuda, cuda:N or mps", self.torch_device)
        for name, kind in _SECTIONS.items():
            check_instance(where + name, getattr(self, name), kind, f"a {kind.__name__}")

    def check(self, discrete: bool | None = None) -> TrainConfig:
        """Itself, or ``ValueError`` naming what depends on several settings (each field on its own is
        checked as it is given, :meth:`__post_init__`): the learner in its env (``discrete``: whether the
        env's actions are discrete, where known) and the learner's section in the batch."""
        if discrete and algorithm(self.algo).continuous_only:
            raise ValueError(
                f"train.algo: {self.algo} plays continuous moves; set env.action_type=continuous "
                "(or train with ppo)"
            )
        self.learner.check(self.batch_size)
        return self

    @property
    def learner(self):
        """The chosen learner's section of settings (``train.ALGO``)."""
        return getattr(self, self.algo)

    @property
    def batch_size(self) -> int:
        """The envs a run trains with: ``num_envs``, or the learner's."""
        return self.num_envs if self.num_envs is not None else algorithm(self.algo).num_envs

    def total_iterations(self, episode_steps: int) -> int:
        """The iterations a run trains for on episodes of ``episode_steps``: ``iterations``, or the
        learner's."""
        if self.iterations is not None:
            return self.iterations
        return default_iterations(self.algo, self.batch_size, episode_steps)

    def to_rsl_rl(
        self,
        num_action_choices: int | None = None,
        feedback_inputs: tuple[int, int] | None = None,
        episode_steps: int | None = None,
    ) -> dict:
        """rsl-rl 5.5's ``OnPolicyRunner`` config: the network settings here, the learner's part from its
        section (:mod:`agents.algorithms`).

        Args:
            num_action_choices: Options per discrete action (the env's ``num_action_choices``); None for
                continuous actions.
            feedback_inputs: ``(start, size)`` of the tracking error in the observation
                (:func:`agents.models.feedback_inputs`); required where the learner's actor has the feedback
                path.
            episode_steps: The env's episode length (es and gps play one whole cut per env an iteration).
        """
        part = self.learner.rsl_rl(num_action_choices is not None, num_action_choices, episode_steps)
        model = {"class_name": "rsl_rl.models:MLPModel", "activation": self.activation}
        actor = dict(model)
        if self.feedback:
            if feedback_inputs is None:
                raise ValueError(
                    "feedback: the actor's feedback path needs the tracking error in the observation"
                )
            actor.update(class_name="agents.models:FeedbackMLPModel", feedback_inputs=list(feedback_inputs))
        actor.update(part.get("actor", {}))
        return {
            **part.get("own", {}),
            "num_steps_per_env": part["num_steps_per_env"],
            "save_interval": self.save_interval,
            "obs_groups": {name: list(groups) for name, groups in OBS_GROUPS.items()},
            "logger": "tensorboard",
            "actor": {
                **actor,
                "hidden_dims": list(self.actor_hidden_dims),
                "obs_normalization": self.obs_normalization,
                "distribution_cfg": part["distribution"],
            },
            "critic": {
                **model,
                "hidden_dims": list(part.get("critic_hidden_dims", CRITIC_HIDDEN_DIMS)),
                "obs_normalization": self.obs_normalization,
            },
            "algorithm": part["algorithm"],
        }

    @property
    def feedback(self) -> bool:
        """Whether the actor has the linear feedback path on the tracking error (the learner's
        ``feedback``)."""
        return bool(self.learner.feedback)


_SECTIONS = {name: entry.settings_class() for name, entry in ALGORITHMS.items()}
"""Each learner's settings class, by name: :class:`TrainConfig`'s sections."""

TrainConfig = dataclasses.make_dataclass(
    "TrainConfig",
    [(name, kind, field(default_factory=kind)) for name, kind in _SECTIONS.items()],
    bases=(_TrainSettings,),
)
TrainConfig.__module__ = __name__
TrainConfig.__doc__ = """How a policy is trained: the learner and its batch, the policy network, and model
selection (:class:`_TrainSettings`' fields); then one section per learner of the registry
(:data:`agents.algorithms.ALGORITHMS`), named after it (``es``, ``gps``, ``ppo``, ``apg``; only the chosen
one's is used): that learner's settings class (``Algorithm.settings``)."""


BUDGETS = {
    # candidates for the pinch search, of which the best rl_candidates (by fixed tension; None: all, as in
    # the paper) get a policy each; the candidates of the generalist's plan; evaluation trials
    "fast": {"candidates": 8, "generalist_candidates": 30, "rl_candidates": 1, "trials": EVALUATION_TRIALS},
    "paper": {
        "candidates": 30,
        "generalist_candidates": 30,
        "rl_candidates": None,
        "trials": EVALUATION_TRIALS,
    },
}
"""``run_pipeline``'s budgets (``warpcut run --budget``). fast: a policy for the best pinch candidate by
fixed tension, about a minute on 2 CPU cores; paper: a policy for each of the paper's 30 candidates. The
generalist, which trains nothing, chooses among the paper's 30 candidates with either budget
(``generalist_candidates``): on the 20 generated test contours +58.0% against +48.7% with 8
(docs/results.md, "The main job with the generalist")."""

DEFAULT_CONTOUR = "fls-circle"
"""The contour ``warpcut run`` cuts unless told otherwise: the FLS pattern-cutting circle."""

DEFAULT_BUDGET = "fast"
"""The budget of ``run_pipeline`` (``warpcut run``)."""

DEFAULT_SELECTOR = "rl"
"""The tensioner that chooses ``run_pipeline``'s pinch candidate."""

ANALYTIC_PINCHES = ("feasible", "centroid")
"""Where the analytic policy pinches: the centroid when it is feasible, else the feasible point nearest it
(feasible, the default); or the centroid wherever it is (centroid: the paper's literal choice)."""

EVALUATION_CANDIDATES = PINCH_CANDIDATES
"""Pinch candidates per plan in :func:`evaluate_table` (the paper's 30)."""

GENERALIST_CANDIDATES = None
"""Pinch candidates ``evaluate``'s generalist chooses among, on validation episodes: the plan's best by
fixed tension (``generalist_candidates``; None: all of them, the plan's 30; 1: the planned pinch point, as
fixed and rl pinch). All measured best on the generated validation contours: +50.3% against +48.7% with 16
and +39.8% with 8 (docs/results.md)."""

GENERALIST_GAINS = (0.5, 0.75, 1.0, 1.25, 1.5)
"""Factors on the generalist's moves it chooses among with its pinch candidate, on validation episodes
(``generalist_gains``; 1: its moves as they are; (1,): no choice, as for a generalist with discrete
moves). A policy trained over many contours pulls too hard on some and too little on others: on the 48
contours of the generated ``validation`` stream, ``evaluate``'s generalist column scored +51.6% against
+49.3% with (1,) (docs/results.md);
``experiments/generalist_gains.py`` compares sets of gains (on 28 of them, 0.35 to 1.4 did as well and
adding 2 did not help: ``--gains 0.25,0.35,0.5,0.7,1,1.4,2``)."""

GAIN_SHORTLIST = 5
"""The generalist's best candidates (its moves as they are) also tried with each other gain
(:data:`GENERALIST_GAINS`): on the same contours as good as all 30 within 0.3 points, 0.5 above the best 3,
at a third of the validation episodes of all 30 (``experiments/generalist_gains.py``)."""

GENERALIST_FINALISTS = 5
"""The generalist's best options (member, candidate, gain) per contour by their validation episodes that play
again on as many fresh ones, the lowest mean over both winning (``generalist_finalists``; 1: the best by
the validation episodes alone). The lowest of some 200 noisy means flatters its option; the finalists' fresh
episodes tell the options apart without that bias, for 40 more episodes a contour. On the first 16
contours of the generated ``validation`` stream: +62.3% against +60.9% with 1, +61.7% with 3 and +61.5%
with 10 (docs/results.md)."""


FINE_TUNING_GAIN = 0.5
"""The factor on a generalist's moves that fine-tuning (``train --set init=generalist``) starts from
(``init_gain``): es reaches the per-contour level sooner from the generalist's moves halved than from its
moves as they are (docs/results.md, "Fine-tuning"; ``scripts/fine_tuning.py --init-gain``)."""


def check_gains(gains, key: str = "generalist_gains") -> tuple[float, ...]:
    """``gains`` (:data:`GENERALIST_GAINS`'s kind) as a tuple, or ``ValueError`` naming ``key``: positive
    numbers, 1 among them (the candidates are ranked with the generalist's moves as they are)."""
    try:
        listed = tuple(float(g) for g in gains)
    except (TypeError, ValueError):
        listed = ()
    if 1.0 not in listed or any(not math.isfinite(g) or g <= 0 for g in listed):
        raise ValueError(
            f"{key}: {gains!r}: give a list of positive factors on the generalist's moves, 1 among them "
            "(e.g. [1]: its moves as they are)"
        )
    return listed


GENERALIST_CONTOURS = 48
"""Generated training contours of a generalist (``warpcut generalist --generated``)."""

GENERALIST_VALIDATION_CONTOURS = 16
"""Generated held-out contours that choose a generalist's policy (model selection)."""

GENERALIST_ITERATIONS = 150
"""es iterations of a generalist's training where none are given."""

GENERALIST_POPULATION = 32
"""es's perturbed policies a generalist iteration: each cuts every training contour."""

GENERALIST_LOOKAHEAD = 8
"""Look-ahead points a generalist observes (``env.lookahead``; :mod:`envs.observations`)."""

STUDENT_DEFAULTS = {
    "env.num_fiducials": 0,
    "train.actor_hidden_dims": [64, 64],
    "train.validation_interval": 1,
}
"""What a generalist learned from teachers (``warpcut generalist --teachers``) observes and learns with,
unless given: no fiducials (absolute positions of random material points, which let a network tell its
training contours apart rather than learn what they share), a 2 x 64 MLP, and a validation every iteration
(its best came early: 16 validation cuts against a batch of one cut per teacher; docs/results.md)."""

TEACHER_CONTOURS = 200
"""Generated contours ``warpcut teachers`` optimises a teacher for where no count is given."""


def generalist_train_config() -> TrainConfig:
    """A generalist's learner (``warpcut generalist``): es with :data:`GENERALIST_POPULATION` perturbed
    policies, each cutting every training contour, its gains scheduled on the look-ahead, larger steps on
    the MLP than one contour's es (the MLP carries the contour's shape here), validated every 5 iterations."""
    es = EsConfig(population=GENERALIST_POPULATION, sigma=0.01, learning_rate=0.003, scheduled=True)
    return TrainConfig(
        algo="es", iterations=GENERALIST_ITERATIONS, validation_interval=5, save_interval=5, es=es
    )
