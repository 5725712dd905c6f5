"""The ``warpcut`` command line.

Every command has ``--help``; bad input exits with status 2 and a one-line ``error: ...`` naming what
to fix, never a traceback.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import click

from warpcut.config import FIXTURES, SimConfig

POLICY_NAMES = ("none", "fixed", "analytic")


class CleanErrors(click.Group):
    """Turn usage errors and the library's ValueErrors into one line on stderr and exit status 2."""

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
            click.echo(f"error: {exc.format_message()}{hint}", err=True)
            sys.exit(2)
        except (ValueError, FileNotFoundError) as exc:
            click.echo(f"error: {exc}", err=True)
            sys.exit(2)
        sys.exit(result if isinstance(result, int) else 0)


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
@click.option(
    "--noise",
    default=0.0,
    show_default=True,
    type=click.FloatRange(min=0.0),
    help="Process noise sigma (mm per update).",
)
@click.option(
    "--resolution", default=25, show_default=True, type=click.IntRange(5, 100), help="Vertices per side."
)
@click.option("--fixture", default="corners", show_default=True, type=click.Choice(FIXTURES))
@click.option("--device", default=None, help="Warp device: cpu or cuda (default: cuda if available).")
@click.option("--seed", default=0, show_default=True, type=int)
@click.option(
    "--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write results here."
)
def simulate(
    contour_name: str,
    policies: str,
    pinch: str | None,
    trials: int,
    noise: float,
    resolution: int,
    fixture: str,
    device: str | None,
    seed: int,
    json_path: Path | None,
) -> None:
    """Cut a contour with each baseline tensioner and compare their errors."""
    from agents.evaluation import compare_policies
    from warpcut.contours import load_contour
    from warpcut.simulator import resolve_device

    names = _parse_policies(policies)
    point = _parse_point(pinch, "--pinch")
    device = resolve_device(device)
    contour = load_contour(contour_name)
    config = SimConfig(resolution=resolution, fixture=fixture, noise_std=noise).validated()
    start = time.perf_counter()
    report = compare_policies(
        contour, names, trials=trials, config=config, pinch=point, device=device, seed=seed
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


@main.command()
@click.option("--device", default=None, help="Warp device: cpu or cuda (default: cuda if available).")
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
    from warpcut.simulator import resolve_device

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
    click.echo(
        f"fls-circle no-tension rollouts/s (B={result['rollout_envs']}): {result['rollouts_per_s']:,.1f}"
    )
    click.echo(
        f"NumPy reference updates/s: {result['numpy_updates_per_s']:,.1f}  "
        f"(Warp best / NumPy = {result['speedup_vs_numpy']:,.0f}x)"
    )
    if result["train_steps_per_s"] is not None:
        click.echo(f"PPO training env steps/s: {result['train_steps_per_s']:,.0f}")
    if json_path:
        from warpcut.io import write_json

        write_json(json_path, result)
        click.echo(f"wrote {json_path}")
