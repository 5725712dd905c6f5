"""The options several commands share (the device, the seed, the run directory, ``--config``/``--set``,
``--record``, ...) and :class:`Setting`, an option that sets one key of its command's job."""

from __future__ import annotations

import math
from pathlib import Path

import click

from agents.config import SEED_RANGE
from warpcut.sim.config import ARM_LENGTH_MM, RESOLUTION_RANGE, SimConfig


class Setting(click.Option):
    """An option that sets one key of its command's job: ``key``, dotted as ``--set`` takes it (``--algo``:
    ``train.algo``). A command's flags are its :class:`Setting` options: the key a flag sets is said where
    the flag is declared, and :func:`agents.cli.settings.resolve` reads it from there."""

    def __init__(self, *args, key: str, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.key = key


def setting_keys(command: click.Command) -> dict[str, str]:
    """``{parameter name: key}`` of ``command``'s flags (its :class:`Setting` options)."""
    return {param.name: param.key for param in command.params if isinstance(param, Setting)}


def _resolve_device(ctx: click.Context, param: click.Parameter, value: str | None) -> str:
    from warpcut.sim.devices import resolve_device

    return resolve_device(value)


class FloatRange(click.FloatRange):
    """click's ``FloatRange`` that also refuses NaN, which its bounds let through (NaN compares false with
    every bound), and the infinities unless ``allow_inf`` (e.g. ``--arm-length inf``)."""

    def __init__(self, *args, allow_inf: bool = False, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.allow_inf = allow_inf

    def convert(self, value, param, ctx):
        number = super().convert(value, param, ctx)
        if math.isnan(number) or (math.isinf(number) and not self.allow_inf):
            self.fail(f"{number} is not a finite number.", param, ctx)
        return number


device_option = click.option(
    "--device",
    default=None,
    callback=_resolve_device,
    help="Warp device: cpu or cuda (default: cuda if available, else cpu).",
)


seed_option = click.option(
    "--seed",
    cls=Setting,
    key="seed",
    default=0,
    show_default=True,
    type=click.IntRange(*SEED_RANGE),
    help=f"Seed of everything random (noise, sampling, training); an integer in [0, {SEED_RANGE[1]}].",
)


DEFAULTS = SimConfig()
"""The library's defaults, which the options below show and pass on (one set for library and CLI)."""


arm_length_option = click.option(
    "--arm-length",
    cls=Setting,
    key="arm.length_mm",
    default=ARM_LENGTH_MM,
    show_default=True,
    type=FloatRange(min=0.0, allow_inf=True),
    help="Reach of the cutting arm's footprint from the scissor tip toward +x (mm), for pinch feasibility; "
    "inf (the paper's cylinder): the whole way, so the grasp never holds the piece being cut; a short "
    "footprint (e.g. 15) lets it hold the piece (docs/results.md).",
)


generalist_option = click.option(
    "--generalist",
    "generalist_source",
    cls=Setting,
    key="generalist",
    default=None,
    metavar="DIR",
    help="The generalist to play (a run directory of 'warpcut generalist'); default: the one warpcut ships.",
)


def _check_ray(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    from agents.cluster import parse_address

    try:
        parse_address(value)
    except ValueError as exc:
        raise click.BadParameter(str(exc).removeprefix("--ray: "), ctx, param) from None
    return value


def ray_option(units: str):
    """``--ray ADDRESS``: run the command's independent ``units`` on a Ray cluster (:mod:`agents.cluster`)."""
    return click.option(
        "--ray",
        default=None,
        metavar="ADDRESS",
        callback=_check_ray,
        help=f"Run {units} as tasks on a Ray cluster: local (a cluster of this machine's cores for the "
        "command; local:N, N CPUs), auto or HOST:PORT (one 'ray start' runs); the same results as "
        "without it (docs/cluster.md).",
    )


json_option = click.option(
    "--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write results here."
)


def out_option(default: str):
    """``--out DIR``, the run directory (``default`` says where it goes without it)."""
    return click.option(
        "--out",
        type=click.Path(file_okay=False, path_type=Path),
        default=None,
        help=f"Run directory (default: {default}).",
    )


overwrite_option = click.option(
    "--overwrite",
    is_flag=True,
    help="Delete what an earlier warpcut run wrote in --out (nothing else) and start again.",
)


def run_dir_options(command):
    """``--resume`` and ``--overwrite`` for a command that writes a run directory (``--out``)."""
    command = overwrite_option(command)
    return click.option(
        "--resume",
        is_flag=True,
        help="Continue the run in --out (interrupted, or to finish it): policies trained to the end are "
        "kept, interrupted ones continue from their checkpoints; the settings must be the run's.",
    )(command)


def count_option(name: str, default: int | None, help: str, key: str | None = None):
    """A positive integer option ``--NAME`` (shows its default when it has one); with ``key``, the flag of
    that setting (:class:`Setting`)."""
    setting = {} if key is None else {"cls": Setting, "key": key}
    return click.option(
        f"--{name}",
        default=default,
        show_default=default is not None,
        type=click.IntRange(min=1),
        help=help,
        **setting,
    )


CONTOUR_HELP = "Built-in name or a .json/.svg contour file."

contour_option = click.option("--contour", "contour_name", required=True, help=CONTOUR_HELP)


def contour_setting(default: str | None = None, note: str = ""):
    """``--contour``, the job's ``contour`` key (``default`` shown where there is one; ``note`` added to the
    help)."""
    return click.option(
        "--contour", cls=Setting, key="contour", default=default, show_default=default is not None,
        help=CONTOUR_HELP[:-1] + (f" ({note})." if note else "."),
    )  # fmt: skip


resolution_option = click.option(
    "--resolution",
    cls=Setting,
    key="sim.resolution",
    default=DEFAULTS.resolution,
    show_default=True,
    type=click.IntRange(*RESOLUTION_RANGE),
    help="Vertices per side.",
)


def parse_point(value: str | None, name: str) -> tuple[float, float] | None:
    """``X,Y`` (mm) as a point; None stays None."""
    if value is None:
        return None
    try:
        x, y = (float(v) for v in value.split(","))
    except ValueError:
        raise click.BadParameter(f"expected X,Y in mm, e.g. 60,40 (got {value!r})", param_hint=name) from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise click.BadParameter(f"X and Y must be finite numbers in mm (got {value!r})", param_hint=name)
    return x, y


def config_options(command):
    """``--config FILE|PRESET``, ``--set KEY=VALUE`` (repeatable) and ``--print-config``: the settings a
    command's flags do not reach (:func:`resolve`)."""
    from agents.config_io import presets

    command = click.option(
        "--print-config", is_flag=True, help="Print the full resolved config (YAML) and exit."
    )(command)
    command = click.option(
        "--set",
        "overrides",
        multiple=True,
        metavar="KEY=VALUE",
        help="Set one setting by its dotted key (repeatable), e.g. --set sim.noise_std=0 --set "
        "train.es.sigma=0.01; --print-config shows every key.",
    )(command)
    return click.option(
        "--config",
        "config_file",
        metavar="FILE|PRESET",
        help="Settings from a TOML, YAML or JSON file (a run directory's config.json runs it again), or a "
        f"preset: {', '.join(presets())}. Flags and --set override it.",
    )(command)


def point_callback(ctx: click.Context, param: click.Parameter, value: str | None) -> list[float] | None:
    """A ``X,Y`` option (mm) as ``[x, y]``."""
    point = parse_point(value, param.opts[0])
    return None if point is None else [float(v) for v in point]


def record_flag(what: str):
    """``--record [N]``: a rerun recording (``what``) of the first N envs (default 1) of each method."""
    return click.option(
        "--record",
        "record_envs",
        cls=Setting,
        key="record",
        type=click.IntRange(min=1),
        is_flag=False,
        flag_value=1,
        default=None,
        metavar="[N]",
        help=f"Write recording.rrd ({what}) of the first N envs (default 1) of each method; view it with "
        "'warpcut replay' (colours: --set colour_by=strain|height).",
    )
