"""``warpcut plan``: the paper's cut planning for one contour."""

from __future__ import annotations

import time
from pathlib import Path

import click

from agents.cli import options, outputs, settings
from agents.config import EVALUATION_CANDIDATES
from agents.methods import point_text
from warpcut.sim.config import ARM_RADIUS_MM, SEGMENT_TOLERANCE_MM, SimConfig


@click.command("plan", cls=settings.Command)
@options.contour_option
@options.count_option(
    "candidates",
    EVALUATION_CANDIDATES,
    "Pinch points sampled from the feasible region (paper: 30; the centroid is added if feasible).",
)
@click.option(
    "--arm-radius",
    cls=options.Setting,
    key="arm.radius_mm",
    default=ARM_RADIUS_MM,
    show_default=True,
    type=options.FloatRange(min=0.0),
    help="Radius of the cutting arm (mm) whose sweep pinch points must avoid.",
)
@options.arm_length_option
@click.option(
    "--tolerance",
    default=SEGMENT_TOLERANCE_MM,
    show_default=True,
    type=options.FloatRange(min=0.0, min_open=True),
    help="Segmentation tolerance (mm): x reversals smaller than this are ignored.",
)
@options.resolution_option
@options.device_option
@options.seed_option
@options.json_option
def command(
    contour_name: str,
    candidates: int,
    arm_radius: float,
    arm_length: float,
    tolerance: float,
    resolution: int,
    device: str | None,
    seed: int,
    json_path: Path | None,
) -> None:
    """Plan a cut: segments, orderings and pinch candidates, scored with fixed tension."""
    import warnings

    from warpcut.contours import load_contour
    from warpcut.planning import ArmModel, plan_cut

    outputs.check_outputs({"--json": json_path}, [contour_name])
    contour = load_contour(contour_name)
    config = SimConfig(resolution=resolution).validated()
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = plan_cut(
            contour,
            config,
            num_candidates=candidates,
            seed=seed,
            device=device,
            tolerance_mm=tolerance,
            arm=ArmModel(radius_mm=arm_radius, length_mm=arm_length),
        )
    for warning in caught:
        click.echo(f"warning: {warning.message}", err=True)
    data = result.to_json()
    click.echo(
        f"contour {contour.name}: {len(data['segments'])} segment(s), planned in "
        f"{time.perf_counter() - start:.1f} s"
    )
    for k, s in enumerate(data["segments"]):
        click.echo(
            f"  segment {k}: notch {point_text(s['notch'])} -> termination {point_text(s['termination'])}, "
            f"{len(s['points'])} points"
        )
    errors = result.errors
    click.echo(f"orders searched: {len(result.orders)}" + (" (heuristic)" if result.heuristic_orders else ""))
    for o, order in enumerate(result.orders[:10]):
        click.echo(
            f"  order {list(order)}: best {errors[:, o].min():.1f}, mean {errors[:, o].mean():.1f} vertices"
        )
    click.echo(f"pinch candidates: {len(result.candidates)} feasible")
    ranked = sorted(result.candidates, key=lambda c: c["error_vertices"])
    for c in ranked[:5]:
        click.echo(
            f"  {point_text(c['point'])}: {c['error_vertices']:.1f} vertices, order {list(c['best_order'])}"
        )
    for r in result.rejected:
        click.echo(f"  centroid {point_text(r['point'])} infeasible: {', '.join(r['violates'])}")
    chosen = data["chosen"]
    click.echo(
        f"chosen: pinch {point_text(chosen['pinch'])}, order {chosen['order']}, "
        f"{chosen['error_vertices']:.1f} vertices"
    )
    if json_path:
        from warpcut.io import write_json

        write_json(json_path, data)
        click.echo(f"wrote {json_path}")
