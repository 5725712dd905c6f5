"""``warpcut contours``: list the built-in contours."""

from __future__ import annotations

from pathlib import Path

import click

from agents.cli import outputs, settings


@click.command("contours", cls=settings.Command)
@click.option(
    "--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write the list here."
)
def command(json_path: Path | None) -> None:
    """List the built-in contours (name, closed/open, length, area)."""
    from warpcut.contours import builtin_contours

    outputs.check_outputs({"--json": json_path})
    rows = [
        {
            "name": c.name,
            "closed": c.closed,
            "length_mm": round(c.length, 2),
            "area_mm2": round(c.area_mm2, 1),
        }
        for c in builtin_contours().values()
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
