"""``python -m warpcut`` runs the ``warpcut`` command.

The command line lives in ``agents.cli`` (it drives the learning pipelines, which ``warpcut`` must not
import); this finds it through the installed console-script entry point instead of importing upward.
"""

import sys
from importlib.metadata import entry_points

scripts = entry_points(group="console_scripts", name="warpcut")
if not scripts:
    sys.exit("error: the warpcut command is not installed; run 'pip install -e .' (scripts/setup.sh does)")
next(iter(scripts)).load()()
