"""``warpcut robustness``: the paper's sensitivity studies (Fig. 5) for trained policies, optimised plans and
the baselines (:func:`agents.pipelines.robustness`)."""

from __future__ import annotations

from pathlib import Path

import click

from agents.cli import options, outputs, settings
from agents.config import EVALUATION_TRIALS
from agents.methods import BASELINES


def _labelled(items: tuple[str, ...], flag: str, default) -> dict[str, str]:
    """``--FLAG [LABEL=]PATH`` values as ``{label: path}``; an unlabelled item ``k`` (of the list) is named
    ``default(k, path)``."""
    labelled: dict[str, str] = {}
    for k, item in enumerate(items):
        label, sep, path = item.partition("=")
        if not sep or Path(item).exists():  # a path whose name holds '='
            label, path = default(k, item), item
        if label in labelled:
            raise click.BadParameter(f"label {label!r} given twice", param_hint=flag)
        labelled[label] = path
    return labelled


def _labelled_runs(runs: tuple[str, ...]) -> dict[str, str]:
    """``--run [LABEL=]DIR`` values as ``{label: dir}``: one unlabelled run is ``rl``, several ``rl-1``..."""
    return _labelled(runs, "--run", lambda k, _: "rl" if len(runs) == 1 else f"rl-{k + 1}")


def _labelled_plans(plans: tuple[str, ...]) -> dict[str, str]:
    """``--plan [LABEL=]FILE`` values as ``{label: file}``; an unlabelled one is named after its file."""
    return _labelled(plans, "--plan", lambda _, path: Path(path).stem)


def _listed(ctx: click.Context, param: click.Parameter, value: str | None) -> list[str] | None:
    """A comma-separated option as a list."""
    return None if value is None else [v.strip() for v in value.split(",") if v.strip()]


@click.command("robustness", cls=settings.Command)
@options.contour_setting(note="default with --run: the run's")
@click.option(
    "--study",
    cls=options.Setting,
    key="study",
    default=None,
    callback=_listed,
    help="resolution (vertices per side), noise (process noise, mm) or force (gravity, mm/s^2); several "
    "comma-separated, or all. The sweep: --set values=[...] (one study; default: each study's own).",
)
@click.option(
    "--methods",
    cls=options.Setting,
    key="methods",
    default=",".join(BASELINES),
    show_default=True,
    callback=_listed,
    help="The methods besides the runs and plans: none, fixed, analytic, generalist (one policy for every "
    "contour, zero-shot; another than the shipped one: --set generalist=DIR), and grad (a plan optimised "
    "through the simulator on the nominal sheet, then played unchanged at every value; its optimiser: "
    "grad.*); none always runs, the others are measured against it.",
)
@click.option(
    "--run",
    "runs",
    cls=options.Setting,
    key="runs",
    multiple=True,
    metavar="[LABEL=]DIR",
    callback=lambda ctx, param, value: _labelled_runs(value),
    help="A trained policy's run (warpcut train or run) of the contour, repeatable: each is a method named "
    "LABEL (one run: rl). The first sets the pinch point, cut order and nominal sheet. Without: fixed "
    "tension at the plan's pinch point.",
)
@click.option(
    "--plan",
    "plans",
    cls=options.Setting,
    key="plans",
    multiple=True,
    metavar="[LABEL=]FILE",
    callback=lambda ctx, param, value: _labelled_plans(value),
    help="An optimised plan of the contour (warpcut optimize's NAME.json, or warpcut evaluate's "
    "grad/NAME.json), repeatable: each is a method named LABEL (default: the file's name), played as it was "
    "optimised at its own pinch point at every value.",
)
@options.count_option("trials", EVALUATION_TRIALS, "Seeded noisy trials per value and method.", key="trials")
@options.seed_option
@options.device_option
@options.ray_option("each method's batch of values")
@options.out_option("logs/robustness-CONTOUR-TIMESTAMP; robustness-STUDY.json and the figure")
@click.option(
    "--resume",
    is_flag=True,
    help="Continue the run in --out (interrupted, or to finish it): the studies it finished are read back, "
    "grad's plan is kept or continues from its state; the settings must be the run's (its config.json).",
)
@options.overwrite_option
@options.json_option
@options.config_options
def command(
    contour: str | None,
    study: list[str] | None,
    methods: list[str],
    runs: dict[str, str],
    plans: dict[str, str],
    trials: int,
    seed: int,
    device: str | None,
    ray: str | None,
    out: Path | None,
    resume: bool,
    overwrite: bool,
    json_path: Path | None,
    config_file: str | None,
    overrides: tuple[str, ...],
    print_config: bool,
) -> None:
    """Sweep mesh resolution, process noise or gravity around the nominal sheet and compare how each
    tensioner holds up (the paper's Fig. 5).

    Everything but the flags is set with --config FILE and --set KEY=VALUE (the sweep: values; the nominal
    sheet and noise without --run: sim.*; grad's optimiser: grad.*; plots); --print-config shows them all.
    """
    from agents.cluster import executor
    from agents.jobs import RobustnessJob
    from agents.pipelines import robustness
    from agents.pipelines.robustness import check_job, robustness_table
    from warpcut.io import safe_name, write_json
    from warpcut.planning import resolve_contour

    base = settings.resumed_job(RobustnessJob, out, resume, "robustness")
    job = settings.resolve(RobustnessJob, config_file, overrides, base)
    if base is None:  # a resumed run's config.json holds every setting it was started with
        settings.refuse_unused_settings(job, overrides)
    job = check_job(job)
    name = "run" if job.contour is None else resolve_contour(job.contour).name  # a bad one: now
    if print_config:
        settings.print_config(job)
        return
    out, claim = outputs.claim(out, f"robustness-{safe_name(name)}", resume, overwrite, "robustness")
    outputs.check_outputs(
        {"--json": json_path}, [job.contour] if isinstance(job.contour, str) else [], own=(out, "robustness")
    )
    with claim, executor(ray, device, outputs.log) as units:
        reports = robustness(job, out, resume=resume, device=device, log=outputs.log, cluster=units)
    for report in reports:
        click.echo("\n".join(robustness_table(report)))
        outputs.echo_infeasible(report.get("infeasible_pinches") or {})
        if report["skipped"]:
            click.echo(f"skipped (mesh too coarse): {', '.join(f'{v:g}' for v in report['skipped'])}")
    if json_path:
        write_json(
            json_path, reports[0] if len(reports) == 1 else {"studies": {r["study"]: r for r in reports}}
        )
    if job.plots:
        from agents.plots import plot_robustness

        outputs.echo_written(plot_robustness(reports, out))
    click.echo(f"wrote {out}")
