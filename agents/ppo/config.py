"""PPO's settings (torch-free, so the command line reads them without loading torch)."""

from __future__ import annotations

from dataclasses import dataclass, field

from agents.algorithms import CRITIC_HIDDEN_DIMS
from warpcut.validation import ConfigError, check_flag, is_integer, is_number, shown


@dataclass
class PpoConfig:
    """rsl-rl's PPO with warpcut's recipe: a categorical policy over stay / +-x / +-y / +-z that starts by
    holding still, an entropy bonus that keeps it exploring, 3 passes of 4 minibatches an update.

    ``num_envs`` and ``iterations`` are :class:`~agents.config.TrainConfig`'s (PPO's default batch: 256 envs x
    150 iterations). docs/results.md, "Why the defaults are what they are", has the measurements behind each
    choice.
    """

    num_steps_per_env: int = 32
    """Env steps per env per iteration; an iteration collects ``num_envs * num_steps_per_env`` steps."""
    num_learning_epochs: int = 3
    """Passes over each rollout. rsl-rl's usual 5 cost two thirds more per update and learned no better on the
    suite (the adaptive schedule keeps each update's KL near ``desired_kl`` either way)."""
    num_mini_batches: int = 4
    """Mini-batches per pass."""
    learning_rate: float = 1e-3
    """Adam's step size (its initial value under the adaptive schedule)."""
    schedule: str = "adaptive"
    """``"adaptive"``: scale the learning rate to keep each update's KL near ``desired_kl``; ``"fixed"``."""
    desired_kl: float = 0.01
    """Target KL divergence between successive policies for the adaptive schedule."""
    entropy_coef: float = 0.03
    """Entropy bonus weight: 0.03 keeps PPO exploring away from the "stay" prior; rsl-rl's usual 0.01 and 0.1
    kept the still initial policy more often."""
    gamma: float = 0.99
    """Discount per env step."""
    lam: float = 0.95
    """GAE lambda."""
    clip_param: float = 0.2
    """PPO's ratio clip (also the value clip)."""
    value_loss_coef: float = 1.0
    """Value loss weight."""
    max_grad_norm: float = 1.0
    """Gradient norm clip."""
    stay_prior: float = 0.9
    """Discrete actions only: the initial probability of action 0 ("stay": hold the grasp still, what fixed
    tensioning does), the others sharing the rest, so PPO learns moves on top of holding still. 0: a uniform
    start (the paper's)."""
    init_noise_std: float = 1.0
    """Continuous actions only: the initial action standard deviation, in the env's action units."""
    critic_hidden_dims: list[int] = field(default_factory=lambda: list(CRITIC_HIDDEN_DIMS))
    """Hidden layer widths of the value MLP."""
    feedback: bool = False
    """Give the actor the linear feedback path on the tracking error (:class:`agents.models.FeedbackMLP`),
    as es's. Off: with it PPO did no better on the suite."""

    def __post_init__(self) -> None:  # each field as it is given (a file's or --set's key at a time)
        self.check()

    def check(self, num_envs: int | None = None) -> None:
        """``ValueError`` naming the first field out of range (``num_envs``: unused)."""
        for name in ("num_steps_per_env", "num_learning_epochs", "num_mini_batches"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"train.ppo.{name}", f"must be an integer >= 1 (got {shown(value)})")
        if self.schedule not in ("adaptive", "fixed"):
            raise ConfigError("train.ppo.schedule", f"choose adaptive or fixed (got {shown(self.schedule)})")
        if not (is_number(self.stay_prior) and 0 <= self.stay_prior < 1):
            raise ConfigError("train.ppo.stay_prior", f"must be in [0, 1) (got {shown(self.stay_prior)})")
        for name in ("entropy_coef", "gamma", "lam", "value_loss_coef"):
            value = getattr(self, name)
            if not (is_number(value) and 0 <= value < float("inf")):
                raise ConfigError(f"train.ppo.{name}", f"must be a finite number >= 0 (got {shown(value)})")
        dims = self.critic_hidden_dims
        if not (isinstance(dims, list | tuple) and dims and all(is_integer(d) and d >= 1 for d in dims)):
            raise ConfigError(
                "train.ppo.critic_hidden_dims",
                f"must be a non-empty list of layer widths >= 1 (got {shown(dims)})",
            )
        check_flag("train.ppo.feedback", self.feedback)
        for name in ("learning_rate", "desired_kl", "clip_param", "max_grad_norm", "init_noise_std"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not 0 < value < float("inf"):
                raise ConfigError(f"train.ppo.{name}", f"must be a finite number > 0 (got {shown(value)})")

    def rsl_rl(
        self, discrete: bool, num_action_choices: int | None, episode_steps: int | None = None
    ) -> dict:
        """PPO's part of rsl-rl's runner config (:mod:`agents.algorithms`): the ``algorithm`` section, the
        actor's ``distribution``, the ``critic_hidden_dims`` and ``num_steps_per_env``."""
        if discrete:
            if num_action_choices is None:
                raise ValueError("discrete training needs the env's num_action_choices")
            distribution = {
                "class_name": "agents.ppo.distributions:Categorical",
                "num_choices": num_action_choices,
            }
            if self.stay_prior > 0:
                distribution.update(init_choice=0, init_choice_prob=self.stay_prior)
        else:
            distribution = {
                "class_name": "rsl_rl.modules:GaussianDistribution",
                "init_std": self.init_noise_std,
            }
        algorithm = {
            "class_name": "agents.ppo.algorithm:PPO",
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
        }
        return {
            "algorithm": algorithm,
            "distribution": distribution,
            "critic_hidden_dims": self.critic_hidden_dims,
            "num_steps_per_env": self.num_steps_per_env,
        }
