"""Trained policies as deployable files: TorchScript (``policy.pt``) and ONNX (``policy.onnx``).

Both map a batch of observations ``(batch, obs_dim)``, the actor's observation groups concatenated in
the checkpoint's ``obs_groups["actor"]`` order, to deterministic actions ``(batch, num_actions)``: the most
likely choice index (as a float, exactly what the env's ``step()`` receives in training) for discrete
policies, the Gaussian mean for continuous ones. Observation normalization is part of both. They are built
from rsl-rl's own export wrappers (``MLPModel.as_jit`` and ``as_onnx``), which its runner uses too; the
runner's export methods need a live env, these need only the run directory.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import logging
import os
import warnings
from collections.abc import Iterator
from pathlib import Path

import torch

from agents.checkpoints import policy_checkpoint
from agents.policies import is_run, load_options, load_policy, policy_runs
from agents.training import make_run_dir
from warpcut.io import (
    claim_run_dir,
    enclosing_run,
    note_written,
    read_run_marker,
    temp_file,
    write_atomic,
    written_by_warpcut,
)
from warpcut.planning import check_pinch

ONNX_OPSET = 18
"""ONNX opset of ``policy.onnx`` (rsl-rl's choice)."""


def export_run(source: str | Path, out_dir: str | Path | None = None) -> list[dict]:
    """Export every policy ``source`` holds (:func:`policy_runs`): one policy into ``out_dir`` (default
    ``exported/`` beside its checkpoint), an evaluate directory's into ``out_dir/NAME`` (default
    ``SOURCE/exported/NAME``). Returns per policy ``{"policy": what it is, "torchscript": path, "onnx":
    path, "unfinished": what :func:`unfinished_note` says, or None}``."""
    if out_dir is not None and enclosing_run(out_dir) is None:  # a folder of its own: marked as warpcut's
        with claim_run_dir(out_dir, command="export", reuse=True):
            return _export_runs(source, out_dir)
    inside, own = (None, None) if out_dir is None else (enclosing_run(out_dir), enclosing_run(source))
    exports = inside is not None and (read_run_marker(inside) or {}).get("command") == "export"
    if inside is not None and not exports and (own is None or Path(inside).resolve() != Path(own).resolve()):
        raise ValueError(
            f"{out_dir}: lies in the run in {inside}, not the one exported from, so warpcut never writes "
            "there; choose a folder outside it (or leave --out out: the run's own exported/)"
        )
    return _export_runs(source, out_dir)


def _export_runs(source: str | Path, out_dir: str | Path | None) -> list[dict]:
    runs = policy_runs(source)
    exported = []
    for run, what in runs:
        target = out_dir
        if len(runs) > 1:
            target = Path(out_dir if out_dir is not None else Path(source) / "exported") / run.name
        exported.append({"policy": what, **export_policy(run, target), "unfinished": unfinished_note(run)})
    return exported


def training_status(source: str | Path) -> dict | None:
    """How far the training of the run whose policy ``source`` (a run directory or checkpoint) exports got:
    ``{"status", "iterations", "target_iterations", "checkpoint"}``, ``status`` being its
    ``summary.json``'s (``completed``, ``interrupted``, ``failed``) or ``unfinished`` where it has none
    (killed, or still training), ``iterations`` those trained (its newest checkpoint's, without a summary),
    ``target_iterations`` those it was to train (None where not recorded) and ``checkpoint`` the one
    exported; None for a checkpoint outside a run directory."""
    from agents.checkpoints import latest_checkpoint, read_checkpoint
    from warpcut.io import read_json

    checkpoint = policy_checkpoint(source)
    run = checkpoint.parent
    if not is_run(run):
        return None
    summary = read_json(run / "summary.json") if (run / "summary.json").is_file() else None
    summary = summary if isinstance(summary, dict) else {}
    iterations = summary.get("iterations")
    if iterations is None:
        state = read_checkpoint(latest_checkpoint(run))
        iterations = (state.get("infos") or {}).get("iterations_done", state["iter"] + 1)
    target = summary.get("target_iterations")
    if target is None and (run / "config.json").is_file():
        config = read_json(run / "config.json")
        target = ((config.get("train") or {}) if isinstance(config, dict) else {}).get("iterations")
    return {
        "status": summary.get("status") or "unfinished",
        "iterations": iterations,
        "target_iterations": target,
        "checkpoint": checkpoint.name,
    }


def unfinished_note(source: str | Path) -> str | None:
    """One line saying that the run whose policy ``source`` exports did not finish its training (see
    :func:`training_status`) and which checkpoint was exported; None for a finished run."""
    status = training_status(source)
    if status is None or status["status"] == "completed":
        return None
    run = policy_checkpoint(source).parent
    how = {"unfinished": "no summary.json: killed, or still training"}.get(status["status"], status["status"])
    of = "" if status["target_iterations"] is None else f" of {status['target_iterations']}"
    name = status["checkpoint"]
    which = {"latest.pt": "its latest checkpoint", "best.pt": "its best checkpoint so far"}.get(name)
    return (
        f"{run} is unfinished ({how}; trained {status['iterations']}{of} iterations); exported "
        f"{which or 'the checkpoint'} ({name})"
    )


def policy_metadata(source: str | Path) -> dict[str, str]:
    """What an exported policy's inputs and outputs mean, as ONNX metadata (string values, JSON where
    structured): ``warpcut.observations`` (the name of each input entry, :mod:`envs.observations`),
    ``warpcut.actions`` (the meaning of each action: discrete choices, or continuous axes in units of
    ``max_step_mm``), ``warpcut.options`` (the run's :class:`~envs.options.PatternCutOptions` as JSON: its
    fields are ``gymnasium.make("warpcut/PatternCut-v0", **options)``'s keyword arguments),
    ``warpcut.pinch_feasible`` (``true``, or ``false`` with ``warpcut.pinch_problem``: the run's pinch point
    is not a grasp the gripper could make), ``warpcut.training`` (:func:`training_status`: an unfinished
    run's policy says so) and ``warpcut.checkpoint``; only the last for a run of another env."""
    import json

    from envs.core import DISCRETE_MOVES
    from envs.observations import observation_names

    checkpoint = policy_checkpoint(source)
    if not is_run(checkpoint.parent):  # a policy of another env (train() takes any rsl-rl VecEnv)
        return {"warpcut.checkpoint": str(checkpoint)}
    options = load_options(checkpoint.parent)
    axes = 3 if options.allow_z else 2
    if options.action_type == "discrete":
        moves = DISCRETE_MOVES[: 1 + 2 * axes]
        actions = [
            "stay" if not move.any() else f"{'+' if move.sum() > 0 else '-'}{'xyz'[int(abs(move).argmax())]}"
            for move in moves
        ]
        actions = [f"{k}: {name} (grasp move of max_step_mm)" for k, name in enumerate(actions)]
    else:
        actions = [f"grasp d{axis} / max_step_mm, in [-1, 1]" for axis in "xyz"[:axes]]
    names = observation_names(options.num_fiducials, options.contour_features, options.lookahead)
    scenario = dataclasses.replace(options, device=None).to_dict()
    contours, pinch, cuts = dataclasses.replace(options, allow_infeasible_pinch=True).per_env(1)
    problem = check_pinch(pinch[0], contours[0], options.config(), cuts and cuts[0], options.arm, allow=True)
    return {
        "warpcut.observations": json.dumps(names),
        "warpcut.actions": json.dumps(actions),
        "warpcut.options": json.dumps(scenario),
        "warpcut.pinch_feasible": json.dumps(problem is None),
        **({} if problem is None else {"warpcut.pinch_problem": problem}),
        "warpcut.training": json.dumps(training_status(checkpoint)),
        "warpcut.checkpoint": str(checkpoint),
    }


def export_policy(source: str | Path, out_dir: str | Path | None = None) -> dict[str, Path]:
    """Write ``policy.pt`` (TorchScript) and ``policy.onnx`` for the actor of a run or checkpoint; the ONNX
    carries :func:`policy_metadata`.

    Args:
        source: Run directory (``best.pt`` if training validated, else ``latest.pt``) or a checkpoint.
        out_dir: Where to write; defaults to ``exported/`` beside the checkpoint.

    Returns:
        Paths of the files, under the keys "torchscript" and "onnx", and "pinch_problem": why the run's
        pinch point is not a grasp the gripper could make (its training allowed it), or None.
    """
    actor = load_policy(source)
    metadata = policy_metadata(source)
    target = Path(out_dir if out_dir is not None else policy_checkpoint(source).parent / "exported")
    made = [p for p in (target, *target.parents) if not p.exists()]
    out_dir = make_run_dir(target)
    try:
        return _write_policy(actor, metadata, out_dir)
    except BaseException:
        for folder in made:  # a refused export leaves no folder behind (only where it is empty)
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise


def _write_policy(actor, metadata: dict, out_dir: Path) -> dict[str, Path]:
    """:func:`export_policy`'s files, in the folder ``out_dir``."""
    for name in ("policy.pt", "policy.onnx"):
        if (out_dir / name).is_dir():
            raise ValueError(f"{out_dir / name}: is a directory; remove it, or choose another --out")
        if (out_dir / name).exists() and not written_by_warpcut(out_dir / name):
            raise ValueError(
                f"{out_dir / name}: exists, and warpcut did not write it, so never replaces it: move it, "
                "or choose another --out"
            )

    buffer = io.BytesIO()
    with warnings.catch_warnings():
        # TorchScript is deprecated in favour of torch.export, but it is what C++ deployments load.
        warnings.filterwarnings("ignore", message=".*torch.jit.* is deprecated", category=DeprecationWarning)
        torch.jit.save(torch.jit.script(actor.as_jit()), buffer)
    torchscript_path = write_atomic(out_dir / "policy.pt", buffer.getvalue())

    onnx_model = actor.as_onnx(verbose=False).eval()
    # A batch of 2: torch.export would specialize a batch of 1 to a constant.
    example = torch.zeros(2, onnx_model.input_size)
    onnx_path = out_dir / "policy.onnx"
    note_written(onnx_path)  # in a run directory, a file of its run
    fd, tmp = temp_file(onnx_path)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        with _quiet_onnx_exporter():
            program = torch.onnx.export(
                onnx_model,
                (example,),
                opset_version=ONNX_OPSET,
                input_names=onnx_model.input_names,
                output_names=onnx_model.output_names,
                dynamic_shapes=({0: torch.export.Dim("batch")},),
                verbose=False,
            )
            program.model.metadata_props.update(metadata)
            program.save(tmp_path, external_data=False)
        os.replace(tmp_path, onnx_path)
    finally:
        tmp_path.unlink(missing_ok=True)
    problem = metadata.get("warpcut.pinch_problem")
    return {"torchscript": torchscript_path, "onnx": onnx_path, "pinch_problem": problem}


@contextlib.contextmanager
def _quiet_onnx_exporter() -> Iterator[None]:
    """Silence the exporter's notes about optional torchvision ops and a torch-internal deprecation."""
    exporter_log = logging.getLogger("torch.onnx")
    level = exporter_log.level
    exporter_log.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)
            yield
    finally:
        exporter_log.setLevel(level)
