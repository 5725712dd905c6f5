"""``warpcut robustness``: the paper's sensitivity studies (Fig. 5) for trained policies and the baselines
(:func:`agents.robustness.robustness`)."""

from __future__ import annotations

from pathlib import Path

import click

from agents.cli import common
from agents.config import EVALUATION_TRIALS
from agents.methods import BASELINES
from warpcut.sim.config import SimConfig


@click.command("robustness")
@click.option(
    "--contour",
    "contour_name",
    default=None,
    help="Built-in name or a .json/.svg contour file (default with --run: the run's contour).",
)
@click.option(
    "--study",
    required=True,
    help="resolution (vertices per side), noise (process noise, mm) or force (gravity, mm/s^2); several "
    "comma-separated, or all.",
)
@click.option(
    "--run",
    "runs",
    multiple=True,
    metavar="[LABEL=]DIR",
    help="A trained policy's run (warpcut train or run) of the contour, repeatable: each is a method named "
    "LABEL (one run: rl). The first sets the pinch point, cut order and nominal sheet. Without: the "
    "baselines only, fixed at the plan's pinch point.",
)
@click.option(
    "--plan",
    "plans",
    multiple=True,
    metavar="[LABEL=]FILE",
    help="An optimised plan of the contour (warpcut optimize's NAME.json, or warpcut evaluate's "
    "grad/NAME.json), repeatable: each is a method named LABEL (default: the file's name), played as it was "
    "optimised (open or closed loop) at its own pinch point at every value.",
)
@click.option(
    "--methods",
    default=",".join(BASELINES),
    show_default=True,
    help="The methods to run besides the policies: none, fixed, analytic, and grad (an open-loop plan "
    "optimised through the simulator on the nominal sheet, then played unchanged at every value); none "
    "always runs, the others are measured against it.",
)
@click.option(
    "--values",
    default=None,
    help="The sweep, comma-separated (one study only; default: agents.robustness.STUDY_VALUES).",
)
@common.count_option("trials", EVALUATION_TRIALS, "Seeded noisy trials per value and method.")
@common.noise_option
@common.score_option
@common.device_option
@common.seed_option
@common.out_option("logs/robustness-CONTOUR-TIMESTAMP; robustness-STUDY.json and the figure")
@common.run_dir_options
@common.json_option
@common.plots_option("robustness.png/svg in the run directory")
def command(
    contour_name: str | None,
    study: str,
    runs: tuple[str, ...],
    plans: tuple[str, ...],
    methods: str,
    values: str | None,
    trials: int,
    noise: float,
    score: str,
    device: str | None,
    seed: int,
    out: Path | None,
    resume: bool,
    overwrite: bool,
    json_path: Path | None,
    no_plots: bool,
) -> None:
    """Sweep mesh resolution, process noise or gravity around the nominal sheet and compare how each
    tensioner holds up (the paper's Fig. 5)."""
    from agents.robustness import STUDY_METHODS, check_runs, parse_studies, robustness, robustness_table
    from warpcut.contours import load_contour
    from warpcut.io import safe_name, write_json

    try:
        studies = parse_studies(study)
    except ValueError as error:
        raise click.BadParameter(str(error).split(": ", 1)[1], param_hint="--study") from None
    labelled, plan_files = _labelled_runs(runs), _labelled_plans(plans)
    try:
        checked = check_runs(labelled or None)
    except ValueError as error:
        raise click.BadParameter(str(error).split(": ", 1)[1], param_hint="--run") from None
    if contour_name is None and not checked:
        raise click.UsageError("--contour: give the contour (or --run, whose contour is used)")
    if checked:
        for flag, name in (("--noise", "noise"), ("--score", "score")):
            source = click.get_current_context().get_parameter_source(name)
            if source == click.core.ParameterSource.COMMANDLINE:
                raise click.UsageError(f"{flag}: with --run the nominal sheet is the run's; drop {flag}")
    baselines = common.parse_methods(methods, "--methods", STUDY_METHODS)
    sweep = _parse_values(values)
    common.check_outputs({"--json": json_path}, [contour_name] if contour_name else [])
    name = load_contour(contour_name).name if contour_name else "run"
    out, claim = common.claim(out, f"robustness-{safe_name(name)}", resume, overwrite)
    with claim:
        reports = robustness(
            contour_name, studies, out, runs=checked, plans=plan_files, methods=baselines,
            values=sweep, trials=trials,
            config=SimConfig(noise_std=noise, score=score), device=device, seed=seed, resume=resume,
            log=common.log,
        )  # fmt: skip
    for report in reports:
        click.echo("\n".join(robustness_table(report)))
        if report["skipped"]:
            click.echo(f"skipped (mesh too coarse): {', '.join(f'{v:g}' for v in report['skipped'])}")
    if json_path:
        write_json(
            json_path, reports[0] if len(reports) == 1 else {"studies": {r["study"]: r for r in reports}}
        )
    if not no_plots:
        from warpcut.viz.plots import plot_robustness

        common.echo_written(plot_robustness(reports, out))
    click.echo(f"wrote {out}")


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


def _parse_values(values: str | None) -> list[float] | None:
    """``--values`` as numbers (None: the study's defaults)."""
    if values is None:
        return None
    try:
        return [float(v) for v in values.split(",") if v.strip()]
    except ValueError:
        raise click.BadParameter(
            f"expected numbers, e.g. 0,0.05,0.1 (got {values!r})", param_hint="--values"
        ) from None
