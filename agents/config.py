"""The settings of agents that the command line reads without loading torch: PPO's
:class:`TrainConfig` and the pipelines' presets (:data:`RECIPE`, :data:`BUDGETS`, ...)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from warpcut.sim.config import PINCH_CANDIDATES, RANDOMIZE_ALIASES, randomize_ranges

ALGORITHMS = ("ppo", "apg", "es")
"""How ``warpcut train`` learns: PPO (rsl-rl), analytic policy gradients through the simulator, or evolution
strategies on the policy's weights."""

CONTINUOUS_ALGORITHMS = ("apg", "es")
"""The algorithms that play continuous moves only (``--actions continuous``, their default)."""


@dataclass
class TrainConfig:
    """PPO training settings; :meth:`to_rsl_rl` turns them into rsl-rl's nested config dict."""

    num_envs: int = 256
    """Parallel envs; must equal the env's ``num_envs`` (the caller builds the env with it). 256: on the
    Table I suite, two seeds of 256 envs x 75 iterations kept a trained policy on 15-16 contours of 26 and
    averaged +41.1-41.6%, against 10-14 and +40.1% for 64 envs x 150 in as much wall time; PPO's fixed
    costs per step are spread over four times the envs (docs/learning.md, "Table I"; docs/performance.md,
    section 6)."""
    algorithm: str = "ppo"
    """"ppo" (rsl-rl's PPO), "apg": analytic policy gradients through the differentiable simulator
    (:mod:`agents.apg`), or "es": evolution strategies on the actor's weights (:mod:`agents.es`). APG and es
    play continuous actions, one whole episode per env and iteration, so ``num_steps_per_env`` does not
    apply."""
    apg_window: int | None = 5
    """APG only: truncate the gradient to windows of this many env steps (:meth:`~warpcut.gradients.
    DifferentiableRollout.backward`); None: through the whole episode (docs/learning.md, "APG")."""
    apg_accept: bool = False
    """APG only: keep a step only if it lowers the iteration's mean path error on the same episodes (run
    again with the new weights: the same noise and fiducials); otherwise revert it (weights and Adam's
    state) and halve the step size; a kept step grows it by 1.5, up to ``learning_rate``. The observation
    normaliser then learns from each iteration's observations after the step, not during the rollout
    (docs/learning.md, "APG that keeps only steps that help")."""
    es_population: int = 64
    """es only: perturbed policies per iteration, in antithetic pairs; each plays ``num_envs /
    es_population`` episodes (256 envs: 4 each)."""
    es_sigma: float = 0.005
    """es only: the perturbations' standard deviation in weight space for the MLP (the actor's output is in
    units of ``max_step_mm``). 0.005: a perturbed MLP moves the grasp by a near-constant bias that adds up
    over the episode, so with 0.05 the perturbed population cut e-shape at 80.6 vertices where its centre
    (the still grasp) cut 43.3 and es learned nothing on long contours; 0.005 gave 52.3 (docs/learning.md,
    "es with separate steps for the feedback path"). An MLP without the feedback path learns alone and takes
    :data:`ES_PLAIN_NETWORK`'s σ instead (:func:`algorithm_settings`, what ``warpcut train`` uses)."""
    es_feedback_sigma: float = 0.1
    """es only, with ``actor_feedback``: the perturbations' standard deviation for the feedback gains (they
    act on the normalised tracking error, and useful gains are ~0.5-1). 0.1: with the normaliser learned
    before the first population, 0.25 (session 25's) left the population's mean error far above the still
    grasp's on short-error contours, and validation kept the still grasp more often (docs/learning.md, "The
    normaliser's first iteration")."""
    es_feedback_learning_rate: float = 0.1
    """es only, with ``actor_feedback``: Adam's step for the feedback gains (``learning_rate``: the MLP's)."""
    iterations: int | None = 150
    """Total learning iterations of the run, counting those done before a resume. 150: on the Table I suite,
    two seeds of 256 envs x 150 iterations (5 epochs) kept a trained policy on 17-18 contours of 26 at RL
    +43.0-43.3%, against 15-16 and +41.1-41.6% with 75; 50-59 s a contour on this 2-core CPU, at the edge of
    issue 16's 60 s (docs/learning.md, "Table I"). None: the algorithm's default for the env (es: as many
    whole cuts as PPO's default run simulates env steps, :func:`es_iterations`)."""
    seed: int = 0
    """Seed of Python, NumPy, torch and the env (``env.seed``)."""
    torch_device: str = "cpu"
    """Torch device of the policy and the PPO update; the simulator's Warp device is the env's own
    (``PatternCutOptions.device``). The CPU by default, wherever the simulator runs: the policy is a 2 x 32
    MLP and its observations arrive as NumPy arrays each step."""
    discrete: bool = True
    """Categorical actions (the paper's 1 mm moves) if True, else a Gaussian over continuous actions."""
    actor_hidden_dims: list[int] = field(default_factory=lambda: [32, 32])
    """Hidden layer widths of the policy MLP (paper: 2 x 32)."""
    critic_hidden_dims: list[int] = field(default_factory=lambda: [64, 64])
    """Hidden layer widths of the value MLP."""
    actor_feedback: bool = False
    """Add a linear map of the observed tracking error to the policy MLP's output, zero at the start
    (:class:`agents.models.FeedbackMLPModel`: es's feedback gains inside the network; needs the contour
    features). The ``es`` recipe's: at es's default budget on issue 16's six contours, validation kept a
    trained policy on 5 of 6 with it and on 2 of 6 without; on the suite +49.4% against +45.5%
    (docs/learning.md, "es with a feedback path on the tracking error")."""
    activation: str = "tanh"
    """Hidden activation of both MLPs (an rsl-rl name: elu, relu, tanh, ...)."""
    obs_normalization: bool = True
    """Normalize observations by running mean and std (part of the exported policy)."""
    obs_groups: dict[str, list[str]] = field(
        default_factory=lambda: {"actor": ["policy"], "critic": ["policy"]}
    )
    """Observation groups of the env that feed the actor and the critic."""
    init_noise_std: float = 1.0
    """Initial action standard deviation (continuous only), in the env's action units."""
    num_steps_per_env: int = 32
    """Env steps per env per iteration; an iteration collects ``num_envs * num_steps_per_env`` steps."""
    num_learning_epochs: int = 3
    """Passes over each rollout. 3 (rsl-rl's usual 5 until session 31): the update's cost is nearly
    proportional to it (at 256 envs 112 → 66 ms an update, of an iteration of ~330), and the adaptive
    schedule keeps each update's KL near ``desired_kl`` either way. On the Table I suite at two seeds 3 epochs
    gave RL +44.1% and +43.6%, trained policies kept on 19 and 18 contours, against 5's +43.0% and +43.3%,
    17 and 18; PPO's rate rose from 45% to 51.5% of the simulator's in alternating runs (docs/learning.md,
    "Table I with 3 PPO epochs"; docs/performance.md, section 6)."""
    num_mini_batches: int = 4
    """Mini-batches per pass."""
    learning_rate: float = 1e-3
    """Adam step size (initial value when ``schedule`` is "adaptive")."""
    schedule: str = "adaptive"
    """"adaptive": scale the learning rate to keep the KL per update near ``desired_kl``; "fixed": don't."""
    desired_kl: float = 0.01
    """Target KL divergence between successive policies for the adaptive schedule."""
    entropy_coef: float = 0.03
    """Entropy bonus weight. warpcut's recipe: 0.03 keeps PPO exploring moves away from the "stay" prior
    (0.01, rsl-rl's usual value, and 0.1 both kept the still initial policy more often; docs/learning.md,
    "Recipes that learn motion")."""
    gamma: float = 0.99
    """Discount per env step."""
    lam: float = 0.95
    """GAE lambda."""
    clip_param: float = 0.2
    """PPO ratio clip (also the value clip)."""
    value_loss_coef: float = 1.0
    """Value loss weight."""
    max_grad_norm: float = 1.0
    """Gradient norm clip."""
    save_interval: int = 50
    """Save a checkpoint every this many iterations (and at the end, and on Ctrl-C)."""
    stay_prior: float = 0.9
    """Discrete only: initial probability of action 0, the others sharing the rest; the initial
    deterministic policy then takes action 0. For warpcut's env action 0 is "stay" (hold the grasp still,
    what fixed tensioning does), so PPO learns moves on top of holding still (warpcut's recipe,
    docs/learning.md). 0: start uniform over the actions (the paper's setting)."""
    validation_interval: int = 10
    """With a ``validate`` callback (see :func:`train`): score the deterministic policy every this many
    iterations and keep the best in ``best.pt``."""
    selection_margin: float = 1.0
    """Model selection: a validated policy's score is its mean validation error plus this many standard
    errors of its episode-by-episode difference from the initial policy's (the same held-out episodes), and
    the lowest score is kept. 1: a trained policy must beat the initial one by more than one standard
    error; 0: the lowest mean, however noisy (docs/learning.md, "Model selection")."""

    def check_algorithm(self) -> None:
        """``ValueError`` naming ``algorithm`` unless it is known and fits the actions."""
        if self.algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm: choose one of {', '.join(ALGORITHMS)} (got {self.algorithm!r})")
        if self.algorithm in CONTINUOUS_ALGORITHMS and self.discrete:
            raise ValueError(
                f"algorithm: {self.algorithm} plays continuous moves; set discrete=False "
                "(--actions continuous)"
            )

    def to_rsl_rl(
        self, num_action_choices: int | None = None, feedback_inputs: tuple[int, int] | None = None
    ) -> dict:
        """Return rsl-rl 5.5.1's ``OnPolicyRunner`` config.

        Args:
            num_action_choices: Options per discrete action (the env's ``num_action_choices``); required
                when ``discrete``.
            feedback_inputs: ``(start, size)`` of the tracking error in the observation
                (:func:`agents.models.feedback_inputs`); required with ``actor_feedback``.
        """
        if self.discrete:
            if num_action_choices is None:
                raise ValueError("discrete training needs the env's num_action_choices")
            distribution = {
                "class_name": "agents.distributions:Categorical",
                "num_choices": num_action_choices,
            }
            if self.stay_prior > 0:
                distribution.update(init_choice=0, init_choice_prob=self.stay_prior)
        else:
            distribution = {
                "class_name": "rsl_rl.modules:GaussianDistribution",
                "init_std": self.init_noise_std,
            }
        model = {"class_name": "rsl_rl.models:MLPModel", "activation": self.activation}
        actor = dict(model)
        if self.actor_feedback:
            if feedback_inputs is None:
                raise ValueError("actor_feedback needs the tracking error's place in the observation")
            actor.update(class_name="agents.models:FeedbackMLPModel", feedback_inputs=list(feedback_inputs))
        own = {
            "apg": {"apg": {"window": self.apg_window, "accept": self.apg_accept}},
            "es": {
                "es": {
                    "population": self.es_population,
                    "sigma": self.es_sigma,
                    "feedback_sigma": self.es_feedback_sigma,
                    "feedback_learning_rate": self.es_feedback_learning_rate,
                }
            },
        }.get(self.algorithm, {})
        return {
            **own,
            "num_steps_per_env": self.num_steps_per_env,
            "save_interval": self.save_interval,
            "obs_groups": {name: list(groups) for name, groups in self.obs_groups.items()},
            "logger": "tensorboard",
            "actor": {
                **actor,
                "hidden_dims": list(self.actor_hidden_dims),
                "obs_normalization": self.obs_normalization,
                "distribution_cfg": distribution,
            },
            "critic": {
                **model,
                "hidden_dims": list(self.critic_hidden_dims),
                "obs_normalization": self.obs_normalization,
            },
            "algorithm": {
                "class_name": "rsl_rl.algorithms:PPO",
                "num_learning_epochs": self.num_learning_epochs,
                "num_mini_batches": self.num_mini_batches,
                "learning_rate": self.learning_rate,
                "schedule": self.schedule,
                "desired_kl": self.desired_kl,
                "entropy_coef": self.entropy_coef,
                "gamma": self.gamma,
                "lam": self.lam,
                "clip_param": self.clip_param,
                "value_loss_coef": self.value_loss_coef,
                "max_grad_norm": self.max_grad_norm,
            },
        }


EVALUATION_TRIALS = 10
"""Seeded trials per method of an evaluation (the paper's Table I: 10)."""

VALIDATION_TRIALS = 16
"""Held-out episodes scoring a policy during training (model selection, ``best.pt``); 0 turns it off."""

RECIPE = {"dense_reward": True, "contour_features": True, "allow_z": True, "action_type": "discrete"}
"""warpcut's learning recipe, as :class:`~envs.options.PatternCutOptions` fields: dense cut-deviation
shaping, contour-aware observations and x-y-z moves; with :class:`~agents.train.TrainConfig`'s defaults
(the initial policy holds still with probability ``stay_prior``) and validation-based model selection.
``warpcut train``, ``evaluate`` and ``run`` use it; docs/learning.md has the measurements behind each
choice. The paper's setting is the env's defaults (sparse reward, fiducials only, x-y moves) with
``stay_prior=0`` and no validation."""


@dataclass(frozen=True)
class Recipe:
    """How a pipeline trains a tensioner: the env's observations, actions and reward, PPO's settings beyond
    the batch and the budget, and model selection."""

    options: dict
    """:class:`~envs.options.PatternCutOptions` fields (reward, observations, actions)."""
    train: dict = field(default_factory=dict)
    """:class:`TrainConfig` fields (not ``num_envs``, ``iterations``, ``seed``: the budget's)."""
    validation_trials: int = VALIDATION_TRIALS
    """Held-out episodes per validation; 0: no validation, the last policy is the run's."""
    base_plan: str | None = None
    """``"grad"``: each contour's policy acts on top of the open-loop plan the gradient optimiser finds at
    its pinch point (the ``grad`` column's plan, :func:`agents.gradient.cached_plan`; the env's
    ``base_plan``), so PPO (``grad-residual``) or APG (``apg-residual``) learns a residual on it and its
    "stay" plays the plan (both also observe the plan's move, ``observe_plan``). None: the policy's moves
    alone."""

    @property
    def batch(self) -> dict[str, int]:
        """The envs and iterations it trains with unless told otherwise: its algorithm's
        (:func:`batch_defaults`)."""
        return batch_defaults(self.train.get("algorithm", TrainConfig.algorithm))


APG_FIXED_SHEET = "randomize: APG differentiates one fixed sheet; train with PPO (--algo ppo)"
"""Why APG refuses domain randomisation and a relative reward (:class:`agents.apg.ApgRunner`, the CLI)."""

SHARED_BASE_PLAN = (
    "shared-policy: a recipe on a base plan (grad-residual) trains a policy per pinch candidate, each on its "
    "own candidate's plan; drop --shared-policy or choose another --recipe"
)
"""Why a shared policy refuses a recipe with a ``base_plan`` (``agents.pipeline.run_pipeline``, the CLI)."""

APG_BATCH = {"num_envs": 16, "iterations": 30}
"""APG's envs and iterations where none are given (Table I's APG column, docs/learning.md): PPO's 256 x 150
would train APG for about an hour and a half a contour (an APG iteration at 256 envs took 35 s here)."""


def es_population_error(population: int, num_envs: int) -> str | None:
    """Why ``es_population`` does not fit ``num_envs`` (it must be even, antithetic pairs, and divide the
    envs: each perturbed policy plays as many episodes), with a population that would; None if it fits."""
    if population >= 2 and population % 2 == 0 and num_envs % population == 0:
        return None
    fits = max((p for p in range(2, min(num_envs, 64) + 1, 2) if num_envs % p == 0), default=None)
    fix = f"e.g. --es-population {fits}" if fits else "give an even --num-envs"
    return (
        f"es_population: {population} must be even (antithetic pairs) and divide num_envs ({num_envs}); {fix}"
    )


ES_BATCH = {"num_envs": 256, "iterations": None}
"""es's envs and iterations where none are given: 64 perturbed policies x 4 episodes, one whole cut each, an
iteration; as many iterations as :func:`es_iterations` gives for the contour (resolved by
:func:`agents.train.train`, where the episode's length is known)."""

ES_ENV_STEPS = TrainConfig.iterations * TrainConfig.num_envs * TrainConfig.num_steps_per_env
"""es's env steps per policy where no iterations are given: PPO's default run's (150 x 256 x 32 =
1,228,800). An es iteration plays whole cuts, 41 to 380 steps on the suite, so a fixed count of them would
cost eight times more on the longest contour than on the shortest."""

ES_MIN_ITERATIONS = 10
"""The fewest iterations :func:`es_iterations` gives (one validation after the initial one)."""


def default_iterations(algorithm: str, env) -> int:
    """The iterations a run of ``algorithm`` on ``env`` (warpcut's rsl-rl env) trains for where none are
    given: :func:`es_iterations` of its episode for es, :func:`batch_defaults`' otherwise."""
    if algorithm == "es":
        return es_iterations(env.num_envs, env.env.scene.task.num_steps)
    return int(batch_defaults(algorithm)["iterations"])


def iterations_text(iterations: int | None) -> str:
    """``iterations`` for the logs: ``"150 iterations"``, or for None es's rule (:func:`es_iterations`)."""
    return f"{iterations} iterations" if iterations is not None else "iterations for PPO's env steps"


def es_iterations(num_envs: int, episode_steps: int) -> int:
    """es's default iterations: :data:`ES_ENV_STEPS` over ``num_envs`` whole cuts of ``episode_steps``,
    at least :data:`ES_MIN_ITERATIONS`."""
    return max(ES_MIN_ITERATIONS, round(ES_ENV_STEPS / (num_envs * episode_steps)))


def batch_defaults(algorithm: str) -> dict[str, int]:
    """``{"num_envs": ..., "iterations": ...}`` a run of ``algorithm`` (:data:`ALGORITHMS`) trains with unless
    told otherwise: :class:`TrainConfig`'s for PPO, :data:`APG_BATCH` for APG, :data:`ES_BATCH` for es."""
    if algorithm in ("apg", "es"):
        return dict({"apg": APG_BATCH, "es": ES_BATCH}[algorithm])
    return {"num_envs": TrainConfig.num_envs, "iterations": TrainConfig.iterations}


APG_LEARNING_RATE = 3e-3
"""Adam's step of the ``apg`` recipe (APG's gradients are clipped to ``max_grad_norm``; docs/learning.md)."""

APG_RESIDUAL_LEARNING_RATE = 1e-3
"""Adam's step of the ``apg-residual`` recipe: on fls-circle's plan 3e-3 left the plan within 5 iterations and
diverged, 3e-4 did not move it, 1e-3 improved wave-1 and wave-2's plans (docs/learning.md)."""

ES_LEARNING_RATE = 0.001
"""Adam's step of the ``es`` recipe for the MLP's weights, in weight space: small, so the MLP stays near "hold
still" while the feedback gains learn (``TrainConfig.es_feedback_learning_rate``; docs/learning.md, "es with
separate steps for the feedback path")."""

ES_PLAIN_NETWORK = {"es_sigma": 0.05, "learning_rate": 0.01}
"""es on an actor without the feedback path (a policy that observes no tracking error, or a run trained before
the path): the MLP is all that learns, so it keeps session 22's σ and Adam step (on issue 16's six contours σ
0.05 gave +46.9% against +44.0% with 0.02; docs/learning.md, "es on the neural policy")."""

RECIPES = {
    "warpcut": Recipe(
        RECIPE, {"stay_prior": TrainConfig.stay_prior, "entropy_coef": TrainConfig.entropy_coef}
    ),
    "paper": Recipe(
        {"dense_reward": False, "contour_features": False, "allow_z": False, "action_type": "discrete"},
        {"stay_prior": 0.0},
        validation_trials=0,
    ),
    "apg": Recipe(
        {**RECIPE, "action_type": "continuous"}, {"algorithm": "apg", "learning_rate": APG_LEARNING_RATE}
    ),
    "es": Recipe(
        {**RECIPE, "action_type": "continuous"},
        {"algorithm": "es", "learning_rate": ES_LEARNING_RATE, "actor_feedback": True},
    ),
    "grad-residual": Recipe(
        {**RECIPE, "observe_plan": True},
        {"stay_prior": TrainConfig.stay_prior, "entropy_coef": TrainConfig.entropy_coef},
        base_plan="grad",
    ),
    "apg-residual": Recipe(
        {**RECIPE, "action_type": "continuous", "observe_plan": True},
        {"algorithm": "apg", "learning_rate": APG_RESIDUAL_LEARNING_RATE},
        base_plan="grad",
    ),
}
"""``--recipe``: warpcut's (:data:`RECIPE`, the default) or the paper's setting (sparse reward, 12
fiducials observed, x-y moves of 1 mm, a uniform initial policy, the last policy kept)."""


def algorithm_settings(algorithm: str, feedback: bool | None = None) -> dict:
    """The :class:`TrainConfig` fields ``warpcut train --algo ALGORITHM`` trains with beyond its flags: those
    of the recipe of that name (``apg``, ``es``: their learning rates), warpcut's for PPO. ``feedback``:
    whether the actor gets the feedback path (None: the recipe's choice); es without it learns with the MLP
    alone, so it takes :data:`ES_PLAIN_NETWORK`'s σ and step."""
    settings = dict(RECIPES["warpcut" if algorithm == "ppo" else algorithm].train)
    if feedback is not None:
        settings["actor_feedback"] = feedback
    if algorithm == "es" and not settings.get("actor_feedback", False):
        settings.update(ES_PLAIN_NETWORK)
    return settings


BUDGETS = {
    # candidates for the pinch search, of which the best rl_candidates (by fixed tension; None: all, as in
    # the paper) get a PPO policy each; PPO iterations per policy; evaluation trials
    "fast": {"candidates": 8, "rl_candidates": 2, "iterations": 60, "trials": EVALUATION_TRIALS},
    "paper": {"candidates": 30, "rl_candidates": None, "iterations": 200, "trials": EVALUATION_TRIALS},
}
"""``run_pipeline``'s budgets (``warpcut run --budget``)."""

DEFAULT_CONTOUR = "fls-circle"
"""The contour ``warpcut run`` cuts unless told otherwise: the FLS pattern-cutting circle."""

DEFAULT_BUDGET = "fast"
"""The budget of ``run_pipeline`` (``warpcut run``): about a minute on 2 CPU cores (README)."""

DEFAULT_SELECTOR = "rl"
"""The tensioner that chooses ``run_pipeline``'s pinch candidate."""

ANALYTIC_PINCHES = ("feasible", "centroid")
"""Where the analytic policy pinches: the centroid when it is feasible, else the feasible point nearest it
(feasible, the default); or the centroid wherever it is (centroid: the paper's literal choice)."""

EVALUATION_CANDIDATES = PINCH_CANDIDATES
"""Pinch candidates per plan in :func:`evaluate_table` (the paper's 30)."""


@dataclass(frozen=True)
class GradConfig:
    """Gradient-based tensioning (:mod:`agents.gradient`): Adam on an open-loop plan of grasp moves (and
    optionally the pinch point) through the differentiable simulator (:mod:`warpcut.gradients`)."""

    estimator: str = "tape"
    """How each step's gradient is estimated. "tape": the path surrogate's gradient through ``wp.Tape``
    (:mod:`warpcut.gradients`), over ``trials`` episodes. "es": evolution strategies, the gradient of the path
    score itself smoothed by Gaussian perturbations of the plan (``es_population`` perturbed plans, antithetic
    pairs, ``es_trials`` episodes each, ranked; forward passes only, one batch a step). docs/learning.md,
    "Evolution strategies through the batched simulator"."""
    iterations: int = 20
    """Adam steps (tape: each one forward and one backward pass of ``trials`` episodes; es: one batch of
    ``es_population x es_trials`` episodes)."""
    trials: int = 8
    """Noisy episodes per step of the tape estimator, the same seeds every step (the expected surrogate over
    them is minimised); their noise is not the evaluation's (seed ``seed + GRAD_SEED_OFFSET``)."""
    es_population: int = 64
    """Perturbed plans per step of the es estimator (an even number: antithetic pairs)."""
    es_trials: int = 2
    """Noisy episodes per perturbed plan (es), the same seeds every step, not the evaluation's."""
    es_sigma_mm: float = 0.3
    """Standard deviation of the es estimator's perturbation of each move (mm) and of each feedback gain
    (mm of move per mm of tracking error)."""
    es_feedback_phases: int = 0
    """es: 0 optimises an open-loop plan. P > 0 adds feedback, a closed-loop policy: every step's move is the
    plan's plus ``K @ e``, ``e`` the x-y tracking error (mm; the vector from the scissor tip to the contour
    point it is about to cut, as it lies on the moved sheet, what the analytic controller opposes) and ``K``
    a 3 x 2 gain matrix, one per phase (the episode split into P equal parts), optimised with the plan from
    zero (docs/learning.md, "Closed loop: es on feedback gains")."""
    es_feedback_only: bool = False
    """es with feedback: True keeps the plan at zero and optimises only the gains, a policy that holds still
    where the sheet does not move from where the scissors expect it (docs/robustness.md, "es policies")."""
    es_feedback_sag: bool = False
    """es with feedback: the gains are scheduled on the sheet's sag. Each phase's matrix is 3 x 4, acting on
    ``[e, s e]``, ``s`` how far the sheet hangs before the cut (:func:`agents.gradient.sheet_sag`: 0 on a
    sheet without gravity, ~1.2 on the default one). On a flat sheet only the first half acts, so es over
    randomised sheets can learn a policy that holds still there (docs/robustness.md, "Gains scheduled on
    the sag")."""
    es_randomize: str = ""
    """es: physical parameters drawn anew at every step for the ``es_trials`` episodes (comma-separated names
    of :data:`warpcut.sim.config.RANDOMIZE_RANGES`, over their ranges; every perturbed plan cuts the same
    draws). Each episode's error is then weighed by the nominal sheet's no-tension error over its own
    (:class:`warpcut.task.NoTensionReference`, as ``relative_reward`` does), and the validation episodes
    draw theirs too (seeded, the same every iterate). Empty: the nominal sheet."""
    es_randomize_ranges: dict[str, list[float]] | None = None
    """es: the range of a randomised parameter, ``{name: [low, high]}`` in its units, where it differs from
    :data:`warpcut.sim.config.RANDOMIZE_RANGES` (``warpcut optimize --randomize-range``); None: the
    defaults."""
    learning_rate: float = 0.3
    """Adam's step (mm per grasp move); moves are projected back onto ``max_step_mm`` per axis."""
    validation_trials: int = 8
    """Held-out noisy episodes every iterate is scored on (path score); the best is kept. 0: keep the
    iterate with the lowest error on the optimiser's own episodes."""
    window: int | None = 10
    """Truncate the gradient to windows of this many env steps (a move answers only for the surrogate's
    terms up to its window's end: lower variance on a chaotic sheet, some bias); None: the whole episode.
    10 steps and a step of 0.3 mm did best of the settings tried on 12 contours (docs/learning.md)."""
    optimize_pinch: bool = False
    """Also move the pinch point along its gradient (the grasped set held fixed per step), staying
    feasible."""
    pinch_learning_rate: float = 1.0
    """Adam's step for the pinch point (mm)."""

    def validated(self) -> GradConfig:
        """Itself, or ``ValueError`` naming the field and the fix."""
        if self.estimator not in GRAD_ESTIMATORS:
            names = ", ".join(GRAD_ESTIMATORS)
            raise ValueError(f"estimator: must be one of {names} (got {self.estimator!r})")
        for name in ("iterations", "trials", "es_population", "es_trials"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"{name}: must be a positive integer (got {value!r})")
        if self.es_population % 2:
            raise ValueError(f"es_population: must be even, antithetic pairs (got {self.es_population})")
        if self.estimator == "es" and self.optimize_pinch:
            raise ValueError("optimize_pinch: the pinch point moves only with estimator 'tape'; drop one")
        phases = self.es_feedback_phases
        if not isinstance(phases, int) or isinstance(phases, bool) or phases < 0:
            raise ValueError(f"es_feedback_phases: must be an integer >= 0, 0 for open loop (got {phases!r})")
        try:
            chosen = randomize_ranges(self.es_randomize, self.es_randomize_ranges)
        except ValueError as error:
            field = "es_randomize_ranges" if str(error).startswith("randomize_ranges") else "es_randomize"
            raise ValueError(f"{field}: {str(error).split(': ', 1)[1]}") from None
        for name in ("es_feedback_only", "es_feedback_sag"):
            if getattr(self, name) and not self.es_feedback_phases:
                raise ValueError(f"{name}: there are no gains to optimise; give es_feedback_phases >= 1")
        closed_loop = {
            "es_feedback_phases": self.es_feedback_phases,
            "es_feedback_only": self.es_feedback_only,
            "es_feedback_sag": self.es_feedback_sag,
            "es_randomize": self.es_randomize,
        }
        for name, value in closed_loop.items():
            if value and self.estimator != "es":
                raise ValueError(f"{name}: only estimator 'es' has it; use estimator 'es', or drop {name}")
        if self.estimator == "es" and self.validation_trials == 0:
            raise ValueError(
                "validation_trials: estimator 'es' scores each iterate on held-out episodes only; give at "
                f"least 1 (got {self.validation_trials!r})"
            )
        if not isinstance(self.validation_trials, int) or self.validation_trials < 0:
            raise ValueError(f"validation_trials: must be an integer >= 0 (got {self.validation_trials!r})")
        if self.window is not None and (not isinstance(self.window, int) or self.window < 1):
            raise ValueError(f"window: must be a positive number of steps or None (got {self.window!r})")
        for name in ("learning_rate", "pinch_learning_rate", "es_sigma_mm"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and 0 < value < float("inf")):
                raise ValueError(f"{name}: must be a positive number of mm (got {value!r})")
        if self.es_randomize_ranges:  # one spelling, lists of floats, so a saved run's settings compare equal
            names = [RANDOMIZE_ALIASES.get(k, k) for k in self.es_randomize_ranges]
            canonical = {k: list(chosen[k]) for k in names}
            if canonical != self.es_randomize_ranges:
                return dataclasses.replace(self, es_randomize_ranges=canonical)
        return self


GRAD_CONFIGS = {
    "tape": GradConfig(),
    "es": GradConfig(estimator="es", iterations=40, learning_rate=0.1),
}
"""The optimiser's defaults per estimator (library and command line). es: 40 steps of 0.1 mm, on fls-circle
and kidney +74.6% and +55.3% against +75.3% and +48.9% with 20 steps of 0.3 mm (docs/learning.md)."""

GRAD_ESTIMATORS = tuple(GRAD_CONFIGS)
"""How the plan optimiser may estimate its gradient (``GradConfig.estimator``): "tape" or "es"."""


def grad_config(estimator: str = "tape", **overrides) -> GradConfig:
    """``estimator``'s defaults (:data:`GRAD_CONFIGS`) with the ``overrides`` that are not None (the CLI's
    options left unset are None), validated."""
    base = GRAD_CONFIGS.get(estimator, GradConfig(estimator=estimator))  # unknown: validated() names it
    given = {k: v for k, v in overrides.items() if v is not None}
    return dataclasses.replace(base, **given).validated()


GRAD_CONFIG = GRAD_CONFIGS["tape"]
"""The optimiser's defaults (library and command line): the tape estimator's."""

GRAD_SEED_OFFSET = 4241
"""The gradient optimiser's episodes use seed ``seed + GRAD_SEED_OFFSET``: never the evaluation's noise."""
