"""Running the command line in-process, as the tests of its commands do."""

import pytest
from click.testing import CliRunner

from agents.cli import main


def invoke(args):
    """Run the CLI in-process: (exit code, stdout, stderr)."""
    result = CliRunner().invoke(main, args, standalone_mode=True, catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def refused(args, capfd) -> str:
    """The one line ``error: ...`` that ``args`` exits with, status 2 (no traceback)."""
    with pytest.raises(SystemExit) as exit_info:
        main.main(args=args, prog_name="warpcut")
    assert exit_info.value.code == 2
    err = [line for line in capfd.readouterr().err.strip().splitlines() if not line.startswith("Warp CUDA")]
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


def simulate_folder(cwd):
    """The one folder of simulate's implicit outputs (figures, recording, videos) under ``cwd``."""
    from pathlib import Path

    (folder,) = Path(cwd).glob("logs/simulate-*")
    return folder.absolute()
