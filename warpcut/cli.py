"""The ``warpcut`` command line.

Every command has ``--help``; bad input exits with status 2 and a one-line ``error: ...`` naming what
to fix, never a traceback.
"""

from __future__ import annotations

import functools
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import click

from warpcut.sim.config import ARM_LENGTH_MM, ARM_RADIUS_MM, FIXTURES, SCORES, SimConfig
from warpcut.viz.process import RecordingError

POLICY_NAMES = ("none", "fixed", "analytic")


class CleanErrors(click.Group):
    """Turn usage errors, the library's ValueErrors and files that cannot be read or written (an OSError
    naming a path; with ``WARPCUT_VERBOSE`` set, its traceback instead) into one line on stderr and exit
    status 2; a failed recording (:class:`RecordingError`) into one line and status 1
    (with ``WARPCUT_VERBOSE`` set, also the recorder process's traceback)."""

    def main(self, *args, **kwargs):
        kwargs["standalone_mode"] = False
        try:
            result = super().main(*args, **kwargs)
        except click.exceptions.Abort:
            click.echo("interrupted", err=True)
            sys.exit(130)
        except click.ClickException as exc:
            hint = (
                f" (see 'warpcut {exc.ctx.command.name} --help')"
                if getattr(exc, "ctx", None) and exc.ctx.command is not self
                else ""
            )
            message = exc.format_message()
            if isinstance(exc, click.NoSuchOption) and (value := _negative_record(kwargs, args, exc)):
                # click reads "--record -1" (an option whose value is optional) as --record, then -1.
                message = f"--record: N must be a positive integer (got {value})"
            click.echo(f"error: {message}{hint}", err=True)
            sys.exit(2)
        except (ValueError, FileNotFoundError) as exc:
            click.echo(f"error: {exc}", err=True)
            sys.exit(2)
        except OSError as exc:  # a file that cannot be read or written (a path named), unless debugging
            if exc.filename is None or os.environ.get("WARPCUT_VERBOSE"):
                raise
            click.echo(f"error: {exc}", err=True)
            sys.exit(2)
        except RecordingError as exc:  # the file holds what was recorded until then
            click.echo(f"error: {exc}", err=True)
            for note in getattr(exc, "__notes__", ()) if os.environ.get("WARPCUT_VERBOSE") else ():
                click.echo(note, err=True)
            sys.exit(1)
        sys.exit(result if isinstance(result, int) else 0)


def _negative_record(kwargs: dict, args: tuple, exc: click.NoSuchOption) -> str | None:
    """The negative number given to ``--record`` that click took for the unknown option ``exc`` names,
    if that is what happened."""
    given = list(kwargs.get("args") or (args[0] if args else sys.argv[1:]))
    for k, token in enumerate(given):
        if token == "--record" and k + 1 < len(given):
            value = given[k + 1]
        elif token.startswith("--record="):
            value = token.split("=", 1)[1]
        else:
            continue
        if re.fullmatch(r"-\d[\d.eE+-]*", value) and value.startswith(exc.option_name):
            return value
    return None


RECORD_COLOURS = ("strain", "height")
"""``--colour-by`` choices: :data:`warpcut.viz.recording.COLOUR_FIELDS` (not imported here: slow to load)."""


def _record_option(what: str):
    """``--record [N]`` and ``--colour-by`` (passed to the command as ``record_envs`` and ``colour_by``)."""
    record = click.option(
        "--record",
        "record_envs",
        type=click.IntRange(min=1),
        is_flag=False,
        flag_value=1,
        default=None,
        metavar="[N]",
        help=f"Write recording.rrd ({what}) of the first N envs (default 1) of each method; "
        "view it with 'warpcut replay'.",
    )
    colour = click.option(
        "--colour-by",
        type=click.Choice(RECORD_COLOURS),
        default="strain",
        show_default=True,
        help="What the recorded sheet's vertex colours show: the stretch of its springs, or its height.",
    )

    def check(command):
        @functools.wraps(command)
        def checked(**kwargs):
            source = click.get_current_context().get_parameter_source("colour_by")
            if kwargs["record_envs"] is None and source == click.core.ParameterSource.COMMANDLINE:
                raise click.UsageError(
                    "--colour-by: colours a recording; add --record [N], or drop --colour-by"
                )
            if kwargs["record_envs"] is not None:
                from warpcut.viz.process import start_recorder_process

                start_recorder_process()  # its start-up overlaps the command's own
            return command(**kwargs)

        return checked

    return lambda command: record(colour(check(command)))


_device_option = click.option(
    "--device", default=None, help="Warp device: cpu or cuda (default: cuda if available, else cpu)."
)
_seed_option = click.option(
    "--seed",
    default=0,
    show_default=True,
    type=click.IntRange(min=0),
    help="Seed of everything random (noise, sampling, PPO); a non-negative integer.",
)


DEFAULTS = SimConfig()
"""The library's defaults, which the options below show and pass on (one set for library and CLI)."""

_noise_option = click.option(
    "--noise",
    default=DEFAULTS.noise_std,
    show_default=True,
    type=click.FloatRange(min=0.0),
    help="Process noise sigma (mm per update): seeded trials differ by their noise stream; 0: noise-free.",
)
_score_option = click.option(
    "--score",
    default=DEFAULTS.score,
    show_default=True,
    type=click.Choice(SCORES),
    help="What tables and rewards use: path (the paper's: the region the scissors' path through the "
    "material encloses) or separated (the material that came free). Both are reported.",
)


def _protocol_sim(config: SimConfig) -> dict:
    """The protocol fields of ``config`` as a scenario's ``sim`` dict (stored with a trained run)."""
    sim = {"noise_std": config.noise_std, "score": config.score}
    if config.resolution != DEFAULTS.resolution:
        sim["resolution"] = config.resolution
    return sim


_arm_length_option = click.option(
    "--arm-length",
    default=ARM_LENGTH_MM,
    show_default=True,
    type=click.FloatRange(min=0.0),
    help="Reach of the cutting arm's footprint from the scissor tip toward +x (mm), for pinch feasibility; "
    "inf (the paper's cylinder): the whole way, so the grasp never holds the piece being cut; a short "
    "footprint (e.g. 15) lets it hold the piece (docs/learning.md).",
)


_analytic_pinch_option = click.option(
    "--analytic-pinch",
    default="feasible",
    show_default=True,
    type=click.Choice(["feasible", "centroid"]),
    help="Where the analytic policy pinches: the centroid (the paper's choice) when it is feasible, else the "
    "feasible point nearest to it (feasible); or the centroid even under the cutting arm or on the cut line "
    "(centroid: a grasp the robot could not make).",
)


def _analytic_pinches(mode: str, contours, plans) -> list | None:
    """Per contour, the analytic policy's pinch point for ``--analytic-pinch`` (None: its own default, the
    feasible centroid without an arm footprint)."""
    import numpy as np

    if mode == "centroid":
        return [np.asarray(c.centroid, dtype=np.float64) for c in contours]
    return None if plans is None else [p.analytic_pinch for p in plans]


def _plots_option(what: str):
    return click.option("--no-plots", is_flag=True, help=f"Do not write the plots ({what}).")


def _parse_point(value: str | None, name: str) -> tuple[float, float] | None:
    if value is None:
        return None
    try:
        x, y = (float(v) for v in value.split(","))
    except ValueError:
        raise click.BadParameter(f"expected X,Y in mm, e.g. 60,40 (got {value!r})", param_hint=name) from None
    return x, y


def _parse_policies(value: str) -> list[str]:
    names = [v.strip() for v in value.split(",") if v.strip()]
    unknown = [n for n in names if n not in POLICY_NAMES]
    if not names or unknown:
        raise click.BadParameter(
            f"unknown {', '.join(unknown) or 'empty list'}; choose from {','.join(POLICY_NAMES)}",
            param_hint="--policy",
        )
    return names


@click.group(cls=CleanErrors, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="warpcut")
def main() -> None:
    """Simulate, plan and learn tensioning for surgical pattern cutting."""


@main.command()
@click.option(
    "--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write the list here."
)
def contours(json_path: Path | None) -> None:
    """List the built-in contours (name, closed/open, length)."""
    from warpcut.contours import builtin_contours

    suite = builtin_contours()
    rows = [
        {
            "name": c.name,
            "closed": c.closed,
            "length_mm": round(c.length, 2),
            "area_mm2": round(c.area_mm2, 1),
        }
        for c in suite.values()
    ]
    click.echo(f"{'name':<18} {'kind':<7} {'length (mm)':>11} {'area (mm^2)':>11}")
    for r in rows:
        click.echo(
            f"{r['name']:<18} {'closed' if r['closed'] else 'open':<7} {r['length_mm']:>11.1f} "
            f"{r['area_mm2']:>11.1f}"
        )
    if json_path:
        from warpcut.io import write_json

        write_json(json_path, {"contours": rows})


@main.command()
@click.option("--contour", "contour_name", required=True, help="Built-in name or a .json/.svg contour file.")
@click.option(
    "--policy",
    "policies",
    default="none,fixed,analytic",
    show_default=True,
    help="Comma-separated tensioners to compare.",
)
@click.option("--pinch", default=None, help="Pinch point X,Y (mm, material) for fixed and analytic.")
@click.option(
    "--trials",
    default=1,
    show_default=True,
    type=click.IntRange(min=1),
    help="Seeded trials per policy (they differ by process noise).",
)
@_noise_option
@_score_option
@click.option(
    "--resolution", default=25, show_default=True, type=click.IntRange(5, 100), help="Vertices per side."
)
@click.option("--fixture", default="corners", show_default=True, type=click.Choice(FIXTURES))
@_device_option
@_seed_option
@click.option(
    "--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write results here."
)
@_record_option("next to --json, or in logs/simulate-TIMESTAMP")
@_plots_option("regions.png/svg next to --json, or in logs/simulate-TIMESTAMP")
def simulate(
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
    no_plots: bool,
) -> None:
    """Cut a contour with each baseline tensioner and compare their errors."""
    from agents.evaluation import compare_policies
    from warpcut.contours import load_contour
    from warpcut.sim.simulator import resolve_device

    names = _parse_policies(policies)
    point = _parse_point(pinch, "--pinch")
    device = resolve_device(device)
    contour = load_contour(contour_name)
    config = SimConfig(resolution=resolution, fixture=fixture, noise_std=noise, score=score).validated()
    out = json_path.parent if json_path else _run_dir(None, "simulate")
    cuts = None
    if not no_plots:
        from warpcut.viz.plots import FinalCuts

        cuts = FinalCuts()
    start = time.perf_counter()
    with _recorder(out, record_envs, colour_by) as recorder:
        report = compare_policies(
            contour,
            names,
            trials=trials,
            config=config,
            pinch=point,
            device=device,
            seed=seed,
            on_step=_step_hooks(recorder, cuts),
        )
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
        pinch_txt = "-" if r["pinch"] is None else f"({r['pinch'][0]:.1f}, {r['pinch'][1]:.1f})"
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

        _echo_written(plot_regions(cuts.of(contour.name), out))
    _echo_recording(recorder)


def _recorder(out: Path, record_envs: int | None, colour_by: str):
    """A :class:`Recorder` of ``out/recording.rrd``, or a null context when not recording."""
    import contextlib

    if record_envs is None:
        return contextlib.nullcontext()
    from warpcut.viz.recording import Recorder

    return Recorder(out / "recording.rrd", envs=record_envs, colour_by=colour_by)


def _step_hooks(*hooks):
    """One ``on_step(method)`` factory calling every hook's (objects with ``on_step(method)``; None: off)."""
    hooks = [h for h in hooks if h is not None]
    if not hooks:
        return None
    if len(hooks) == 1:
        return hooks[0].on_step

    def for_method(method: str):
        callbacks = [h.on_step(method) for h in hooks]

        def on_step(task, action) -> None:
            for callback in callbacks:
                callback(task, action)

        return on_step

    return for_method


def _echo_recording(recorder) -> None:
    """Say where the recording went (if anything was recorded), and which methods had fewer envs than
    ``--record`` asked for."""
    if recorder is None or not recorder.written:
        return
    fewer = {m: k for m, k in recorder.recorded_envs.items() if k < recorder.envs}
    if fewer:
        ran = ", ".join(f"{m}: {k}" for m, k in fewer.items())
        click.echo(
            f"warning: --record {recorder.envs}: fewer envs ran, all of them recorded ({ran})", err=True
        )
    _echo_written([recorder.path])


def _echo_written(paths: list[Path]) -> None:
    for path in paths:
        click.echo(f"wrote {path}")


@main.command()
@_device_option
@click.option(
    "--repeats", default=3, show_default=True, type=click.IntRange(min=1), help="Timed repeats (median)."
)
@click.option(
    "--batch-sizes", default="1,64,1024,4096", show_default=True, help="Comma-separated batch sizes."
)
@click.option(
    "--rollout-envs",
    default=256,
    show_default=True,
    type=click.IntRange(min=1),
    help="Batch size of the fls-circle rollout measurement.",
)
@click.option(
    "--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write results here."
)
def bench(
    device: str | None, repeats: int, batch_sizes: str, rollout_envs: int, json_path: Path | None
) -> None:
    """Measure simulator throughput (medians over repeats, all in one run)."""
    from warpcut.bench import run_bench
    from warpcut.sim.simulator import resolve_device

    try:
        sizes = tuple(int(v) for v in batch_sizes.split(","))
    except ValueError:
        raise click.BadParameter(
            f"expected integers like 1,64,1024 (got {batch_sizes!r})", param_hint="--batch-sizes"
        ) from None
    if not sizes or min(sizes) < 1:
        raise click.BadParameter("batch sizes must be positive", param_hint="--batch-sizes")
    device = resolve_device(device)
    result = run_bench(
        device,
        repeats=repeats,
        batch_sizes=sizes,
        rollout_envs=rollout_envs,
        progress=lambda what: click.echo(f"  measuring {what} ...", err=True),
    )
    click.echo(f"device {result['device']} ({result['device_name']}), 25x25 sheet, median of {repeats}")
    click.echo(
        f"cold start (compile) {result['cold_start_s']:.2f} s, warm start {result['warm_start_s']:.2f} s"
    )
    click.echo(
        f"{'batch':>6} {'updates/s (default: shear, 20 sweeps)':>38} {'updates/s (paper: 5 sweeps)':>28}"
    )
    for b in result["updates_per_s"]:
        click.echo(
            f"{b:>6} {result['updates_per_s'][b]:>38,.0f} {result['updates_per_s_paper_sweeps'][b]:>28,.0f}"
        )
    for b, rate in result["updates_per_s_noise_free"].items():
        click.echo(f"default physics without process noise, B={b}: {rate:,.0f} updates/s")
    click.echo(
        f"fls-circle no-tension rollouts/s (B={result['rollout_envs']}): {result['rollouts_per_s']:,.1f} "
        f"default physics, {result['rollouts_per_s_paper_sweeps']:,.1f} paper sweeps; the path score adds "
        f"{result['scoring_overhead_pct']:.1f}%"
    )
    click.echo(
        f"NumPy reference updates/s: {result['numpy_updates_per_s']:,.1f}  "
        f"(Warp best / NumPy = {result['speedup_vs_numpy']:,.0f}x)"
    )
    click.echo(f"PPO training env steps/s (64 envs): {result['train_steps_per_s']:,.0f}")
    if json_path:
        from warpcut.io import write_json

        write_json(json_path, result)
        click.echo(f"wrote {json_path}")


def _run_dir(out: Path | None, prefix: str) -> Path:
    """``out`` or a fresh ``logs/PREFIX-YYYYmmdd-HHMMSS`` directory."""
    if out is not None:
        return out
    stamp = time.strftime("%Y%m%d-%H%M%S")
    path = Path("logs") / f"{prefix}-{stamp}"
    suffix = 1
    while path.exists():
        path = Path("logs") / f"{prefix}-{stamp}-{suffix}"
        suffix += 1
    return path


@main.command()
@click.option("--contour", "contour_name", required=True, help="Built-in name or a .json/.svg contour file.")
@click.option(
    "--pinch", default=None, help="Pinch point X,Y (mm); default: centroid or nearest feasible point."
)
@click.option("--num-envs", default=64, show_default=True, type=click.IntRange(min=1), help="Parallel envs.")
@click.option(
    "--iterations",
    default=100,
    show_default=True,
    type=click.IntRange(min=1),
    help="PPO iterations in total (a resumed run continues up to this count).",
)
@click.option(
    "--steps-per-env",
    default=32,
    show_default=True,
    type=click.IntRange(min=1),
    help="Env steps per env per PPO iteration.",
)
@_noise_option
@_score_option
@click.option(
    "--reward",
    default="dense",
    show_default=True,
    type=click.Choice(["sparse", "dense"]),
    help="sparse: -(final error / area) at the last step only (paper); dense: plus per-step shaping by the "
    "cut's deviation from the contour in material coordinates (learns in short runs, docs/learning.md).",
)
@click.option(
    "--observe",
    default="contour",
    show_default=True,
    type=click.Choice(["fiducials", "contour"]),
    help="fiducials: time, grasp displacement, 12 fiducials (paper); contour: plus the scissor tip and the "
    "vector to the contour point it is about to cut.",
)
@click.option(
    "--actions",
    "action_type",
    default="discrete",
    show_default=True,
    type=click.Choice(["discrete", "continuous"]),
    help="discrete: stay, +-x, +-y (and +-z) at 1 mm (paper: x-y); continuous: moves up to 1 mm per axis.",
)
@click.option(
    "--z/--no-z",
    "allow_z",
    default=True,
    show_default=True,
    help="Let the grasp also move along z (lift or lower the sheet); --no-z: x-y only (paper).",
)
@click.option(
    "--stay-prior",
    default=0.9,
    show_default=True,
    type=click.FloatRange(0.0, 1.0, max_open=True),
    help="Discrete: initial probability of 'stay', so training starts from holding still (fixed "
    "tensioning); 0: a uniform start (paper).",
)
@click.option(
    "--validation-trials",
    default=16,
    show_default=True,
    type=click.IntRange(min=0),
    help="Held-out episodes scoring the policy every 10 iterations; the best is kept (best.pt). 0: off, "
    "the last policy is the run's.",
)
@click.option(
    "--eval-trials",
    default=10,
    show_default=True,
    type=click.IntRange(min=1),
    help="Trials of the final evaluation against no tension.",
)
@_device_option
@_seed_option
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Run directory (default: logs/train-CONTOUR-TIMESTAMP).",
)
@click.option(
    "--resume",
    type=click.Path(exists=True, path_type=Path),
    default=None,
    help="Run directory or checkpoint to continue from (writes into it unless --out is given).",
)
@_record_option("of the final evaluation, in the run directory")
@_plots_option("learning_curve.png/svg in the run directory")
@click.option("--no-progress", is_flag=True, help="Hide the progress bar.")
def train(
    contour_name: str,
    pinch: str | None,
    num_envs: int,
    iterations: int,
    steps_per_env: int,
    noise: float,
    score: str,
    reward: str,
    observe: str,
    action_type: str,
    allow_z: bool,
    stay_prior: float,
    validation_trials: int,
    eval_trials: int,
    device: str | None,
    seed: int,
    out: Path | None,
    resume: Path | None,
    record_envs: int | None,
    colour_by: str,
    no_plots: bool,
    no_progress: bool,
) -> None:
    """Train a PPO tensioning policy (rsl-rl, 2x32 MLP, 1 mm moves) for one contour."""
    from agents.rl import Scenario, load_scenario, train_contour
    from agents.train import TrainConfig
    from warpcut.contours import load_contour
    from warpcut.sim.simulator import resolve_device

    device = resolve_device(device)
    point = _parse_point(pinch, "--pinch")
    if resume is not None:
        scenario = load_scenario(resume if resume.is_dir() else resume.parent)
        out = out or (resume if resume.is_dir() else resume.parent)
    else:
        contour = load_contour(contour_name)
        scenario = Scenario(
            contour=contour_name,
            pinch=None if point is None else list(point),
            sim=_protocol_sim(SimConfig(noise_std=noise, score=score).validated()),
            action_type=action_type,
            dense_reward=reward == "dense",
            contour_features=observe == "contour",
            allow_z=allow_z,
        )
        scenario.pinch_point()  # fail early on an infeasible default pinch
        out = _run_dir(out, f"train-{contour.name}")
    cfg = TrainConfig(
        num_envs=num_envs,
        iterations=iterations,
        num_steps_per_env=steps_per_env,
        seed=seed,
        device="cpu",
        discrete=scenario.action_type == "discrete",
        stay_prior=stay_prior if scenario.action_type == "discrete" else 0.0,
    )
    click.echo(f"training {scenario.contour} into {out} ({num_envs} envs, {iterations} iterations, {device})")
    try:
        with _recorder(out, record_envs, colour_by) as recorder:
            result = train_contour(
                scenario,
                out,
                cfg,
                resume=resume,
                eval_trials=eval_trials,
                progress=not no_progress,
                device=device,
                validation_trials=validation_trials,
                on_step=None if recorder is None else recorder.on_step,
            )
    except KeyboardInterrupt:
        click.echo(f"interrupted: checkpoint saved in {out}; continue with --resume {out}", err=True)
        sys.exit(130)
    s, e = result["summary"], result["evaluation"]
    click.echo(
        f"done: {s['iterations']} iterations, {s['env_steps']:,} env steps in {s['wall_time_s']:.0f} s "
        f"({s['steps_per_s']:,.0f} steps/s)"
    )
    click.echo(
        f"evaluation ({e['trials']} trials): no tension {e['none_error_vertices']:.1f} vertices, "
        f"rl {e['rl_error_vertices']:.1f} vertices, improvement {e['rl_improvement_pct']:+.1f}% "
        f"± {e['rl_ci95']:.1f}"
    )
    if not no_plots:
        from warpcut.viz.plots import plot_learning_curve

        _echo_written(plot_learning_curve(s["history"], s["validation"], out, title=scenario.contour))
    _echo_recording(recorder)
    click.echo(f"wrote {out}")


@main.command()
@click.argument("run_dir", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Where to write policy.pt and policy.onnx (default: RUN_DIR/exported).",
)
def export(run_dir: Path, out: Path | None) -> None:
    """Export a trained policy as TorchScript and ONNX (observation -> action index)."""
    from agents.export import export_policy

    paths = export_policy(run_dir, out)
    for kind, path in paths.items():
        click.echo(f"{kind}: {path}")


EVALUATE_METHODS = ("none", "fixed", "analytic", "rl")


@main.command()
@click.option(
    "--contours",
    "contour_args",
    multiple=True,
    default=("all",),
    show_default=True,
    help="'all' (the built-in suite), names or contour files; repeat or comma-separate.",
)
@click.option(
    "--methods", default="none,fixed,analytic,rl", show_default=True, help="Comma-separated methods."
)
@click.option(
    "--trials", default=10, show_default=True, type=click.IntRange(min=1), help="Trials per contour."
)
@_noise_option
@_score_option
@click.option(
    "--checkpoints",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    default=None,
    help="Directory of trained runs, one per contour (CHECKPOINTS/NAME, as 'warpcut train' writes); "
    "without it the rl column trains a policy per contour.",
)
@click.option(
    "--iterations",
    default=100,
    show_default=True,
    type=click.IntRange(min=1),
    help="PPO iterations per contour when training.",
)
@click.option(
    "--num-envs", default=64, show_default=True, type=click.IntRange(min=1), help="Envs when training."
)
@_device_option
@_seed_option
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Run directory (default: logs/evaluate-TIMESTAMP): results and trained policies.",
)
@click.option(
    "--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write results here."
)
@click.option(
    "--markdown",
    "markdown_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the table as Markdown here.",
)
@click.option(
    "--plan/--no-plan",
    default=True,
    show_default=True,
    help="Cut every contour as planned (segments, order) and pinch fixed and rl at the planned point "
    "(analytic at the centroid, as in the paper; see --analytic-pinch); --no-plan: one loop per contour, "
    "fixed by random search, rl at the centroid (or the feasible point nearest to it).",
)
@click.option(
    "--candidates",
    default=30,
    show_default=True,
    type=click.IntRange(min=1),
    help="Pinch candidates per plan.",
)
@_arm_length_option
@_analytic_pinch_option
@_record_option("in the run directory; of the first contour, at most --trials envs")
@_plots_option(
    "improvement.png/svg, regions/CONTOUR.png/svg and plans/CONTOUR.png/svg in the run directory, and "
    "policies/CONTOUR/learning_curve.png/svg when training"
)
def evaluate(
    contour_args: tuple[str, ...],
    methods: str,
    trials: int,
    noise: float,
    score: str,
    checkpoints: Path | None,
    iterations: int,
    num_envs: int,
    plan: bool,
    candidates: int,
    arm_length: float,
    analytic_pinch: str,
    device: str | None,
    seed: int,
    out: Path | None,
    json_path: Path | None,
    markdown_path: Path | None,
    record_envs: int | None,
    colour_by: str,
    no_plots: bool,
) -> None:
    """The paper's Table I: per contour the no-tension error and each method's improvement (95% CI)."""
    from agents.evaluation import MethodResult, evaluate_suite
    from warpcut.contours import builtin_names, load_contour
    from warpcut.io import write_atomic, write_json
    from warpcut.sim.simulator import resolve_device

    names = [m.strip() for m in methods.split(",") if m.strip()]
    unknown = [m for m in names if m not in EVALUATE_METHODS]
    if not names or unknown:
        raise click.BadParameter(
            f"unknown {', '.join(unknown) or 'empty list'}; choose from {','.join(EVALUATE_METHODS)}",
            param_hint="--methods",
        )
    specs = [s.strip() for arg in contour_args for s in arg.split(",") if s.strip()]
    if "all" in specs:
        specs = [s for s in specs if s != "all"] + [n for n in builtin_names() if n not in specs]
    contours = [load_contour(s) for s in specs]
    by_name = dict(zip([c.name for c in contours], specs, strict=True))
    device = resolve_device(device)
    config = SimConfig(noise_std=noise, score=score).validated()
    if record_envs is not None and record_envs > trials:
        click.echo(
            f"warning: --record {record_envs}: the first contour has only {trials} env(s) per method "
            f"(--trials); recording {trials}",
            err=True,
        )
        record_envs = trials
    out = _run_dir(out, "evaluate")
    start = time.perf_counter()
    plans = None
    if plan:
        from warpcut.planning import plan_cut

        plans = []
        for contour in contours:
            click.echo(f"  planning {contour.name} ({candidates} candidates)", err=True)
            plans.append(
                plan_cut(
                    contour,
                    config.replace(noise_std=0.0),
                    num_candidates=candidates,
                    seed=seed,
                    device=device,
                    arm_length_mm=arm_length,
                )
            )
        write_json(out / "plans.json", {p.contour.name: p.to_json() for p in plans})
    pinches = {} if plans is None else {"fixed": [p.chosen["pinch"] for p in plans]}
    analytic = _analytic_pinches(analytic_pinch, contours, plans)
    if analytic is not None:
        pinches["analytic"] = analytic
    cuts = None
    if not no_plots:
        from warpcut.viz.plots import FinalCuts

        cuts = FinalCuts()
    extra = {}
    with _recorder(out, record_envs, colour_by) as recorder:
        hooks = _step_hooks(recorder, cuts)
        if "rl" in names:
            regions = _step_hooks(cuts)

            def rl_hook(k: int):  # the recorder sees the first contour's batch only
                hook = hooks if k == 0 else regions
                return None if hook is None else hook("rl")

            extra["rl"] = _rl_results(
                contours,
                by_name,
                checkpoints,
                out,
                trials,
                _protocol_sim(config),
                iterations,
                num_envs,
                device,
                seed,
                MethodResult,
                plans,
                rl_hook,
                plots=not no_plots,
            )
        report = evaluate_suite(
            contours,
            names,
            trials=trials,
            config=config,
            device=device,
            seed=seed,
            extra=extra,
            progress=lambda what: click.echo(f"  running {what}", err=True),
            on_step=hooks,
            segments=None if plans is None else [p.ordered_segments() for p in plans],
            pinches=pinches,
        )
    report["planned"] = plans is not None
    report["analytic_pinch"] = analytic_pinch
    report["seconds"] = time.perf_counter() - start
    table = _markdown_table(report, names)
    click.echo(table)
    click.echo(f"({len(contours)} contours x {trials} trials in {report['seconds']:.0f} s)")
    write_json(out / "results.json", report)
    if json_path:
        write_json(json_path, report)
    if markdown_path:
        write_atomic(markdown_path, table + "\n")
    if not no_plots:
        from warpcut.viz.plots import plot_improvements, plot_pinch_candidates

        _echo_written(plot_improvements(report, names, out))
        shown = ["none"] + [m for m in names if m != "none"]
        _echo_written(cuts.plot(out / "regions", shown, [c.name for c in contours]))
        for p in plans or []:
            _echo_written(plot_pinch_candidates(p, config, out / "plans", name=p.contour.name))
    _echo_recording(recorder)
    click.echo(f"wrote {out}")


VIEWER = [sys.executable, "-m", "rerun_cli"]
"""The rerun viewer (rerun-sdk's ``rerun`` command), as ``replay`` runs it."""

VIEWER_START_S = 3.0
"""How long ``replay`` watches the viewer it started: one that ends within this time with an error could
not open a window, and ``replay`` then prints what it prints without a display."""


@main.command()
@click.argument("path", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--web", is_flag=True, help="Serve the web viewer on http://127.0.0.1:9090 instead (Ctrl-C stops it)."
)
def replay(path: Path, web: bool) -> None:
    """Open a recording (.rrd from --record) in the rerun viewer.

    Without a display (no DISPLAY or WAYLAND_DISPLAY) it prints how to view the file and what it holds;
    so it does, exiting with status 1, where the viewer ends at once (a display that cannot be reached).
    """
    from warpcut.viz.recording import read_summary

    summary = read_summary(path)
    viewer = VIEWER
    if web:
        click.echo(f"serving {path} at http://127.0.0.1:9090 (gRPC on port 9876); Ctrl-C stops it")
        sys.exit(subprocess.run([*viewer, "--web-viewer", "--bind", "127.0.0.1", str(path)]).returncode)
    has_display = sys.platform in ("darwin", "win32") or any(
        os.environ.get(v) for v in ("DISPLAY", "WAYLAND_DISPLAY")
    )
    if has_display:
        with tempfile.TemporaryFile() as log:  # not a pipe: the viewer outlives this command
            process = subprocess.Popen(
                [*viewer, str(path)], stdout=subprocess.DEVNULL, stderr=log, start_new_session=True
            )
            try:  # a viewer that cannot open a window (a display that is set but unreachable) ends at once
                code = process.wait(timeout=VIEWER_START_S)
            except subprocess.TimeoutExpired:
                click.echo(f"opened {path} in the rerun viewer")
                return
            log.seek(0)
            said = re.sub(r"\x1b\[[0-9;]*m", "", log.read().decode(errors="replace")).splitlines()
        errors = [line.strip() for line in said if line.startswith("Error")]
        if code == 0 and not errors:  # e.g. handed the file to a viewer that was open already
            click.echo(f"opened {path} in the rerun viewer")
            return
        # (rerun's viewer ends with status 0 also when it cannot reach the display)
        reason = errors[-1].rsplit(": ", 1)[-1] if errors else f"exit code {code}"
        click.echo(
            f"error: the rerun viewer ended at once ({reason}); is the display reachable? "
            "What the recording holds:",
            err=True,
        )
    size_mb = path.stat().st_size / 1e6
    click.echo(f"recording {path} ({size_mb:.1f} MB, application {summary.application_id})")
    click.echo(
        f"  {summary.frames} frames (steps {summary.first_step} to {summary.last_step}), "
        f"{summary.duration_s:.2f} s simulated"
    )
    shown = 40
    click.echo(f"  {len(summary.entity_paths)} entities:")
    for entity in summary.entity_paths[:shown]:
        click.echo(f"    {entity}")
    if len(summary.entity_paths) > shown:
        click.echo(f"    ... and {len(summary.entity_paths) - shown} more")
    click.echo(
        "no display here (DISPLAY and WAYLAND_DISPLAY are unset); to view it, either"
        if not has_display
        else "to view it, either"
    )
    click.echo(f"  run 'rerun {path}' (pip install rerun-sdk) on a machine with a display, or")
    click.echo(
        f"  run 'warpcut replay {path} --web' and open http://localhost:9090 "
        "(over ssh, forward ports 9090 and 9876: ssh -L 9090:localhost:9090 -L 9876:localhost:9876 HOST)"
    )
    if has_display:  # the viewer could not be opened
        sys.exit(1)


def _rl_results(
    contours,
    by_name,
    checkpoints,
    out,
    trials,
    sim,
    iterations,
    num_envs,
    device,
    seed,
    result_type,
    plans,
    on_step=None,
    plots=False,
):
    """Per contour, a trained run (from ``checkpoints`` or trained now, at the planned pinch and
    segments when ``plans`` are given, with its learning curve when ``plots``) rolled out for ``trials``;
    ``on_step(k)`` gives the step callback of contour ``k``'s rollout (or None)."""

    from agents.rl import RECIPE, Scenario, recipe_config, rollout_errors, train_contour

    rollouts = []
    for k, contour in enumerate(contours):
        if checkpoints is not None:
            run = checkpoints / contour.name
            if not (run / "scenario.json").is_file():
                raise click.BadParameter(
                    f"no trained run for {contour.name!r} at {run} (expected "
                    "CHECKPOINTS/NAME/scenario.json from 'warpcut train --out')",
                    param_hint="--checkpoints",
                )
        else:
            run = out / "policies" / contour.name
            click.echo(f"  training rl for {contour.name} ({iterations} iterations)", err=True)
            # The same recipe as 'warpcut train' by default (agents.rl.RECIPE).
            planned = {}
            if plans is not None:
                planned = {
                    "pinch": [float(v) for v in plans[k].chosen["pinch"]],
                    "segments": [s.tolist() for s in plans[k].ordered_segments()],
                }
            scenario = Scenario(
                contour=by_name[contour.name],
                sim=sim,
                **RECIPE,
                **planned,
            )
            cfg = recipe_config(num_envs=num_envs, iterations=iterations, seed=seed, device="cpu")
            summary = train_contour(scenario, run, cfg, eval_trials=trials, progress=False, device=device)[
                "summary"
            ]
            if plots:
                from warpcut.viz.plots import plot_learning_curve

                plot_learning_curve(summary["history"], summary["validation"], run, title=contour.name)
        hook = None if on_step is None else on_step(k)
        # Trial t sees the noise of the baselines' trial t of this contour (env k * trials + t there).
        rollouts.append(
            rollout_errors(
                run, trials, seed=seed + 1, device=device, on_step=hook, paired_noise=(seed, k * trials)
            )
        )
    return result_type.from_rollouts(rollouts)


def _markdown_table(report: dict, methods: list[str]) -> str:
    shown = [m for m in methods if m != "none"]
    head = "| contour | no tension (vertices) | " + " | ".join(f"{m} (%)" for m in shown) + " |"
    lines = [head, "|---|---|" + "---|" * len(shown)]
    for row in report["rows"]:
        cells = [f"{row[f'{m}_improvement_pct']:+.1f} ± {row[f'{m}_ci95']:.1f}" for m in shown]
        lines.append(f"| {row['contour']} | {row['none_error_vertices']:.1f} | " + " | ".join(cells) + " |")
    mean = report["mean"]
    cells = [f"{mean[f'{m}_improvement_pct']:+.1f} ± {mean[f'{m}_ci95']:.1f}" for m in shown]
    lines.append("| **mean** | | " + " | ".join(cells) + " |")
    return "\n".join(lines)


@main.command()
@click.option("--contour", "contour_name", required=True, help="Built-in name or a .json/.svg contour file.")
@click.option(
    "--candidates",
    default=30,
    show_default=True,
    type=click.IntRange(min=1),
    help="Pinch points sampled from the feasible region (paper: 30; the centroid is added if feasible).",
)
@click.option(
    "--arm-radius",
    default=ARM_RADIUS_MM,
    show_default=True,
    type=click.FloatRange(min=0.0),
    help="Radius of the cutting arm (mm) whose sweep pinch points must avoid.",
)
@_arm_length_option
@click.option(
    "--tolerance",
    default=1.0,
    show_default=True,
    type=click.FloatRange(min=0.0, min_open=True),
    help="Segmentation tolerance (mm): x reversals smaller than this are ignored.",
)
@click.option(
    "--resolution", default=25, show_default=True, type=click.IntRange(5, 100), help="Vertices per side."
)
@_device_option
@_seed_option
@click.option(
    "--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write the plan here."
)
def plan(
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
    from warpcut.planning import plan_cut
    from warpcut.sim.simulator import resolve_device

    device = resolve_device(device)
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
            arm_radius_mm=arm_radius,
            arm_length_mm=arm_length,
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
            f"  segment {k}: notch ({s['notch'][0]:.1f}, {s['notch'][1]:.1f}) -> termination "
            f"({s['termination'][0]:.1f}, {s['termination'][1]:.1f}), {len(s['points'])} points"
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
            f"  ({c['point'][0]:.1f}, {c['point'][1]:.1f}): {c['error_vertices']:.1f} vertices, "
            f"order {list(c['best_order'])}"
        )
    for r in result.rejected:
        click.echo(
            f"  centroid ({r['point'][0]:.1f}, {r['point'][1]:.1f}) infeasible: {', '.join(r['violates'])}"
        )
    chosen = data["chosen"]
    click.echo(
        f"chosen: pinch ({chosen['pinch'][0]:.1f}, {chosen['pinch'][1]:.1f}), order {chosen['order']}, "
        f"{chosen['error_vertices']:.1f} vertices"
    )
    if json_path:
        from warpcut.io import write_json

        write_json(json_path, data)
        click.echo(f"wrote {json_path}")


def _train_run_candidates(
    contour_spec: str,
    plan,
    listed: list[dict],
    settings: dict,
    num_envs: int | None,
    sim: dict,
    seed: int,
    device: str | None,
    out: Path,
    shared: bool,
    plots: bool,
) -> tuple[Path, int]:
    """``warpcut run``'s RL step: a PPO policy per candidate in ``listed`` (or one shared by all), each
    candidate cut in its best order; records each candidate's validation error in ``listed`` and returns
    the run directory of the winner and its index (the first, i.e. the better fixed rank, among ties)."""
    from agents.rl import RECIPE, Scenario, recipe_config, train_contour
    from warpcut.viz.plots import plot_learning_curve

    cuts = [[s.tolist() for s in plan.ordered_segments(c["order"])] for c in listed]
    if shared:
        envs = num_envs or max(64, 8 * len(listed))
        jobs = [
            (
                out / "rl",
                Scenario(
                    contour=contour_spec,
                    sim=sim,
                    candidates=[
                        {"pinch": c["pinch"], "segments": s} for c, s in zip(listed, cuts, strict=True)
                    ],
                    **RECIPE,
                ),
                f"one policy for {len(listed)} pinch candidates",
            )
        ]
        what = f"one RL policy shared by {len(listed)} pinch candidate(s) ({envs} envs"
    else:
        envs = num_envs or 64
        jobs = [
            (
                out / "rl" / f"candidate-{k}",
                Scenario(contour=contour_spec, pinch=c["pinch"], segments=s, sim=sim, **RECIPE),
                f"pinch ({c['pinch'][0]:.1f}, {c['pinch'][1]:.1f})",
            )
            for k, (c, s) in enumerate(zip(listed, cuts, strict=True))
        ]
        what = f"an RL policy for each of the best {len(listed)} pinch candidate(s) ({envs} envs each"
    click.echo(f"[2/3] training {what}, {settings['iterations']} PPO iterations)", err=True)
    cfg = recipe_config(num_envs=envs, iterations=settings["iterations"], seed=seed, device="cpu")
    for k, (run_dir, scenario, title) in enumerate(jobs):
        try:
            result = train_contour(
                scenario, run_dir, cfg, eval_trials=settings["trials"], progress=True, device=device
            )
        except KeyboardInterrupt:
            click.echo(f"interrupted: checkpoint saved in {run_dir}", err=True)
            sys.exit(130)
        summary = result["summary"]
        if plots:
            plot_learning_curve(
                summary["history"], summary["validation"], run_dir, title=f"{plan.contour.name}, {title}"
            )
        if shared:
            errors = summary["candidates"]["validation_error_vertices"]
            for c, e in zip(listed, errors, strict=True):
                c["rl_validation_error_vertices"], c["run"] = e, str(run_dir.relative_to(out))
            return run_dir, int(summary["candidates"]["chosen"])
        listed[k]["rl_validation_error_vertices"] = summary["best"]["validation_error"]
        listed[k]["rl_best_iteration"] = summary["best"]["iterations"]
        listed[k]["run"] = str(run_dir.relative_to(out))
        click.echo(
            f"      candidate ({listed[k]['pinch'][0]:.1f}, {listed[k]['pinch'][1]:.1f}): fixed "
            f"{listed[k]['fixed_error_vertices']:.1f}, rl {summary['best']['validation_error']:.1f} vertices "
            "(validation)",
            err=True,
        )
    chosen = min(range(len(listed)), key=lambda k: (listed[k]["rl_validation_error_vertices"], k))
    return out / listed[chosen]["run"], chosen


BUDGETS = {
    # candidates for the pinch search, of which the best rl_candidates (by fixed tension; None: all, as in
    # the paper) get a PPO policy each; PPO iterations per policy; evaluation trials
    "fast": {"candidates": 8, "rl_candidates": 2, "iterations": 60, "trials": 10},
    "paper": {"candidates": 30, "rl_candidates": None, "iterations": 200, "trials": 10},
}
RUN_POLICIES = ("rl", "fixed", "analytic")


@main.command()
@click.option(
    "--contour",
    "contour_name",
    default="fls-circle",
    show_default=True,
    help="Built-in name or a .json/.svg contour file.",
)
@click.option(
    "--budget",
    default="fast",
    show_default=True,
    type=click.Choice(list(BUDGETS)),
    help="fast: 8 pinch candidates (plus the centroid when feasible), a PPO policy for each of the best 2, "
    "60 PPO iterations each (a few minutes on 2 CPU cores); paper: 30 candidates, a policy for every one, "
    "200 iterations each (hours).",
)
@click.option(
    "--policy",
    "run_policy",
    default="rl",
    show_default=True,
    type=click.Choice(RUN_POLICIES),
    help="The tensioner that picks the pinch candidate (each candidate with its best order): rl (a PPO "
    "policy per candidate, the one that validates best wins); fixed or analytic for quick plans without "
    "training.",
)
@click.option(
    "--shared-policy",
    is_flag=True,
    help="Train one PPO policy for all the RL candidates (it observes its pinch point) instead of one each: "
    "about K times faster, but it lost to separate policies where they learn (docs/learning.md).",
)
@click.option(
    "--candidates", type=click.IntRange(min=1), default=None, help="Override the budget's pinch candidates."
)
@click.option(
    "--rl-candidates",
    type=click.IntRange(min=1),
    default=None,
    help="Override how many of the best candidates (ranked by fixed tension) get a PPO policy.",
)
@click.option(
    "--iterations", type=click.IntRange(min=1), default=None, help="Override the budget's PPO iterations."
)
@click.option(
    "--trials", type=click.IntRange(min=1), default=None, help="Override the budget's evaluation trials."
)
@click.option(
    "--num-envs",
    default=None,
    type=click.IntRange(min=1),
    help="PPO envs per policy (default: 64; with --shared-policy 64, or 8 per candidate when more).",
)
@click.option(
    "--resolution", default=25, show_default=True, type=click.IntRange(5, 100), help="Vertices per side."
)
@_noise_option
@_score_option
@_arm_length_option
@_analytic_pinch_option
@_device_option
@_seed_option
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Run directory (default: logs/run-CONTOUR-TIMESTAMP).",
)
@click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write the results here.",
)
@_record_option("in the run directory")
@_plots_option("in the run directory")
def run(
    contour_name: str,
    budget: str,
    run_policy: str,
    shared_policy: bool,
    candidates: int | None,
    rl_candidates: int | None,
    iterations: int | None,
    trials: int | None,
    num_envs: int | None,
    resolution: int,
    noise: float,
    score: str,
    arm_length: float,
    analytic_pinch: str,
    device: str | None,
    seed: int,
    out: Path | None,
    json_path: Path | None,
    record_envs: int | None,
    colour_by: str,
    no_plots: bool,
) -> None:
    """The whole pipeline: plan the cut, pick the pinch candidate with a tensioner (RL: a policy per
    candidate), compare none/fixed/analytic/RL."""
    import numpy as np

    from agents.baselines import AnalyticTension
    from agents.evaluation import MethodResult, MethodSpec, evaluate_suite, run_method
    from agents.rl import rollout_errors
    from warpcut.contours import load_contour
    from warpcut.io import write_json
    from warpcut.planning import plan_cut
    from warpcut.sim.simulator import resolve_device

    settings = dict(BUDGETS[budget])
    overrides = dict(candidates=candidates, rl_candidates=rl_candidates, iterations=iterations, trials=trials)
    settings.update({k: v for k, v in overrides.items() if v is not None})
    device = resolve_device(device)
    contour = load_contour(contour_name)
    config = SimConfig(resolution=resolution, noise_std=noise, score=score).validated()
    out = _run_dir(out, f"run-{contour.name}")
    start = time.perf_counter()

    click.echo(f"[1/3] planning {contour.name}: {settings['candidates']} pinch candidates", err=True)
    plan = plan_cut(
        contour,
        config,
        num_candidates=settings["candidates"],
        seed=seed,
        device=device,
        arm_length_mm=arm_length,
    )
    write_json(out / "plan.json", plan.to_json())
    pinch, segments = plan.chosen["pinch"], plan.ordered_segments()
    click.echo(
        f"      {len(plan.segments)} segment(s), order {list(plan.order)}, pinch "
        f"({pinch[0]:.1f}, {pinch[1]:.1f}) with fixed tension: {plan.chosen['error_vertices']:.1f} vertices",
        err=True,
    )

    ranked = sorted(range(len(plan.candidates)), key=lambda c: plan.candidates[c]["error_vertices"])
    if run_policy == "rl" and settings["rl_candidates"] is not None:
        ranked = ranked[: settings["rl_candidates"]]
    listed = [
        {
            "pinch": [float(v) for v in c["point"]],
            "order": [int(k) for k in c["best_order"]],
            "fixed_error_vertices": float(c["error_vertices"]),
        }
        for c in (plan.candidates[k] for k in ranked)
    ]
    methods = ["none", "fixed", "analytic"] + (["rl"] if run_policy == "rl" else [])
    pinches = {"fixed": [pinch], "analytic": _analytic_pinches(analytic_pinch, [contour], [plan])}
    method_segments = {}
    extra = {}
    if run_policy == "fixed":
        chosen = 0  # the plan's choice: the best candidate by fixed tension
        click.echo("[2/3] --policy fixed: the plan's pinch and order", err=True)
    elif run_policy == "analytic":
        click.echo(f"[2/3] scoring the analytic policy at {len(listed)} pinch candidate(s)", err=True)
        scores = run_method(
            [contour] * len(listed),
            MethodSpec([np.asarray(c["pinch"]) for c in listed], AnalyticTension()),
            1,
            config.replace(noise_std=0.0),
            device,
            seed,
            segments=[plan.ordered_segments(c["order"]) for c in listed],
        ).errors[:, 0]
        for c, e in zip(listed, scores, strict=True):
            c["analytic_error_vertices"] = float(e)
        chosen = int(np.argmin(scores))
        pinches["analytic"] = [np.asarray(listed[chosen]["pinch"])]
        method_segments["analytic"] = plan.ordered_segments(listed[chosen]["order"])
    else:
        sim = _protocol_sim(config)
        rl_dir, chosen = _train_run_candidates(
            contour_name, plan, listed, settings, num_envs, sim, seed, device, out, shared_policy,
            plots=not no_plots,
        )  # fmt: skip
    best = listed[chosen]
    click.echo(
        f"      chosen by {run_policy}: pinch ({best['pinch'][0]:.1f}, {best['pinch'][1]:.1f}), order "
        f"{best['order']}"
        + "".join(
            f", {k.split('_')[0]} {best[k]:.1f}"
            for k in ("fixed_error_vertices", "analytic_error_vertices", "rl_validation_error_vertices")
            if k in best
        )
        + " vertices",
        err=True,
    )

    click.echo(f"[3/3] evaluating {', '.join(methods)}: {settings['trials']} trials each", err=True)
    cuts = None
    if not no_plots:
        from warpcut.viz.plots import FinalCuts

        cuts = FinalCuts()
    with _recorder(out, record_envs, colour_by) as recorder:
        hooks = _step_hooks(recorder, cuts)
        if run_policy == "rl":
            rl = rollout_errors(
                rl_dir,
                settings["trials"],
                seed=seed + 1,
                device=device,
                on_step=None if hooks is None else hooks("rl"),
                paired_noise=(seed, 0),  # the baselines' trials' noise (evaluate_suite below, same seed)
            )
            extra["rl"] = MethodResult.from_rollouts([rl])
        report = evaluate_suite(
            [contour],
            methods,
            trials=settings["trials"],
            config=config,
            device=device,
            seed=seed,
            segments=[segments],
            pinches=pinches,
            extra=extra,
            on_step=hooks,
            method_segments={m: [p] for m, p in method_segments.items()},
        )
    report["plan"] = plan.to_json()["chosen"]
    report["policy"] = run_policy
    report["candidates"] = listed
    report["chosen_candidate"] = chosen
    report["budget"] = budget
    report["analytic_pinch"] = analytic_pinch
    report["seconds"] = time.perf_counter() - start
    row = report["rows"][0]
    click.echo(
        f"{contour.name}: planned order {list(plan.order)}, pinch ({pinch[0]:.1f}, {pinch[1]:.1f}); "
        f"{settings['trials']} trials, {report['seconds']:.0f} s"
    )
    click.echo(f"{'method':<10} {'error (vertices)':>16} {'improvement':>14} {'pinch (mm)':>16}")
    for m in methods:
        p = row[f"{m}_pinch"]
        p_txt = "-" if p is None else f"({p[0]:.1f}, {p[1]:.1f})"
        imp = row[f"{m}_improvement_pct"]
        imp_txt = f"{imp:+.1f}% ±{row[f'{m}_ci95']:.1f}" if np.isfinite(imp) else "n/a"
        click.echo(f"{m:<10} {row[f'{m}_error_vertices']:>16.1f} {imp_txt:>14} {p_txt:>16}")
    write_json(out / "results.json", report)
    if json_path:
        write_json(json_path, report)
    if cuts is not None:
        from warpcut.viz.plots import plot_improvements, plot_pinch_candidates, plot_regions

        _echo_written(plot_regions(cuts.of(contour.name, methods), out))
        _echo_written(plot_improvements(report, methods[1:], out))
        _echo_written(plot_pinch_candidates(plan, config, out))
    _echo_recording(recorder)
    click.echo(f"wrote {out}")
