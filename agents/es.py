"""Evolution strategies (es) on the tensioning policy's weights: the neural closed-loop policy trained from
the path score itself through the batched simulator, an alternative to PPO and APG (``warpcut train --algo
es``, ``--recipe es``; Salimans et al. 2017, "Evolution Strategies as a Scalable Alternative to
Reinforcement Learning"; Mania et al. 2018 for the observation normalisation).

Each iteration perturbs the actor's weights ``θ`` into ``TrainConfig.es_population`` policies in
antithetic pairs (``θ ± σ⊙ε``; ``σ`` is ``TrainConfig.es_sigma`` for the MLP's weights and
``es_feedback_sigma`` for the feedback gains), plays every one of them on
``num_envs / es_population`` episodes in one simulator batch (env ``e`` plays policy ``e // trials``; each
policy moves by its deterministic output, clipped to one ``max_step_mm`` per axis, as the env and the
evaluation play it), and scores each whole cut with the evaluation's error (the path score's symmetric
difference in vertices; with ``relative_reward`` or ``randomize`` weighed by the env's reward scale, so a
sheet that hangs flat counts as much as the nominal one). Randomised sheets are common random numbers:
each iteration draws ``trials`` sheets and every perturbed policy cuts the same ones (episode ``k`` of
each), so the ranking compares policies, not sheets (the process noise still differs from env to env).
The errors are replaced by their centred ranks (a diverged cut ranks last) and ``Σ rank_p ε_p / (population
σ)`` is the smoothed error's gradient, a step of Adam (:class:`agents.gradient.Adam`,
``TrainConfig.learning_rate`` for the MLP, ``es_feedback_learning_rate`` for the gains). The observation
normaliser learns from every observation of the iteration after the step (it is frozen within an iteration,
so every perturbed policy sees the same normalisation); a fresh run's first learns from one cut of the initial
policy in every env, so that the first population is perturbed on the scale the later ones are.

Forward passes only: no critic, no action noise, no tape; the env's own step does everything a move does
(analytic share, base plan, randomised sheets), so every option PPO trains with, es trains with. The
policy is rsl-rl's actor and :class:`EsRunner` PPO's runner with the learning iteration replaced
(:class:`agents.episodic.EpisodeRunner`), so checkpoints, validation, model selection, resume, evaluation
and export are PPO's. The actor starts at "hold still" (its output layer zeroed). With
``TrainConfig.actor_feedback`` (the ``es`` recipe's) the actor also has a linear feedback path from the
tracking error (:class:`agents.models.FeedbackMLP`), zero at the start, whose gains es perturbs with the
MLP's weights, with their own σ and step: a perturbed MLP moves the grasp by a near-constant bias that
adds up over a long cut, so the MLP's σ and step are small and the gains', on the normalised tracking
error, large (docs/learning.md, "es with separate steps for the feedback path").
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch
from rsl_rl.env import VecEnv

from agents.config import es_population_error
from agents.episodic import EpisodeRunner
from agents.gradient import Adam


class EsRunner(EpisodeRunner):
    """:class:`~agents.episodic.EpisodeRunner` whose learning iteration is an es step (see the module)."""

    name = "es"
    scalars = ("final_error", "best_error", "step_norm")

    def __init__(self, env: VecEnv, train_cfg: dict, log_dir: str | Path | None, device: str = "cpu") -> None:
        super().__init__(env, train_cfg, log_dir, device)
        settings = train_cfg.get("es", {})
        self.population = int(settings["population"])
        error = es_population_error(self.population, env.num_envs)
        if error:
            raise ValueError(error)
        steps = {
            "es_sigma": settings["sigma"],
            "es_feedback_sigma": settings["feedback_sigma"],
            "learning_rate": train_cfg["algorithm"]["learning_rate"],
            "es_feedback_learning_rate": settings["feedback_learning_rate"],
        }
        for name, value in steps.items():
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise ValueError(f"{name}: must be a finite number > 0 (got {value!r}); e.g. TrainConfig's")
        self.trials = env.num_envs // self.population
        # With actor_feedback: the MLP's layers, then the feedback path's (weights only, its last parameters).
        self.layers = [m for m in self.body.modules() if isinstance(m, torch.nn.Linear)]
        if self.feedback_layer is not None:
            self.layers.append(self.feedback_layer)
        self.params = [p for layer in self.layers for p in (layer.weight, layer.bias) if p is not None]
        self.num_params = sum(p.numel() for p in self.params)
        gains = self.feedback_layer.weight.numel() if self.feedback_layer is not None else 0
        body = self.num_params - gains

        def per_weight(mlp: str, feedback: str) -> np.ndarray:
            return np.concatenate([np.full(body, float(steps[mlp])), np.full(gains, float(steps[feedback]))])

        self.sigmas = per_weight("es_sigma", "es_feedback_sigma")
        self.adam = Adam((self.num_params,), per_weight("learning_rate", "es_feedback_learning_rate"))

    def _extra_state(self) -> dict:
        return {"es_adam": self.adam.state()}

    def _load_extra(self, infos: dict) -> None:
        self.adam.load(infos["es_adam"])

    def _theta(self) -> np.ndarray:
        """The actor MLP's weights and biases, layer by layer, as one float64 vector."""
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

    def _moves(self, obs: np.ndarray, layers: list[tuple[torch.Tensor, torch.Tensor]]) -> np.ndarray:
        """(B, A) actions of env ``e``'s policy ``e // trials`` for the (B, D) observations: the actor's own
        normalisation and MLP, each policy with its own weights, its deterministic output clipped to 1."""
        from tensordict import TensorDict

        actor, b = self.alg.actor, self.env.num_envs
        with torch.inference_mode():
            tensor = torch.as_tensor(obs, device=self.device)
            latent = actor.get_latent(TensorDict({"policy": tensor}, batch_size=[b]))
            x = h = latent.reshape(self.population, self.trials, -1)
            linear = iter(layers)
            for module in self.body:
                if isinstance(module, torch.nn.Linear):
                    weight, bias = next(linear)
                    h = torch.baddbmm(bias.unsqueeze(1), h, weight.transpose(1, 2))
                else:
                    h = module(h)
            feedback = self.feedback_layer
            if feedback is not None:  # FeedbackMLP's path, each policy with its own gains
                weight, _ = next(linear)
                inputs = x[..., actor.mlp.start : actor.mlp.start + actor.mlp.size]
                h = h + torch.bmm(inputs, weight.transpose(1, 2))
            out = h.reshape(b, -1)
            if actor.distribution is not None:
                out = actor.distribution.deterministic_output(out)
            return torch.clamp(out, -1.0, 1.0).cpu().numpy()

    def _episode(self, layers) -> tuple[np.ndarray, list[np.ndarray], int]:
        """Play one whole cut in every env; ``(weighed errors (B,), NaN where diverged; the observations
        seen; steps)``."""
        scene = self.scene
        obs = scene.reset(self.episode_rng, scene.options.resample_fiducials, repeat=self.population)
        seen, steps, info = [obs], 0, {}
        while True:
            obs, _, terminated, truncated, info = scene.step(self._moves(obs, layers))
            steps += 1
            if terminated or truncated:
                break
            seen.append(obs)
        # the score is NaN for a diverged env; an episode that ended with every env diverged has none
        errors = np.asarray(info.get("error_vertices", np.full(self.env.num_envs, np.nan)), dtype=np.float64)
        errors = errors * scene.reward_scale
        return errors, seen, steps

    def _seed_normalisation(self, theta: np.ndarray) -> None:
        """A fresh run's observation normaliser learns from one whole cut of the initial policy ``theta`` in
        every env before es's first step. Otherwise the first population is perturbed on raw observations (the
        normaliser's start: mean 0, std 1), the second on observations scaled by their real std (~0.1-0.6 for
        the tracking error), and the gains' effect jumps several-fold between them: the population's mean
        error rose after the first step on most contours (docs/learning.md, "The normaliser's first
        iteration")."""
        thetas = np.repeat(theta[None], self.population, axis=0)
        _, seen, _ = self._episode(self._unpack(thetas))
        self._update_normalisation(seen)

    def _update_normalisation(self, seen: list[np.ndarray]) -> None:
        """The actor's observation normaliser learns from the observations ``seen`` (one array a step)."""
        from tensordict import TensorDict

        batch = torch.as_tensor(np.concatenate(seen), device=self.device)
        self.alg.actor.update_normalization(TensorDict({"policy": batch}, batch_size=[len(batch)]))

    def _iteration(self) -> dict:
        """One es step (module docstring); the iteration's metrics."""
        start = time.perf_counter()
        theta = self._theta()
        actor = self.alg.actor
        if actor.obs_normalization and int(actor.obs_normalizer.count) == 0:
            self._seed_normalisation(theta)
        half = self.episode_rng.standard_normal((self.population // 2, self.num_params))
        eps = np.concatenate([half, -half])
        errors, seen, steps = self._episode(self._unpack(theta + self.sigmas * eps))
        collected = time.perf_counter()
        errors = errors.reshape(self.population, self.trials)
        finite = np.isfinite(errors).all(axis=1)
        fitness = np.where(finite, errors.mean(axis=1), np.inf)
        ranks = np.empty(self.population)
        ranks[np.argsort(fitness, kind="stable")] = np.arange(self.population)
        centred = ranks / (self.population - 1) - 0.5  # the highest error +0.5
        step = self.adam.step(centred @ eps / (self.population * self.sigmas))
        self._set_theta(theta + step)
        if actor.obs_normalization:
            self._update_normalisation(seen)
        elapsed = time.perf_counter() - start
        total = self.env.num_envs * steps
        return {
            "final_error": float(np.mean(fitness[finite])) if finite.any() else float("nan"),
            "best_error": float(np.min(fitness)) if finite.any() else float("nan"),
            "step_norm": float(np.linalg.norm(step)),
            "mean_return": None,
            "mean_episode_length": float(steps),
            "iteration_steps_per_s": total / elapsed,
            "collection_steps_per_s": total / (collected - start),
        }
