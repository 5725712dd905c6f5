"""``warpcut simulate``: cut a contour with each baseline tensioner and compare their errors."""

from __future__ import annotations

import time
from pathlib import Path

import click

from agents.cli.common import (
    DEFAULTS,
    check_outputs,
    contour_option,
    count_option,
    device_option,
    echo_recording,
    echo_written,
    final_cuts,
    json_option,
    noise_option,
    parse_methods,
    parse_point,
    plots_option,
    record_option,
    recorder,
    resolution_option,
    run_dir,
    score_option,
    seed_option,
    step_callbacks,
)
from agents.cli.video import video_option, videos, with_videos
from agents.methods import BASELINES, point_text
from warpcut.sim.config import FIXTURES, SimConfig


@click.command("simulate")
@contour_option
@click.option(
    "--policy", "policies", default=",".join(BASELINES), show_default=True, help="Comma-separated tensioners."
)
@click.option("--pinch", default=None, help="Pinch point X,Y (mm, material) for fixed and analytic.")
@count_option("trials", 1, "Seeded trials per policy (they differ by process noise).")
@noise_option
@score_option
@resolution_option
@click.option("--fixture", default=DEFAULTS.fixture, show_default=True, type=click.Choice(FIXTURES))
@device_option
@seed_option
@json_option
@record_option("next to --json, or in logs/simulate-TIMESTAMP")
@video_option
@click.option(
    "--export-mesh",
    "mesh_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Write each policy's final sheet (its first trial) as DIR/POLICY_env0_stepN.glb (mm, z up, "
    "strain colours; trimesh).",
)
@plots_option("regions.png/svg next to --json, or in logs/simulate-TIMESTAMP")
def command(
    contour_name: str,
    policies: str,
    pinch: str | None,
    trials: int,
    noise: float,
    score: str,
    resolution: int,
    fixture: str,
    device: str | None,
    seed: int,
    json_path: Path | None,
    record_envs: int | None,
    colour_by: str,
    video_envs: int | None,
    mesh_dir: Path | None,
    no_plots: bool,
) -> None:
    """Cut a contour with each baseline tensioner and compare their errors."""
    from agents.evaluation import compare_policies
    from warpcut.contours import load_contour

    names = parse_methods(policies, "--policy", BASELINES)
    point = parse_point(pinch, "--pinch")
    check_outputs({"--json": json_path, "--export-mesh": mesh_dir}, [contour_name])
    contour = load_contour(contour_name)
    config = SimConfig(resolution=resolution, fixture=fixture, noise_std=noise, score=score).validated()
    out = json_path.parent if json_path else run_dir(None, "simulate")
    cuts = final_cuts(no_plots)
    meshes = None
    if mesh_dir is not None:
        from warpcut.viz.mesh_export import MeshExports

        meshes = MeshExports(mesh_dir)
    start = time.perf_counter()
    with recorder(out, record_envs, colour_by) as rec, videos(out, video_envs) as vid:
        report = compare_policies(
            contour, names, trials=trials, config=config, pinch=point, device=device, seed=seed,
            step_callbacks=with_videos(step_callbacks(rec, cuts, meshes), vid),
        )  # fmt: skip
    elapsed = time.perf_counter() - start
    click.echo(
        f"contour {contour.name} ({'closed' if contour.closed else 'open'}, {contour.length:.1f} mm), "
        f"{trials} trial(s), {config.nx}x{config.ny} on {device}, {elapsed:.1f} s"
    )
    click.echo(
        f"{'policy':<10} {'error (vertices)':>16} {'error (mm^2)':>13} {'improvement':>12} {'pinch (mm)':>16}"
    )
    for name, r in report["results"].items():
        ci = f" ±{r['ci95_pct']:.1f}" if trials > 1 else ""
        pinch_txt = "-" if r["pinch"] is None else point_text(r["pinch"])
        click.echo(
            f"{name:<10} {r['error_vertices']:>16.1f} {r['error_mm2']:>13.1f} "
            f"{r['improvement_pct']:>+11.1f}%{ci} {pinch_txt:>16}"
        )
    if json_path:
        from warpcut.io import write_json

        write_json(json_path, report)
        click.echo(f"wrote {json_path}")
    if cuts is not None:
        from warpcut.viz.plots import plot_regions

        echo_written(plot_regions(cuts.of(contour.name), out))
    echo_written(meshes.written if meshes is not None else [])
    echo_recording(rec)
