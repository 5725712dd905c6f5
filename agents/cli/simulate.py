"""``warpcut simulate``: cut a contour with each baseline tensioner and compare their errors
(:func:`agents.evaluation.compare_policies`)."""

from __future__ import annotations

import contextlib
import math
import time
from pathlib import Path

import click

from agents.cli import options, outputs, settings
from agents.cli.video import video_option, videos, with_videos
from agents.methods import BASELINES, point_text
from warpcut.stats import NEGLIGIBLE_ERROR


@click.command("simulate", cls=settings.Command)
@options.contour_setting()
@click.option(
    "--policy",
    cls=options.Setting,
    key="policy",
    default=",".join(BASELINES),
    show_default=True,
    callback=lambda ctx, param, value: [v.strip() for v in value.split(",") if v.strip()],
    help="Comma-separated tensioners, of none,fixed,analytic,generalist (generalist: one policy for every "
    "contour, no training).",
)
@options.generalist_option
@click.option(
    "--pinch",
    cls=options.Setting,
    key="pinch",
    default=None,
    callback=options.point_callback,
    help="Pinch point X,Y (mm, material) of fixed and analytic; default: fixed's best by random search, "
    "analytic's feasible centroid.",
)
@options.count_option(
    "trials", None, "Seeded trials per tensioner, differing by noise (default: one).", key="trials"
)
@options.seed_option
@options.device_option
@options.json_option
@options.record_flag("in --out")
@options.out_option("logs/simulate-TIMESTAMP; the figures, recording and videos, a folder of simulate's own")
@video_option
@options.config_options
def command(
    contour: str | None,
    policy: list[str],
    generalist_source: str | None,
    pinch: list[float] | None,
    trials: int | None,
    seed: int,
    device: str | None,
    json_path: Path | None,
    record_envs: int | None,
    video_envs: int | None,
    out: Path | None,
    config_file: str | None,
    overrides: tuple[str, ...],
    print_config: bool,
) -> None:
    """Cut a contour with each tensioner that needs no training and compare their errors.

    Everything but the flags is set with --config FILE and --set KEY=VALUE (the physics and the protocol:
    sim.noise_std, sim.score, sim.resolution, sim.fixture; colour_by, export_mesh=DIR, plots=false);
    --print-config shows them all.
    """
    from agents.evaluation import compare_policies
    from agents.jobs import SimulateJob
    from warpcut.io import claim_run_dir
    from warpcut.planning import resolve_contour

    job = settings.resolve(SimulateJob, config_file, overrides).check()
    settings.refuse_unused_settings(job, overrides)
    contour = resolve_contour(job.contour, job.sim)  # a bad name or file: now
    if print_config:
        settings.print_config(job)
        return
    generalist = None
    if "generalist" in job.policy:  # a generalist to play: now
        from agents.generalist import load_generalist

        generalist = load_generalist(job.generalist)
    if job.pinch is not None and {"fixed", "analytic", "generalist"} & set(job.policy):  # infeasible: now
        from warpcut.planning import check_pinch

        check_pinch(job.pinch, contour, job.sim.validated(), allow=job.allow_infeasible_pinch)
    mesh_dir = None if job.export_mesh is None else Path(job.export_mesh)
    inputs = [job.contour] if isinstance(job.contour, str) else []
    # the figures, .rrd and .mp4 go into a run folder of their own, never beside a file the user named
    out = outputs.run_dir(out, "simulate")
    writes_out = job.plots or job.record is not None or job.video is not None
    out_option = "the output folder"
    paths = {"--json": json_path, "export_mesh": mesh_dir, out_option: out if writes_out else None}
    # before the simulation: a folder it could not write, a file it did not write
    outputs.check_outputs(paths, inputs, own=(out, "simulate"))
    with contextlib.ExitStack() as claims:  # the folders of its implicit outputs: warpcut's own, or new
        if writes_out:
            claims.enter_context(claim_run_dir(out, command="simulate", reuse=True, option=out_option))
        if mesh_dir is not None:
            claims.enter_context(
                claim_run_dir(mesh_dir, command="simulate", reuse=True, option="export_mesh")
            )
        if job.record is not None:
            from warpcut.viz.process import start_recorder_process

            start_recorder_process()  # its start-up overlaps the simulation's
        cuts = outputs.final_cuts(not job.plots)
        meshes = None
        if mesh_dir is not None:
            from warpcut.viz.mesh_export import MeshExports

            meshes = MeshExports(mesh_dir)
        config = job.sim.validated()
        start = time.perf_counter()
        here = out.absolute()  # the recorder's process starts in another folder
        with outputs.recorder(here, job.record, job.colour_by) as rec, videos(here, job.video) as vid:
            callbacks = with_videos(outputs.step_callbacks(rec, cuts, meshes), vid)
            given = {}
            if "generalist" in job.policy:
                given["generalist"] = _generalist(generalist, job, contour, config, device, callbacks)
            report = compare_policies(
                contour, job.policy, trials=job.trials, config=config, pinch=job.pinch, device=device,
                seed=job.seed, step_callbacks=callbacks, allow_infeasible_pinch=job.allow_infeasible_pinch,
                results=given,
            )  # fmt: skip
        elapsed = time.perf_counter() - start
        click.echo(
            f"contour {contour.name} ({'closed' if contour.closed else 'open'}, {contour.length:.1f} mm), "
            f"{job.trials} trial(s), {config.nx}x{config.ny} on {device}, {elapsed:.1f} s"
        )
        click.echo(
            f"{'policy':<10} {'error (vertices)':>16} {'error (mm^2)':>13} {'improvement':>12} "
            f"{'pinch (mm)':>16}"
        )
        undefined = False
        none_error = report["results"].get("none", {}).get("error_vertices", math.nan)
        for name, r in report["results"].items():
            ci = f" ±{r['ci95_pct']:.1f}" if job.trials > 1 else ""
            pinch_txt = "-" if r["pinch"] is None else point_text(r["pinch"])
            improvement = f"{r['improvement_pct']:>+11.1f}%{ci}"
            if not math.isfinite(r["improvement_pct"]):
                improvement, undefined = f"{'n/a':>12}", undefined or none_error < NEGLIGIBLE_ERROR
            click.echo(
                f"{name:<10} {r['error_vertices']:>16.1f} {r['error_mm2']:>13.1f} "
                f"{improvement} {pinch_txt:>16}{outputs.infeasible_mark(r['pinch_feasible'])}"
            )
        if undefined:
            click.echo(
                f"improvement n/a: no tension's error ({none_error:.2g} vertices) is zero within float "
                f"precision (under {NEGLIGIBLE_ERROR}): there is nothing to improve on"
            )
        outputs.echo_infeasible({name: r["pinch_problem"] for name, r in report["results"].items()})
        if json_path:
            from warpcut.io import write_json

            write_json(json_path, report)
            click.echo(f"wrote {json_path}")
        if cuts is not None:
            from warpcut.viz.plots import plot_regions

            outputs.echo_written(plot_regions(cuts.of(contour.name), out))
        outputs.echo_written(meshes.written if meshes is not None else [])
        outputs.echo_recording(rec)


def _generalist(generalist, job, contour, config, device, callbacks):
    """``generalist``'s trials (zero-shot) at ``job.pinch`` or the feasible centroid, paired with the
    baselines' (:func:`agents.generalist.generalist_result`)."""
    import numpy as np

    from agents.generalist import generalist_result
    from warpcut.planning import default_pinch

    point = (
        np.asarray(job.pinch, dtype=np.float64) if job.pinch is not None else default_pinch(contour, config)
    )
    return generalist_result(
        generalist, [contour], [point], None, job.trials, config, device, job.seed,
        on_step=callbacks and callbacks("generalist", 0), allow_infeasible_pinch=job.allow_infeasible_pinch,
    )  # fmt: skip
