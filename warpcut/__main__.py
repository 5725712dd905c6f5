"""``python -m warpcut`` runs the command line."""

from warpcut.cli import main

main()
