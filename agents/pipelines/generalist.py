"""Train a generalist, one tensioning policy for every contour, over many contours at once
(:func:`train_generalist`, ``warpcut generalist``; :mod:`agents.generalist` plays it).

Training: every env of one batch cuts its own contour at its own planned pinch point, in its planned
segments and order (the paper's planning, :func:`warpcut.planning.plan_cut`, as ``warpcut evaluate`` plans).
The contours are the generated ``train`` split (:func:`warpcut.planning.generate_contours`) and, where asked,
built-in ones; es's ``population`` perturbed policies each cut every one of them, so each perturbation is
ranked on the same contours (paired), by its mean cost. The policy observes what lies ahead of the scissors
(``env.lookahead``), and each env's reward is relative to its own no-tension error
(``env.reward_reference = "no_tension"``): the cost es ranks is the mean of ``1 - improvement`` over the
contours, Table I's measure. Model selection validates on the generated ``validation`` split, held out from
training; the ``test`` split is the evaluation's.

A generalist's run directory holds ``config.json`` (the job), ``plans.json`` (the plans of the training
and validation contours), ``generalist.json`` (what the policy observes and acts in: the env settings, the
physics and the training contours' names), the checkpoints (``best.pt``) and ``summary.json``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from agents.cluster import Executor
from agents.config_io import to_plain
from agents.generalist import ES_FIELDS, FORMAT, GENERALIST_FILE, POLICY_FIELDS, generalist_dir
from agents.jobs import CONFIG_FILE
from agents.teachers import load_teachers
from envs.options import ENV_FIELDS, PatternCutOptions
from warpcut.contours import Contour
from warpcut.io import claim_run_dir, read_json, write_json

if TYPE_CHECKING:
    from agents.jobs import GeneralistJob


def training_contours(job: GeneralistJob) -> tuple[list[Contour], list[Contour]]:
    """The generalist's training contours (the built-in ones asked for, then the generated ``train``
    split) and its validation contours (the generated ``validation`` split)."""
    from warpcut.planning.generate import generate_contours, resolve_specs

    config = job.sim.validated()
    builtin = [c for _, c in resolve_specs(job.contours, config)] if job.contours else []
    generated = generate_contours(job.generated, "train", job.seed, config)
    validation = generate_contours(job.validation_contours, "validation", job.seed, config)
    return builtin + generated, validation


def train_generalist(
    job: GeneralistJob,
    out: str | Path,
    *,
    resume: bool = False,
    device: str | None = None,
    progress: bool = True,
    log: Callable[[str], None] = lambda _: None,
    cluster: Executor | None = None,
) -> dict:
    """Train ``job``'s generalist into ``out`` (module docstring); Ctrl-C saves a checkpoint and re-raises.

    Args:
        job: The contours, the env (look-ahead, reward), the learner (:class:`agents.jobs.GeneralistJob`).
        out: Run directory (claimed: :func:`warpcut.io.claim_run_dir`).
        resume: Continue the run in ``out``, started with the same job (but ``train.iterations``).
        device: The simulator's Warp device.
        progress: Show the progress bar.
        log: Called with each progress line.
        cluster: Where the contours are planned and the envs step (:mod:`agents.cluster`; on a Ray cluster
            each worker steps the envs of whole perturbed policies, :class:`agents.shards.ShardedEnv`);
            default: here. The policy trained is the same either way.

    Returns:
        The training summary (``summary.json``).
    """
    with claim_run_dir(out, command="generalist", resume=resume):
        return _train_generalist(job.check(), Path(out), resume, device, progress, log, cluster)


def _train_generalist(
    job: GeneralistJob,
    out: Path,
    resume: bool,
    device: str | None,
    progress: bool,
    log: Callable[[str], None],
    cluster: Executor | None,
) -> dict:
    from agents.pipelines.table import _table_plans
    from agents.policies import VALIDATION_SEED_OFFSET, policy_errors
    from agents.training import check_resumed_job, train, training_env
    from envs.vector import PatternCutVecEnv
    from warpcut.sim.memory import batch_named

    if resume:  # the run's own settings, but for train.iterations (train for longer)
        check_resumed_job(out, job)
    config = job.sim.validated()
    settings = dict(num_candidates=job.candidates, seed=job.seed, device=device, arm=job.arm)
    stages = lambda *_: None  # noqa: E731
    if job.train.algo == "dagger":  # the teachers' contours, cut as their teachers cut them
        from warpcut.planning.generate import generate_contours

        teachers_dir = job.train.dagger.dataset()
        teachers = load_teachers(teachers_dir, config)
        train_set = [t.contour for t in teachers]
        cuts = [(t.pinch, t.segments) for t in teachers]
        validation = generate_contours(job.validation_contours, "validation", job.seed, config)
        log(f"  {len(train_set)} teachers ({teachers_dir}), {len(validation)} validation contours")
        plans, _ = _table_plans(True, validation, config, settings, out, log, stages, resume, cluster)
        cuts += [(p.chosen["pinch"], p.ordered_segments()) for p in plans]
    else:
        train_set, validation = training_contours(job)
        log(f"  {len(train_set)} training contours, {len(validation)} validation contours")
        plans, _ = _table_plans(
            True, train_set + validation, config, settings, out, log, stages, resume, cluster
        )
        cuts = [(p.chosen["pinch"], p.ordered_segments()) for p in plans]
    write_json(out / CONFIG_FILE, to_plain(job))
    cfg = job.training_config(len(train_set))
    count = len(train_set)
    population = cfg.batch_size // count
    order = [e % count for e in range(cfg.batch_size)]  # policy p cuts every contour: envs p*C .. p*C+C-1
    options = _options(job, [train_set[k] for k in order], [cuts[k] for k in order], device)
    write_json(out / GENERALIST_FILE, _settings(job, train_set, validation))
    if cfg.algo == "es":
        log(f"  es: {population} perturbed policies x {count} contours = {cfg.batch_size} envs an iteration")
    if cluster is None or cluster.address is None or cfg.algo != "es":  # dagger: a contour an env, here
        env = training_env(options, cfg, job.seed)
    else:  # each worker steps whole perturbed policies' envs
        from agents.shards import ShardedEnv

        env = ShardedEnv(options, cfg.batch_size, cluster, count, cfg.torch_device, job.seed)
        log(f"  es: the batch in {len(env.parts)} part(s), on {', '.join(env.ran_on)}")
    val_options = _options(job, validation, cuts[count:], device)
    with batch_named("validation_contours", "set validation_contours to at most {fits}"):
        validation_env = PatternCutVecEnv(len(validation), val_options)
    area = validation_env.scene.area_mm2

    def validate(actor) -> np.ndarray:
        """Each validation contour's error over its own no-tension error (1 - improvement)."""
        errors = policy_errors(actor, validation_env, job.seed + VALIDATION_SEED_OFFSET)["error_mm2"]
        return errors * validation_env.scene.reward_scale / area

    latest = out if resume and any(out.glob("*.pt")) else None
    init = None if latest is not None or job.init is None else generalist_dir(job.init)
    try:
        return train(
            env, cfg, out, seed=job.seed, resume=latest, progress=progress, validate=validate,
            label=f"{cfg.algo.upper()} generalist", init=init,
            marks={"contours": count, "validation_contours": len(validation)},
        )  # fmt: skip
    finally:
        if hasattr(env, "close"):
            env.close()


def _options(
    job: GeneralistJob,
    contours: list[Contour],
    cuts: list[tuple[np.ndarray, list[np.ndarray]]],
    device: str | None,
):
    """Options of envs cutting ``contours`` at ``cuts`` (each a pinch point and the segments in order), with
    the job's env settings."""
    return PatternCutOptions(
        contour=list(contours),
        pinch_point=np.array([np.asarray(pinch, dtype=np.float64) for pinch, _ in cuts]),
        segments=[[np.asarray(s).tolist() for s in segments] for _, segments in cuts],
        sim_config=job.sim,
        device=device,
        arm=job.arm,
        **{name: getattr(job.env, name) for name in ENV_FIELDS},
    )


def _policy(job: GeneralistJob) -> dict:
    """The network's settings that fine-tuning takes (:data:`agents.generalist.POLICY_FIELDS`)."""
    own = {name: to_plain(getattr(job.train, name)) for name in POLICY_FIELDS}
    learner = getattr(job.train, job.train.algo)  # its network: the feedback path, scheduled gains
    es = {name: getattr(job.train.es, name) for name in ES_FIELDS}  # what fine-tuning with es steps by
    return own | es | {"feedback": learner.feedback, "scheduled": learner.scheduled}


def _settings(job: GeneralistJob, train_set: list[Contour], validation: list[Contour]) -> dict:
    return {
        "format": FORMAT,
        "env": to_plain(job.env),
        "policy": _policy(job),
        "sim": to_plain(job.sim),
        "training_contours": [c.name for c in train_set],
        "validation_contours": [c.name for c in validation],
        "command": " ".join(["warpcut", *sys.argv[1:]]) if Path(sys.argv[0]).name == "warpcut" else None,
    }


__all__ = ["ship_generalist", "train_generalist", "training_contours"]


def ship_generalist(
    run: str | Path | None,
    dest: str | Path,
    zero_shot: dict | None = None,
    members: Sequence[str | Path] = (),
) -> Path:
    """Copy the generalist that ``run`` (a finished run of ``warpcut generalist``) kept into ``dest``, as
    warpcut ships one: its policy alone (``best.pt``, without the optimiser's state) and its
    ``generalist.json``, with the command that trained it and the figures it reached (``figures``: the
    run's validation, and ``zero_shot``, e.g. an evaluation's mean improvements, as given). ``members``:
    other finished runs, trained with the same env settings, shipped the same way into ``dest/member-N``
    and listed in its ``generalist.json`` (:data:`agents.generalist.MEMBERS`). ``run`` None: the generalist
    in ``dest`` stays, and ``members`` join its own (``zero_shot`` replaces its figures' where given).

    Raises:
        ValueError: ``run`` or a member did not finish, holds no generalist, or observes otherwise.
    """
    from agents.generalist import MEMBERS, env_differences, generalist_settings

    dest = Path(dest)
    if run is None:
        settings, state = generalist_settings(dest), None
        if zero_shot:
            settings.setdefault("figures", {})["zero_shot"] = zero_shot
    else:
        settings, state = _shipped(Path(run), zero_shot)
    have = list(settings.get(MEMBERS, []))
    names = [f"member-{k}" for k in range(len(have) + 1, len(have) + len(members) + 1)]
    for member in members:
        differ = env_differences(settings["env"], generalist_settings(member)["env"])
        if differ:
            raise ValueError(
                f"{member}: observes or acts otherwise than {run or dest} ({', '.join(differ)} differ); "
                "train members with the same env settings"
            )
    dest.mkdir(parents=True, exist_ok=True)
    for name, member in zip(names, members, strict=True):
        ship_generalist(member, dest / name)
    if have or names:
        settings[MEMBERS] = have + names
    if state is not None:
        import io

        import torch

        from warpcut.io import write_atomic

        buffer = io.BytesIO()
        torch.save(state, buffer)
        write_atomic(dest / "best.pt", buffer.getvalue())
    write_json(dest / GENERALIST_FILE, settings)
    return dest


def _shipped(run: Path, zero_shot: dict | None) -> tuple[dict, dict]:
    """The ``generalist.json`` and the policy (a checkpoint without the optimiser's state) that ship the
    generalist ``run`` kept (:func:`ship_generalist`)."""
    from agents.checkpoints import policy_checkpoint, read_checkpoint
    from agents.config_io import apply
    from agents.generalist import generalist_settings
    from agents.jobs import GeneralistJob

    summary = read_json(run / "summary.json")
    if summary.get("status") != "completed" or not summary.get("best"):
        raise ValueError(f"{run}: not a finished generalist run (status {summary.get('status')!r})")
    settings = generalist_settings(run)
    settings["policy"] = _policy(apply(GeneralistJob(), read_json(run / CONFIG_FILE), str(run / CONFIG_FILE)))
    state = read_checkpoint(policy_checkpoint(run))
    state = {**state, "optimizer_state_dict": {}}  # the policy alone: nothing to resume
    best = summary["best"]
    command = (settings.get("command") or "warpcut generalist").split()
    for option in ("--out", "--device"):  # where and on what it ran, not what it trained
        if option in command:
            k = command.index(option)
            del command[k : k + 2]
    settings["command"] = " ".join(
        c for c in command if c not in ("--no-progress", "--resume", "--overwrite")
    )
    settings["figures"] = {
        "iteration": best["iterations"],
        "iterations": summary["iterations"],
        "training_hours": round(summary["wall_time_s"] / 3600, 2),
        "env_steps": summary["env_steps"],
        "validation_error_over_no_tension": round(best["validation_error"], 4),
        "validation_improvement_pct": round(100 * (1 - best["validation_error"]), 1),
        **({"zero_shot": zero_shot} if zero_shot else {}),
    }
    return settings, state
