"""``warpcut run``: the main job (:func:`agents.pipelines.run_pipeline`)."""

from __future__ import annotations

from pathlib import Path

import click

from agents.algorithms import ALGORITHMS, DEFAULT_ALGORITHM
from agents.cli import options, outputs, settings
from agents.cli.checks import check_planner_memory
from agents.config import BUDGETS, DEFAULT_BUDGET, DEFAULT_CONTOUR, DEFAULT_SELECTOR
from agents.methods import SELECTORS, point_text


@click.command("run", cls=settings.Command)
@options.contour_setting(DEFAULT_CONTOUR)
@click.option(
    "--budget",
    cls=options.Setting,
    key="budget",
    default=DEFAULT_BUDGET,
    show_default=True,
    type=click.Choice(list(BUDGETS)),
    help="; ".join(
        f"{name}: {b['candidates']} pinch candidates (plus the centroid when feasible), a policy for "
        + {None: "every one", 1: "the best one by fixed tension"}.get(
            b["rl_candidates"], f"each of the best {b['rl_candidates']}"
        )
        + f", {b['trials']} trials"
        for name, b in BUDGETS.items()
    )
    + ". fast: about a minute on 2 CPU cores; paper: hours. --policy generalist plans "
    + f"{BUDGETS[DEFAULT_BUDGET]['generalist_candidates']} candidates with either.",
)
@click.option(
    "--policy",
    "run_policy",
    cls=options.Setting,
    key="policy",
    default=DEFAULT_SELECTOR,
    show_default=True,
    type=click.Choice(SELECTORS),
    help="The tensioner that picks the pinch candidate: rl (a policy trained per candidate, the one that "
    "validates best wins); generalist (one policy for every contour, no training: seconds); fixed or "
    "analytic for a quick plan.",
)
@options.generalist_option
@click.option(
    "--algo",
    cls=options.Setting,
    key="train.algo",
    type=click.Choice(list(ALGORITHMS)),
    default=DEFAULT_ALGORITHM,
    show_default=True,
    help="The learner of --policy rl.",
)
@options.seed_option
@options.device_option
@options.ray_option("rl's pinch candidates (a policy each)")
@options.out_option("logs/run-CONTOUR-TIMESTAMP")
@options.run_dir_options
@options.json_option
@options.record_flag("in the run directory")
@options.config_options
def command(
    contour: str,
    budget: str,
    run_policy: str,
    generalist_source: str | None,
    algo: str,
    seed: int,
    device: str | None,
    ray: str | None,
    out: Path | None,
    resume: bool,
    overwrite: bool,
    json_path: Path | None,
    record_envs: int | None,
    config_file: str | None,
    overrides: tuple[str, ...],
    print_config: bool,
) -> None:
    """The main job: plan the cut, pick the pinch candidate with a tensioner (rl: a policy trained per
    candidate; generalist: one policy for every contour, no training), and compare it with none, fixed and
    analytic tensioning.

    Everything but the flags is set with --config FILE and --set KEY=VALUE (e.g. candidates, trials,
    sim.noise_std, env.randomize, train.iterations); --print-config shows them all.
    """
    import numpy as np

    from agents.cluster import executor
    from agents.jobs import RunJob
    from warpcut.io import safe_name, write_json
    from warpcut.planning import resolve_contour

    base = settings.resumed_job(RunJob, out, resume, "run")
    job = settings.resolve(RunJob, config_file, overrides, base)
    job.settings()
    if base is None:  # a resumed run's config.json holds every setting it was started with
        settings.refuse_unused_settings(job, overrides)
    contour_name = resolve_contour(job.contour, job.sim).name
    if job.policy == "rl":
        settings.check_learner(job)
    elif ray is not None:
        raise click.UsageError(
            f"--ray: --policy {job.policy} trains nothing to fan out (--policy rl trains a policy per pinch "
            "candidate); leave out --ray"
        )
    if print_config:
        settings.print_config(job)
        return
    check_planner_memory(job.settings()["candidates"], job.sim)
    inputs = [job.contour] if isinstance(job.contour, str) else []
    out, claim = outputs.claim(out, f"run-{safe_name(contour_name)}", resume, overwrite, "run")
    outputs.check_outputs({"--json": json_path}, inputs, own=(out, "run"))
    cuts = outputs.final_cuts(not job.plots)
    from agents.pipelines import run_pipeline  # torch: after every check, so that a refusal is quick

    with (
        claim,
        executor(ray, device, outputs.log) as units,
        outputs.recorder(out, job.record, job.colour_by) as rec,
    ):
        report = run_pipeline(
            job,
            out,
            resume=resume,
            device=device,
            log=outputs.log,
            step_callbacks=outputs.step_callbacks(rec, cuts),
            cluster=units,
        )
    name, row = report.contour.name, report.row
    chosen = report.candidates[report.chosen_candidate] if report.candidates else report.plan.chosen
    by = "planned" if job.policy in ("fixed", "analytic") else f"chosen by {job.policy}"
    if not report.table.get("generalist_holds_still"):
        gain, member = chosen.get("generalist_gain", 1.0), chosen.get("generalist_member")
        how = ([f"its moves x{gain:g}"] if gain != 1.0 else []) + ([f"member {member}"] if member else [])
        by += f" ({', '.join(how)})" if how else ""
    click.echo(
        f"{name}: {by}: order {list(chosen['order'])}, pinch {point_text(chosen['pinch'])}; "
        f"{report.table['trials']} trials, {report.seconds:.0f} s"
    )
    click.echo(f"{'method':<10} {'error (vertices)':>16} {'improvement':>14} {'pinch (mm)':>16}")
    for m in report.methods:
        p = row[f"{m}_pinch"]
        p_txt = "-" if p is None else point_text(p)
        imp = row[f"{m}_improvement_pct"]
        ci = f" ±{row[f'{m}_ci95']:.1f}" if report.table["trials"] > 1 else ""  # no CI of one sample
        imp_txt = f"{imp:+.1f}%{ci}" if np.isfinite(imp) else "n/a"
        if m == "none":  # the reference the others improve on
            imp_txt = "reference"
        mark = outputs.infeasible_mark(row.get(f"{m}_pinch_feasible"))
        click.echo(f"{m:<10} {row[f'{m}_error_vertices']:>16.1f} {imp_txt:>14} {p_txt:>16}{mark}")
    outputs.echo_infeasible({m: row.get(f"{m}_pinch_problem") for m in report.methods})
    if json_path:
        write_json(json_path, report.to_json())
    if cuts is not None:
        from agents.plots import plot_improvements
        from warpcut.viz.plots import plot_pinch_candidates, plot_regions

        titles = {
            run: f"{name}, pinch {point_text(c['pinch'])}"
            for c in report.candidates
            if (run := out / c.get("run", "")) in report.policy_runs
        }
        outputs.plot_learning_curves(titles)
        outputs.echo_written(plot_regions(cuts.of(name, report.methods), out))
        outputs.echo_written(plot_improvements(report.to_json(), report.methods[1:], out))
        outputs.echo_written(plot_pinch_candidates(report.plan, report.config, out))
    outputs.echo_recording(rec)
    click.echo(f"wrote {out}")
