"""``warpcut export``: a trained policy as TorchScript and ONNX."""

from __future__ import annotations

from pathlib import Path

import click


@click.command("export")
@click.argument("run_dir", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Where to write policy.pt and policy.onnx (default: RUN_DIR/exported).",
)
def command(run_dir: Path, out: Path | None) -> None:
    """Export a trained policy as TorchScript and ONNX (observation -> action index).

    RUN_DIR is a run directory of 'warpcut train' (its validated best.pt, else its newest checkpoint), or one
    of its .pt checkpoints."""
    from agents.export import export_policy

    for kind, path in export_policy(run_dir, out).items():
        click.echo(f"{kind}: {path}")
