"""What each command runs, as a dataclass: the layout of its config file (``--config``), the keys of its
``--set`` overrides, what ``--print-config`` prints and what a run directory's ``config.json`` holds.

Every job has the same sections where it has them: ``sim`` (:class:`~warpcut.sim.config.SimConfig`: the
physics and the protocol, e.g. ``sim.noise_std``, ``sim.score``), ``env`` (:class:`~envs.options.EnvConfig`:
what a policy observes, how it acts and is rewarded, domain randomisation) and ``train``
(:class:`~agents.config.TrainConfig`: the learner, its batch and its own section, e.g. ``train.es.sigma``).
The flags of a command set a few of these keys; the rest keep their defaults unless a file or ``--set``
changes them.

Each job's class lives in the module of its kind (:mod:`~agents.jobs.contour`: one contour;
:mod:`~agents.jobs.suite`: a suite; :mod:`~agents.jobs.generalist`: many contours); what they share is in
:mod:`~agents.jobs.fields`, and the defaults that follow from other settings in :mod:`~agents.jobs.defaults`.
"""

from agents.jobs.contour import TAPE_ONLY, OptimizeJob, RobustnessJob, RunJob, SimulateJob, TrainJob
from agents.jobs.defaults import with_dependent_defaults
from agents.jobs.fields import CONFIG_FILE, OUTPUT_KEYS, other_learners
from agents.jobs.generalist import GENERALIST_LEARNERS, GeneralistJob, TeachersJob
from agents.jobs.suite import EvaluateJob

__all__ = [
    "CONFIG_FILE",
    "GENERALIST_LEARNERS",
    "OUTPUT_KEYS",
    "TAPE_ONLY",
    "EvaluateJob",
    "GeneralistJob",
    "OptimizeJob",
    "RobustnessJob",
    "RunJob",
    "SimulateJob",
    "TeachersJob",
    "TrainJob",
    "other_learners",
    "with_dependent_defaults",
]
