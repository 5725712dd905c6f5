"""gps's runner: warpcut's rsl-rl runner (:class:`agents.runner.Runner`) that first finds the teacher and
scores it.

Before the first validation or iteration it optimises the teacher's plan for the env's contour, pinch point
and segments (:func:`agents.plan_optimizer.optimizer.cached_plan`, the es estimator: what ``warpcut optimize
--estimator es`` finds with the run's seed), kept in the run directory's ``teacher/`` (an interrupted
optimisation continues there), and sets it as the student's feed-forward. Its first validation then scores, on
the same held-out episodes (the nominal sheet's, and randomised ones where the correction trains on them:
:meth:`agents.gps.config.GpsConfig.sheets`), the still grasp (the plan zeroed: fixed tension) and the plan
played open loop (the student before any correction); later validations score the student. Model
selection keeps the best of the three (``best.pt``), so the student never ships worse than its teacher or a
still grasp on those episodes; beside randomised episodes, only a policy that does no worse than the plan on
the nominal sheet's is kept (:attr:`agents.runner.Runner.guarded_episodes`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from agents.runner import Runner

TEACHER_DIR = "teacher"
"""The run directory's folder of the teacher's plan (``CONTOUR.json``, as ``cached_plan`` keeps it)."""


class GpsRunner(Runner):
    """:class:`agents.runner.Runner` with a teacher (module docstring).

    Attributes:
        teacher: The teacher's :class:`agents.plan_optimizer.plan.PlanResult` once found (None on a resumed
            run, whose checkpoint carries the plan inside the actor).
    """

    def __init__(self, env, train_cfg: dict, log_dir: str | Path | None, device: str = "cpu") -> None:
        super().__init__(env, train_cfg, log_dir, device)
        self.teacher = None
        self._taught = False

    def _teach(self) -> None:
        """Find the teacher's plan (once) and make it the actor's feed-forward."""
        if self._taught:
            return
        from agents.plan_optimizer.config import grad_config
        from agents.plan_optimizer.optimizer import cached_plan
        from warpcut.io import WriteFailed

        options = self.env.cfg
        contours, points, cuts = options.per_env(1)
        config = options.config()
        settings = grad_config("es", iterations=self.cfg["gps"]["teacher_iterations"])
        folder = None if self.logger.log_dir is None else Path(self.logger.log_dir) / TEACHER_DIR
        try:
            self.teacher = cached_plan(
                contours[0], points[0], None if cuts is None else cuts[0], config, settings, options.device,
                self.seed, folder, arm=options.arm, allow_infeasible_pinch=True,
            )  # fmt: skip
        except WriteFailed as exc:  # the optimiser's state so far is whole: the run resumes from it
            raise ValueError(
                f"{exc.path}: not written, {exc.reason}; the teacher's state so far is intact: {exc.fix}, "
                f"then resume from {self.logger.log_dir}"
            ) from exc.__cause__
        moves = np.asarray(self.teacher.plan, dtype=np.float32) / np.float32(config.max_step_mm)
        self._resize(len(moves))
        self.alg.actor.set_plan(torch.as_tensor(moves))
        self.own_summary["teacher"] = {
            "seconds": self.teacher.seconds,
            "env_steps": self.teacher.env_steps,
            "best_iteration": self.teacher.best_iteration,
            "validation_error": self.teacher.history[self.teacher.best_iteration].get(
                "validation_error_vertices"
            ),
        }
        self._taught = True

    def validate(self, validate: Callable[[torch.nn.Module], float | np.ndarray]) -> float:
        """:meth:`Runner.validate`; the first validation of a run scores the teacher's plan (the baseline of
        model selection's paired differences: the student starts as the plan) and then the still grasp,
        later ones the student. Returns the validation error of the policy being trained."""
        self._teach()
        if self.validation_baseline is not None:
            error = super().validate(validate)
            self._label("student")
            return error
        error = super().validate(validate)  # the baseline: the student starts as the plan
        self._label("plan")
        actor = self.alg.actor
        plan = actor.lookup.plan.clone()
        actor.set_plan(torch.zeros_like(plan))
        try:
            super().validate(validate)
        finally:
            actor.set_plan(plan)
        self._label("still")
        return error

    def _label(self, policy: str) -> None:
        """Name the policy the newest validation scored, and the kept one where it is that."""
        self.validation[-1]["policy"] = policy
        if self.best_score == self.validation[-1]["score"] and self.best_iterations == self.iterations_done:
            self.own_summary["kept"] = policy

    def learn(self, num_learning_iterations: int, init_at_random_ep_len: bool = False) -> None:
        self._teach()
        return super().learn(num_learning_iterations, init_at_random_ep_len)

    def _resize(self, steps: int) -> None:
        """Make the actor's plan ``steps`` moves long, the teacher's (the nominal sheet's cut; the training
        env's cut may differ by a step on randomised sheets), as the checkpoints' description says."""
        if steps != self.alg.actor.lookup.plan.shape[0]:
            self.alg.actor.resize(steps)
            self.cfg["actor"]["plan_steps"] = steps
            self.policy_description["actor"]["plan_steps"] = steps

    def load_checkpoint(self, path: str | Path, state: dict | None = None) -> None:
        from agents.checkpoints import read_checkpoint

        state = read_checkpoint(path, map_location=self.device) if state is None else state
        saved = state.get("actor_state_dict", {})
        if "lookup.plan" in saved and "nominal.obs" not in saved:
            raise ValueError(
                f"{path}: a gps run of an earlier warpcut, whose correction is not centred on its plan: it "
                "cannot go on training here; start a new run (its policy still plays, evaluates and exports)"
            )
        plan = saved.get("lookup.plan")
        if plan is not None:  # the checkpoint's plan length, the teacher's
            self._resize(int(plan.shape[0]))
        super().load_checkpoint(path, state)
        # the plan is in the checkpoint's actor, unless the run stopped while its teacher was optimised
        self._taught = "teacher" in self.own_summary
