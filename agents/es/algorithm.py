"""Evolution strategies (es) on the tensioning policy's weights, as an rsl-rl algorithm: rsl-rl's
``OnPolicyRunner`` drives it (``class_name`` ``agents.es.algorithm:ES``) through the same ``act`` /
``process_env_step`` / ``compute_returns`` / ``update`` loop as PPO, one whole cut per env an iteration
(Salimans et al. 2017, "Evolution Strategies as a Scalable Alternative to Reinforcement Learning"; Mania et
al. 2018 for the observation normalisation).

Each iteration perturbs the actor's weights ``θ`` into ``population`` policies in antithetic pairs
(``θ ± σ⊙ε``; ``σ`` is ``sigma`` for the MLP's weights and ``feedback_sigma`` for the feedback gains). Env
``e`` plays policy ``e // trials`` (``trials = num_envs / population``) by its deterministic output, clipped
to one ``max_step_mm`` per axis, as the env and the evaluation play it. When the batch's cut ends, each env's
cost is its path error over the intended area, weighed as the env weighs its reward (``relative_reward``),
NaN where it diverged (:data:`envs.rsl.EPISODE_COST_KEY`). The costs are replaced by their centred ranks (a
diverged cut ranks last), and ``Σ rank_p ε_p / (population σ)`` is the smoothed cost's gradient: a step of
Adam (``learning_rate`` for the MLP, ``feedback_learning_rate`` for the gains). Randomised sheets are common
random numbers: the env draws ``trials`` sheets and every perturbed policy cuts the same ones (the env's
``common_sheets``), so the ranking compares policies, not sheets.

The observation normaliser learns from every observation of the iteration after the step (it is frozen
within an iteration, so every perturbed policy sees the same normalisation). A fresh run's first iteration
plays the initial policy in every env and only teaches the normaliser, so that the first population is
perturbed on the scale the later ones are.

Forward passes only: no critic, no action noise, no tape; the env's own step does everything a move does,
so every option PPO trains with, es trains with. The actor is a continuous PPO actor (rsl-rl's MLP with a
Gaussian head, or :class:`agents.models.FeedbackMLPModel`), started at "hold still" (its output layer
zeroed; the feedback path starts at zero), so checkpoints, evaluation and export are PPO's.
"""

from __future__ import annotations

import numpy as np
import torch
from rsl_rl.env import VecEnv
from rsl_rl.models import MLPModel
from tensordict import TensorDict

from agents.adam import Adam
from agents.learner import ActorOnly


class ES(ActorOnly):
    """Evolution strategies on the actor's weights (module docstring), in rsl-rl's algorithm interface.

    Args:
        actor: The policy (rsl-rl's ``MLPModel`` or :class:`agents.models.FeedbackMLPModel`).
        env: The env it trains on: ``num_envs`` must be a multiple of ``population``.
        population, sigma, feedback_sigma, learning_rate, feedback_learning_rate: :class:`agents.es.config.
            EsConfig`'s.
        seed: Seed of the perturbations' stream.
        device: Torch device of the actor.
    """

    def __init__(
        self,
        actor: MLPModel,
        env: VecEnv,
        population: int,
        sigma: float,
        feedback_sigma: float,
        learning_rate: float,
        feedback_learning_rate: float,
        seed: int = 0,
        device: str = "cpu",
        multi_gpu_cfg: dict | None = None,
    ) -> None:
        from agents.es.config import EsConfig

        EsConfig(population, sigma, feedback_sigma, learning_rate, feedback_learning_rate).check(env.num_envs)
        super().__init__(actor, env, learning_rate, "es", device, multi_gpu_cfg)
        scene = getattr(getattr(env, "env", None), "scene", None)
        if scene is not None and scene.episode_steps < scene.task.num_steps:
            raise ValueError(
                f"env.max_episode_steps: es plays whole cuts ({scene.task.num_steps} steps), not "
                f"{scene.episode_steps}; leave it unset"
            )
        if hasattr(env, "common_sheets"):  # every perturbed policy cuts the same randomised sheets
            env.common_sheets = population
        self.population = population
        self.trials = env.num_envs // population
        self.layers = [m for m in self.body.modules() if isinstance(m, torch.nn.Linear)]
        with torch.no_grad():  # start from holding still (fixed tensioning); a resume loads its weights
            self.layers[-1].weight.zero_()
            self.layers[-1].bias.zero_()
        feedback = self.feedback_layer
        if feedback is not None:  # zero at the start by construction
            self.layers.append(feedback)
        self.params = [p for layer in self.layers for p in (layer.weight, layer.bias) if p is not None]
        self.num_params = sum(p.numel() for p in self.params)
        gains = feedback.weight.numel() if feedback is not None else 0
        body_size = self.num_params - gains

        def per_weight(mlp: float, gain: float) -> np.ndarray:
            return np.concatenate([np.full(body_size, float(mlp)), np.full(gains, float(gain))])

        self.sigmas = per_weight(sigma, feedback_sigma)
        self.adam = Adam((self.num_params,), per_weight(learning_rate, feedback_learning_rate))
        self.rng = np.random.default_rng(seed)
        self._step = 0
        self._batch: list[tuple[torch.Tensor, torch.Tensor | None]] | None = None
        self._eps: np.ndarray | None = None
        self._seen: list[torch.Tensor] = []
        self._costs: np.ndarray | None = None
        self._warm_up = actor.obs_normalization and int(actor.obs_normalizer.count) == 0
        self._rng_start = self.rng.bit_generator.state  # before this iteration's perturbations were drawn

    @property
    def body(self) -> torch.nn.Sequential:
        """The actor's MLP (rsl-rl's), without the feedback path where it has one."""
        mlp = self.actor.mlp
        return getattr(mlp, "body", mlp)

    @property
    def feedback_layer(self) -> torch.nn.Linear | None:
        """The actor's linear feedback path (:class:`agents.models.FeedbackMLP`), or None."""
        return getattr(self.actor.mlp, "feedback", None)

    # rsl-rl's algorithm interface ----------------------------------------------------------------------

    def act(self, obs: TensorDict) -> torch.Tensor:
        """The moves of every env's policy for this step (the iteration's first step draws the
        population)."""
        if self._step == 0:
            self._begin_iteration()
        self._step += 1
        with torch.inference_mode():
            if self.actor.obs_normalization:  # the normaliser learns from the iteration's raw observations
                self._seen.append(torch.cat([obs[group] for group in self.actor.obs_groups], dim=-1))
            out = self._moves(obs)
        return torch.clamp(out, -1.0, 1.0)

    def _moves(self, obs: TensorDict) -> torch.Tensor:
        """(B, A) unclipped moves of every env's policy for ``obs`` (:meth:`_forward` of the normalised
        observations; a learner that adds to the network's output overrides it)."""
        return self._forward(self.actor.get_latent(obs))

    def process_env_step(
        self, obs: TensorDict, rewards: torch.Tensor, dones: torch.Tensor, extras: dict
    ) -> None:
        """Keep the costs of the cuts that ended (the iteration's one episode)."""
        from envs.rsl import EPISODE_COST_KEY

        if EPISODE_COST_KEY in extras:
            if self._costs is not None:
                raise ValueError(
                    "es: the env's episodes must be whole iterations (num_steps_per_env = the episode's "
                    "steps)"
                )
            self._costs = extras[EPISODE_COST_KEY].detach().cpu().double().numpy()

    def compute_returns(self, obs: TensorDict) -> None:
        """Nothing to do: es scores whole cuts."""

    def update(self) -> dict[str, float]:
        """The es step (module docstring), or a warm-up iteration's normaliser; the iteration's losses."""
        if self._costs is None:
            raise ValueError(
                "es: the iteration ended before the cut did; give num_steps_per_env = the episode's steps"
            )
        costs, self._costs, self._step = self._costs, None, 0
        seen, self._seen = self._seen, []
        if self._eps is None:  # the warm-up: the initial policy in every env
            self._update_normalisation(seen)
            finite = np.isfinite(costs)
            return {"population_cost": float(costs[finite].mean()) if finite.any() else float("nan")}
        costs = costs.reshape(self.population, self.trials)
        finite = np.isfinite(costs).all(axis=1)
        fitness = np.where(finite, costs.mean(axis=1), np.inf)
        ranks = np.empty(self.population)
        ranks[np.argsort(fitness, kind="stable")] = np.arange(self.population)
        centred = ranks / (self.population - 1) - 0.5  # the highest cost +0.5
        step = self.adam.step(centred @ self._eps / (self.population * self.sigmas))
        self._set_theta(self._theta() + step)
        self._eps = None
        if self.actor.obs_normalization:
            self._update_normalisation(seen)
        return {
            "population_cost": float(np.mean(fitness[finite])) if finite.any() else float("nan"),
            "best_cost": float(np.min(fitness)),
            "step_norm": float(np.linalg.norm(step)),
        }

    def save(self) -> dict:
        return {
            "actor_state_dict": self.actor.state_dict(),
            # mid-iteration (Ctrl-C): the stream as the iteration began; a resume draws them again
            "optimizer_state_dict": {
                "adam": self.adam.state(),
                "rng": self._rng_start if self._step else self.rng.bit_generator.state,
            },
        }

    def load(self, loaded_dict: dict, load_cfg: dict | None, strict: bool) -> bool:
        self.actor.load_state_dict(loaded_dict["actor_state_dict"], strict=strict)
        state = loaded_dict.get("optimizer_state_dict") or {}
        if "adam" not in state:
            raise ValueError("not an es checkpoint (no es optimiser state); resume it with its own algo")
        self.adam.load(state["adam"])
        self.rng.bit_generator.state = state["rng"]
        # a checkpoint saved before the warm-up iteration ended (Ctrl-C) has not taught its normaliser yet
        self._warm_up = self.actor.obs_normalization and int(self.actor.obs_normalizer.count) == 0
        return True

    # es itself -----------------------------------------------------------------------------------------

    def _begin_iteration(self) -> None:
        """Draw the iteration's perturbations (none in a warm-up iteration) and build the population."""
        theta = self._theta()
        self._rng_start = self.rng.bit_generator.state
        if self._warm_up:
            self._warm_up = False
            self._eps = None
            self._batch = self._unpack(np.repeat(theta[None], self.population, axis=0))
            return
        half = self.rng.standard_normal((self.population // 2, self.num_params))
        self._eps = np.concatenate([half, -half])
        self._batch = self._unpack(theta + self.sigmas * self._eps)

    def _theta(self) -> np.ndarray:
        """The actor's trained weights (the MLP's and the feedback path's), as one float64 vector."""
        return torch.nn.utils.parameters_to_vector(self.params).detach().cpu().double().numpy()

    def _set_theta(self, theta: np.ndarray) -> None:
        vector = torch.as_tensor(theta, dtype=self.params[0].dtype, device=self.params[0].device)
        with torch.no_grad():
            torch.nn.utils.vector_to_parameters(vector, self.params)

    def _unpack(self, thetas: np.ndarray) -> list[tuple[torch.Tensor, torch.Tensor | None]]:
        """``(weights (P, out, in), biases (P, out) or None)`` per layer of the ``(P, num_params)``
        vectors."""
        out, offset = [], 0
        batch = torch.as_tensor(thetas, dtype=torch.float32, device=self.device)
        for layer in self.layers:
            w = layer.weight.shape
            weight = batch[:, offset : offset + w.numel()].reshape(len(batch), *w)
            offset += w.numel()
            bias = None
            if layer.bias is not None:
                bias = batch[:, offset : offset + layer.bias.numel()]
                offset += layer.bias.numel()
            out.append((weight, bias))
        return out

    def _forward(self, latent: torch.Tensor) -> torch.Tensor:
        """(B, A) deterministic outputs of env ``e``'s policy ``e // trials`` for the (B, D) normalised
        observations ``latent``: the actor's MLP (and feedback path), each policy with its own weights."""
        b = latent.shape[0]
        x = h = latent.reshape(self.population, self.trials, -1)
        linear = iter(self._batch)
        for module in self.body:
            if isinstance(module, torch.nn.Linear):
                weight, bias = next(linear)
                h = torch.baddbmm(bias.unsqueeze(1), h, weight.transpose(1, 2))
            else:
                h = module(h)
        if self.feedback_layer is not None:  # FeedbackMLP's path, each policy with its own gains
            weight, _ = next(linear)
            mlp = self.actor.mlp
            error = x[..., mlp.start : mlp.start + mlp.size]
            if mlp.scheduled:  # gains scheduled on the observation: the body's outputs past the move
                gains = h[..., mlp.actions :].unflatten(-1, (mlp.actions, mlp.size))
                h = h[..., : mlp.actions] + (gains @ error.unsqueeze(-1)).squeeze(-1)
            h = h + torch.bmm(error, weight.transpose(1, 2))
        out = h.reshape(b, -1)
        if self.actor.distribution is not None:
            out = self.actor.distribution.deterministic_output(out)
        return out

    def _update_normalisation(self, seen: list[torch.Tensor]) -> None:
        """The actor's observation normaliser learns from the raw observations ``seen`` (one batch a step)."""
        if seen:
            self.actor.obs_normalizer.update(torch.cat(seen))
