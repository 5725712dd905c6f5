"""Tensioning agents: the paper's baselines, the learners (es, PPO and APG, :mod:`agents.algorithms`) and
their training on rsl-rl, the evaluation protocols, the pipelines (:mod:`agents.pipelines`) and the command
line (:mod:`agents.cli`). The map is in docs/architecture.md.

Importing this package before torch sets ``GOMP_SPINCOUNT`` (unless it is set already) to
:data:`OPENMP_SPIN_COUNT`. torch's CPU build runs its parallel ops on GNU OpenMP, whose idle threads spin
~300,000 times before they sleep. After each PPO update that spin held one of the two cores for the first
env step of the next collection, beside the simulator's own threads (that step took ~11 ms instead of ~6
at 256 envs). A tenth of it keeps the update's threads awake between its ops and frees the core after
(docs/performance.md, "Where the time goes"). It is read once, when torch loads: set it in the shell when
torch is imported first.
"""

import os
import sys

OPENMP_SPIN_COUNT = "30000"
"""GNU OpenMP's spin count (``GOMP_SPINCOUNT``) for the processes that train; libgomp's default is 300,000."""

if "torch" not in sys.modules:
    os.environ.setdefault("GOMP_SPINCOUNT", OPENMP_SPIN_COUNT)
