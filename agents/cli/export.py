"""``warpcut export``: a trained policy as TorchScript and ONNX."""

from __future__ import annotations

from pathlib import Path

import click

from agents.cli import outputs, settings


@click.command("export", cls=settings.Command)
@click.argument("run_dir", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Where to write policy.pt and policy.onnx (default: exported/ beside the policy's checkpoint; for "
    "an evaluate directory, RUN_DIR/exported/CONTOUR).",
)
def command(run_dir: Path, out: Path | None) -> None:
    """Export trained policies as TorchScript and ONNX (observation -> action), with ONNX metadata saying
    what each observation entry and action means, and the env the policy acts in (warpcut.options: the
    keyword arguments of gymnasium.make("warpcut/PatternCut-v0", ...)).

    RUN_DIR is a run directory of 'warpcut train' (its validated best.pt, else its newest checkpoint), of
    'warpcut run' (the chosen candidate's policy) or of 'warpcut evaluate' (every contour's policy), or a
    .pt checkpoint. A run whose training did not finish (interrupted, failed or killed) is exported all the
    same, with a note saying so, also in the metadata (warpcut.training)."""
    from agents.export import export_run

    outputs.check_outputs({"--out": out})
    for exported in export_run(run_dir, out):
        click.echo(f"exported {exported['policy']}")
        for kind in ("torchscript", "onnx"):
            click.echo(f"  {kind}: {exported[kind]}")
        if exported["unfinished"]:
            click.echo(f"note: {exported['unfinished']}")
        outputs.echo_infeasible({"policy": exported["pinch_problem"]})
