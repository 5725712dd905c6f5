"""Checks a command makes before any work that the shared options module does not hold: a file the user
names for output (``--json``), the memory an actor's layers need, and how the command gives a setting for
advice in errors."""

from __future__ import annotations

from pathlib import Path

import click


def check_named_file(path: Path, own: tuple[Path, str] | None, option: str) -> None:
    """Refuse the file ``path`` a user named for ``option`` where writing it would replace a file warpcut
    did not write (one in no run directory: warpcut cannot tell it wrote it), or land in a run directory
    other than ``own`` (another run's ``config.json``: that run could no longer be resumed)."""
    from warpcut.io import enclosing_run, read_run_marker, written_by_warpcut

    run = enclosing_run(path)
    if run is not None:
        marker = read_run_marker(run) or {}
        mine = own is not None and run.resolve() == own[0].resolve()
        if not mine or marker.get("command") not in (own[1], None):
            command = marker.get("command") or "COMMAND"
            raise click.BadParameter(
                f"{path} lies in the run of 'warpcut {command}' in {run}, which this command does not own, "
                "so it never writes there; choose a file outside it",
                param_hint=option,
            )
        if path.exists() and not written_by_warpcut(path):
            raise click.BadParameter(
                f"{path} exists, and warpcut did not write it, so it never replaces it; move it, or choose "
                "another file",
                param_hint=option,
            )
    elif path.exists() or path.is_symlink():
        raise click.BadParameter(
            f"{path} exists, and lies in no run directory of warpcut's, so warpcut never replaces it; move "
            "it, or choose another file",
            param_hint=option,
        )


def check_network_memory(train) -> None:
    """``ValueError`` naming ``train.actor_hidden_dims`` where the actor's weights alone, with the copies
    training keeps of them (gradients, Adam's moments, an es population's perturbations, as float64), would
    not fit in the memory a batch may take (:func:`warpcut.sim.memory.memory_limit`): torch's allocator would
    fail mid-run, or the kernel kill the process."""
    from warpcut.sim.memory import memory_limit

    dims = [1, *train.actor_hidden_dims, 1]  # the narrowest input and output: a lower bound
    weights = sum(a * b + b for a, b in zip(dims, dims[1:], strict=False))
    copies = 4 + getattr(train.learner, "population", 0)
    needed, (limit, source) = 8 * weights * copies, memory_limit()
    if needed > limit:
        raise ValueError(
            f"train.actor_hidden_dims: {list(train.actor_hidden_dims)} make an actor of at least {weights:,} "
            f"weights, which training would need about {needed / 1e9:.3g} GB for, more than the "
            f"{limit / 1e9:.3g} GB allowed ({source}); use narrower layers"
        )


def setting_form(command: click.Command, job: str | None, key: str, value: str) -> str | None:
    """How ``command`` gives the setting ``key`` the value ``value``: its own flag (``--resolution 12``,
    a :class:`~agents.cli.options.Setting` option), else ``--set KEY=VALUE`` where its ``job`` (a class of
    :mod:`agents.jobs`, by name; None: it has none) has the setting, else None (advice leaves it out)."""
    from agents.cli.options import Setting

    for param in command.params:
        if isinstance(param, Setting) and param.key == key:
            return f"{param.opts[0]} {value}"
    if job is None:
        return None
    import agents.jobs
    from agents.config_io import flatten, to_plain

    keys = flatten(to_plain(getattr(agents.jobs, job)()))
    return f"--set {key}={value}" if key in keys else None


def check_planner_memory(candidates: int, sim, key: str = "candidates") -> None:
    """``ValueError`` naming ``key`` where the planner's batch for ``candidates`` pinch points (and the
    centroid; one segment order at least) on ``sim``'s sheet would not fit in memory: said before the command
    claims its run directory, not once it has planned its way there."""
    from warpcut.sim.memory import check_batch_memory

    config = sim.validated()
    check_batch_memory(
        candidates + 1, config.nx * config.ny, name=key,
        fix=f"plan fewer pinch candidates (the {key} setting) or lower the resolution",
    )  # fmt: skip
