"""The defaults of a job that follow from its other settings (:func:`with_dependent_defaults`), where they
are not given: what a command resolves after its file, ``--set`` and flags."""

from __future__ import annotations

import dataclasses
from typing import Any

from agents.config import STUDENT_DEFAULTS
from agents.jobs.generalist import GeneralistJob
from agents.plan_optimizer.config import GRAD_CONFIGS, GradConfig


def with_dependent_defaults(job: Any, explicit: set[str]) -> Any:
    """``job`` with the defaults that follow from its other settings, where not set ``explicit``ly (dotted
    keys given by a file, ``--set`` or a flag):

    - the env's action type is the learner's (``agents.algorithms``): PPO trains discrete moves;
    - the gradient optimiser's steps and step size are its estimator's
      (:data:`agents.plan_optimizer.config.GRAD_CONFIGS`);
    - a policy started from a generalist (``init``) observes and acts as the generalist does;
    - a generalist learned from teachers (dagger) has its own observation and network
      (:data:`agents.config.STUDENT_DEFAULTS`).
    """
    from agents.algorithms import algorithm
    from agents.config_io import apply

    if hasattr(job, "train") and hasattr(job, "env") and "env.action_type" not in explicit:
        actions = algorithm(job.train.algo).action_type
        job = dataclasses.replace(job, env=dataclasses.replace(job.env, action_type=actions))
    if isinstance(job, GeneralistJob) and job.train.algo == "dagger":
        given = {key: value for key, value in STUDENT_DEFAULTS.items() if key not in explicit}
        job = apply(job, given, "a dagger generalist's defaults")
    if getattr(job, "init", None) is not None:  # fine-tuning observes and acts as the generalist does
        from agents.generalist import fine_tuning_defaults

        job = fine_tuning_defaults(job, explicit)
    if hasattr(job, "grad") and job.grad.estimator in GRAD_CONFIGS:
        own = GRAD_CONFIGS[job.grad.estimator]
        given = {key.split(".")[1] for key in explicit if key.startswith("grad.") and key.count(".") >= 1}
        keep = {
            f.name: getattr(job.grad, f.name)
            for f in dataclasses.fields(GradConfig)
            if f.name in given or f.name == "estimator"
        }
        job = dataclasses.replace(job, grad=dataclasses.replace(own, **keep))
    return job
