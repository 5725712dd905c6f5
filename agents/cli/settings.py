"""A command's settings: its job resolved from the defaults, a ``--config`` file, ``--set`` and its flags
(:func:`resolve`), resumed from a run directory (:func:`resumed_job`), printed (:func:`print_config`) and
checked before any work (a setting the invocation would ignore, a learner that cannot train in its env);
:class:`Command`, the click command that refuses an option given twice and names the setting an unknown
option stands for."""

from __future__ import annotations

from pathlib import Path

import click

from agents.cli.options import setting_keys


class Command(click.Command):
    """click's command that refuses an option given twice: click would keep the last value without a word."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        try:
            return self._parse_args(ctx, args)
        except click.NoSuchOption as error:
            key = setting_of(self.name, error.option_name)
            if key is None:
                raise
            raise click.UsageError(
                f"{error.option_name}: '{self.name}' has no such option; it is a setting: --set {key}=VALUE",
                ctx=ctx,
            ) from None

    def invoke(self, ctx: click.Context):
        """Run the command, after refusing a run directory another process holds (``--out``,
        ``--resume``), with the library's advice in errors naming settings as the command gives them
        (:func:`setting_form`)."""
        from agents.cli.checks import setting_form
        from warpcut.io import check_not_busy
        from warpcut.planning.feasibility import setting_forms

        for name in ("out", "resume"):  # a run another process holds: said at once, not after the checks
            if isinstance(ctx.params.get(name), Path):
                check_not_busy(ctx.params[name], f"--{name}")
        with setting_forms(lambda key, value: setting_form(self, COMMAND_JOBS.get(self.name), key, value)):
            return super().invoke(ctx)

    def _parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        if args:
            _, _, order = self.make_parser(ctx).parse_args(args=list(args))
            seen: set[str] = set()
            for param in order:
                if not isinstance(param, click.Option) or param.multiple or param.count:
                    continue
                if param.name in seen:
                    raise click.UsageError(f"{param.opts[0]}: given twice; give it once", ctx=ctx)
                seen.add(param.name)
        return super().parse_args(ctx, args)


COMMAND_JOBS = {
    "run": "RunJob",
    "evaluate": "EvaluateJob",
    "train": "TrainJob",
    "optimize": "OptimizeJob",
    "robustness": "RobustnessJob",
    "simulate": "SimulateJob",
    "generalist": "GeneralistJob",
    "teachers": "TeachersJob",
}
"""Each command's job (:mod:`agents.jobs`): the settings ``--set`` reaches."""


def setting_of(command: str | None, option: str) -> str | None:
    """The ``--set`` key of ``command``'s job that an option it lacks (``--trials``, ``--num-envs``) names:
    the key itself, or the one key ending in it (``iterations``: ``train.iterations``); None if none."""
    if command not in COMMAND_JOBS:
        return None
    import agents.jobs
    from agents.config_io import flatten, to_plain

    name = option.lstrip("-").replace("-", "_")
    keys = flatten(to_plain(getattr(agents.jobs, COMMAND_JOBS[command])()))
    found = [key for key in keys if key == name or key.endswith(f".{name}")]
    return found[0] if len(found) == 1 or name in found else None


def resolve(job_class, config_file: str | None, overrides: tuple[str, ...], base=None):
    """The job a command runs: the defaults (or ``base``), then the ``--config`` file, then ``--set``, then
    the flags given on the command line (the command's :class:`~agents.cli.options.Setting` options, each
    naming its key), each checked by its key.

    Defaults that follow from other settings follow them unless given (:func:`agents.jobs.
    with_dependent_defaults`): ``--algo ppo`` trains PPO's discrete moves.

    Raises:
        click.UsageError: A key given twice (``--set`` twice, or a flag and ``--set``).
        ValueError: An unknown key or a value of the wrong type (naming it and where it came from).
    """
    from agents.config_io import apply, flatten, parse_override, read_file, to_plain
    from agents.jobs import with_dependent_defaults

    ctx = click.get_current_context()
    job = base if base is not None else job_class()
    explicit: set[str] = set()
    if config_file:
        data = read_file(config_file)
        job = apply(job, data, str(config_file))
        explicit |= set(flatten(data))
    sets: dict = {}
    for text in overrides:
        key, value = parse_override(text)
        if key in sets:
            raise click.UsageError(f"--set {key}: given twice; give it once")
        sets[key] = value
    given = {}
    for name, key in setting_keys(ctx.command).items():
        if ctx.get_parameter_source(name) != click.core.ParameterSource.COMMANDLINE:
            continue
        flag = next(p.opts[0] for p in ctx.command.params if p.name == name)
        if key in sets:
            raise click.UsageError(f"{flag} and --set {key}: both set {key}; give one")
        given[key] = (flag, ctx.params[name])
    job = apply(job, sets, "--set")
    for key, (flag, value) in given.items():
        job = apply(job, {key: value}, flag)
    explicit |= set(sets) | set(given)
    if base is not None:  # a resumed run's own settings count as given
        explicit |= set(flatten(to_plain(base)))
    return with_dependent_defaults(job, explicit)  # a job checks its seed's range itself (SEED_RANGE)


NOT_SETTINGS = ("out", "json_path", "overwrite", "no_progress", "device")
"""The options that say where and how a command runs, not what: ``--print-config`` would ignore them."""


def print_config(job) -> None:
    """``--print-config``: the resolved job as YAML on stdout; an option that only says where or how the
    command would run (:data:`NOT_SETTINGS`) is refused with it, as a setting the invocation ignores."""
    from agents.config_io import to_yaml

    ctx = click.get_current_context()
    ignored = [
        p.opts[0]
        for p in ctx.command.params
        if p.name in NOT_SETTINGS
        and ctx.get_parameter_source(p.name) == click.core.ParameterSource.COMMANDLINE
    ]
    if ignored:
        raise click.UsageError(
            f"{', '.join(ignored)}: --print-config prints the settings and exits, running and writing "
            f"nothing; drop {'them' if len(ignored) > 1 else 'it'}"
        )
    click.echo(to_yaml(job), nl=False)


def resumed_job(job_class, out: Path | None, resume: bool, command: str):
    """With ``--resume``, the job the run in ``out`` was started with (its ``config.json``): the base of the
    settings, so that a resumed run keeps its own and only what is given again changes (and is then
    checked against the run's); None when not resuming, or when the run saved no settings yet."""
    from agents.jobs import CONFIG_FILE
    from warpcut.io import check_run_dir

    if not resume or out is None or not out.is_dir():
        return None
    check_run_dir(out, command=command, resume=True)  # a run of this command, before its settings are read
    return saved_job(job_class, out / CONFIG_FILE) if (out / CONFIG_FILE).is_file() else None


def saved_job(job_class, path: Path):
    """The job a run directory's ``config.json`` (``path``) holds, to resume it."""
    from agents.config_io import apply
    from warpcut.io import read_json

    if not path.is_file():
        from warpcut.io import read_run_marker

        marker = read_run_marker(path.parent)
        if marker is not None:  # killed before it saved its settings: nothing to continue
            line = " ".join(marker.get("argv") or []) or "its command"
            raise click.BadParameter(
                f"{path.parent}: the run stopped before it saved its settings ({path.name}); start it "
                f"again, without --resume: {line}",
                param_hint="--resume",
            )
        raise click.BadParameter(
            f"{path.parent}: no {path.name}: not a run this command wrote; give its run directory",
            param_hint="--resume",
        )
    data = read_json(path)
    if not isinstance(data, dict):
        raise click.BadParameter(
            f"{path}: not a run's settings; restore it, or start a new run", param_hint="--resume"
        )
    return apply(job_class(), data, str(path))


def refuse_unused_keys(job, keys: list[str], overrides: tuple[str, ...], why: str) -> None:
    """A UsageError naming the settings under ``keys`` (dotted keys or sections, e.g. ``grad``) that this
    invocation gives but would ignore (``why``: when they apply), instead of ignoring them without a word:
    those that ``--set`` or a flag (a :class:`~agents.cli.options.Setting` option) gives, and those away from
    the job's defaults (a ``--config`` file's; a run directory's ``config.json`` holds each unused setting at
    its default, so it runs again as it is)."""
    from agents.config_io import flatten, parse_override, to_plain

    def under(key: str) -> bool:
        return any(key == k or key.startswith(f"{k}.") for k in keys)

    ctx = click.get_current_context()
    now, default = flatten(to_plain(job)), flatten(to_plain(type(job)()))
    given = [key for key, _ in map(parse_override, overrides)]
    given += [
        key
        for name, key in setting_keys(ctx.command).items()
        if ctx.get_parameter_source(name) == click.core.ParameterSource.COMMANDLINE
    ]
    given += [key for key, value in now.items() if value != default.get(key)]
    unused = [key for key in dict.fromkeys(given) if under(key)]
    if unused:
        raise click.UsageError(f"{', '.join(unused)}: {why}; drop {'them' if len(unused) > 1 else 'it'}")


def refuse_unused_settings(job, overrides: tuple[str, ...]) -> None:
    """The general rule that a setting the job would not use is refused, not ignored: each key that
    ``job.unused_keys()`` names (``{key: when it applies}``, from the job's own settings, e.g. simulate's
    ``pinch`` where ``policy`` has neither fixed nor analytic) is checked against the keys given (a flag,
    ``--set``, or a value away from the default: :func:`refuse_unused_keys`)."""
    for key, why in job.unused_keys().items():
        refuse_unused_keys(job, [key], overrides, why)


def check_learner(job) -> None:
    """``ValueError`` naming the setting, before any work, where ``job``'s learner (``job.train``) cannot
    train in its env (``job.env``): an action type it does not play, a population that does not fit the
    batch, an actor's feedback path on a tracking error the policy does not observe, or domain
    randomisation (or a relative reward) for APG, which differentiates one fixed sheet."""
    import dataclasses

    from agents.algorithms import algorithm

    job.train.check(job.env.action_type == "discrete")
    device = job.train.torch_device
    if device.startswith(("cuda", "mps")):
        import torch

        backend = torch.cuda if device.startswith("cuda") else torch.backends.mps
        index = int(device.partition(":")[2] or 0)
        if not backend.is_available() or (backend is torch.cuda and index >= torch.cuda.device_count()):
            raise ValueError(f"train.torch_device: {device} is not available here; use cpu (the default)")
    if job.train.feedback and not job.env.contour_features:
        own = {f.name for f in dataclasses.fields(job.train.learner)}
        drop = f"train.{job.train.algo}.feedback=false" if "feedback" in own else "--algo ppo"
        raise ValueError(
            "feedback: the policy observes no tracking error (env.contour_features=false); observe the "
            f"contour, or train without the feedback path ({drop})"
        )
    fixed_sheet = algorithm(job.train.algo).fixed_sheet
    if fixed_sheet is not None and (job.env.randomize or job.env.relative_reward):
        raise ValueError(fixed_sheet)
    from agents.cli.checks import check_network_memory

    check_network_memory(job.train)
