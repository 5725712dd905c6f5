"""Trained policies as deployable files: TorchScript (``policy.pt``) and ONNX (``policy.onnx``).

Both map a batch of observations ``(batch, obs_dim)``, the actor's observation groups concatenated in
``config.json``'s ``obs_groups["actor"]`` order, to deterministic actions ``(batch, num_actions)``: the most
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
from rsl_rl.models import MLPModel
from rsl_rl.utils import resolve_class
from tensordict import TensorDict

from agents.train import layout_mismatch, make_run_dir, policy_checkpoint, read_checkpoint
from warpcut.io import read_json, write_atomic

ONNX_OPSET = 18
"""ONNX opset of ``policy.onnx`` (rsl-rl's choice)."""


def load_policy(source: str | Path) -> MLPModel:
    """Rebuild a trained actor on the CPU, in eval mode, from a run directory or checkpoint.

    Args:
        source: Run directory (its ``best.pt`` if training validated, else ``latest.pt``) or a checkpoint
            file; ``config.json`` is read from the checkpoint's directory.

    Returns:
        The actor; ``actor(obs_tensordict)`` returns deterministic actions.

    Raises:
        FileNotFoundError: No checkpoint, or no ``config.json`` beside it.
        ValueError: The checkpoint or ``config.json`` cannot be read, or they do not fit together; the
            message names the file and the fix.
    """
    checkpoint = policy_checkpoint(source)
    state = read_checkpoint(checkpoint)
    path = checkpoint.parent / "config.json"
    if not path.is_file():
        raise FileNotFoundError(
            f"{path}: missing; a checkpoint is read with the config.json 'warpcut train' wrote beside it "
            "(give the run directory, or a checkpoint inside it)"
        )
    config = read_json(path)
    try:
        env, rsl_cfg = config["env"], config["rsl_rl"]
        obs = TensorDict(
            {group: torch.zeros(1, *shape) for group, shape in env["obs_shapes"].items()}, batch_size=[1]
        )
        actor_class, actor_cfg = resolve_class(rsl_cfg["actor"])
        actor = actor_class(obs, rsl_cfg["obs_groups"], "actor", env["num_actions"], **actor_cfg)
    except (KeyError, TypeError, AttributeError, ValueError) as exc:
        raise ValueError(
            f"{path}: not a run's config.json ({type(exc).__name__}: {exc}); restore it or retrain"
        ) from None
    mismatch = layout_mismatch(state["actor_state_dict"], actor.state_dict(), path.name)
    if mismatch:
        raise ValueError(
            f"{checkpoint}: {mismatch}: {path.name} was written by another training than this checkpoint; "
            "export or evaluate a checkpoint of the run that wrote it, or retrain"
        )
    actor.load_state_dict(state["actor_state_dict"])
    return actor.eval()


def policy_runs(source: str | Path) -> list[tuple[Path, str]]:
    """The policies a directory holds, as ``(run directory or checkpoint, what it is)``: a checkpoint file;
    a ``warpcut train`` run; a ``warpcut run`` directory (the policy of the candidate it chose); an
    ``evaluate`` directory (each contour's policy in ``policies/``).

    Raises:
        FileNotFoundError: ``source`` does not exist.
        ValueError: ``source`` holds no policy (the message says what would).
    """
    from agents.rl import is_run

    source = Path(source)
    if not source.exists():
        raise FileNotFoundError(f"{source}: no such run directory or checkpoint")
    if source.is_file() or is_run(source) or any(source.glob("*.pt")):  # a checkpoint, or train()'s run
        return [(source, f"{'checkpoint' if source.is_file() else 'train run'} {source}")]
    results = source / "results.json"
    report = read_json(results) if results.is_file() else {}
    if isinstance(report, dict) and report.get("policy") == "rl" and report.get("candidates"):
        chosen = report["candidates"][int(report["chosen_candidate"])]
        run = source / chosen["run"]
        return [(run, f"run {source}: the chosen pinch candidate's policy ({run.relative_to(source)})")]
    policies = sorted(d for d in (source / "policies").glob("*") if is_run(d))
    if policies:
        return [(d, f"evaluate {source}: {d.name}'s policy") for d in policies]
    raise ValueError(
        f"{source}: holds no trained policy; give a run directory of 'warpcut train', 'warpcut run "
        "--policy rl' or 'warpcut evaluate' with rl, or a .pt checkpoint"
    )


def export_run(source: str | Path, out_dir: str | Path | None = None) -> list[dict]:
    """Export every policy ``source`` holds (:func:`policy_runs`): one policy into ``out_dir`` (default
    ``exported/`` beside its checkpoint), an evaluate directory's into ``out_dir/NAME`` (default
    ``SOURCE/exported/NAME``). Returns per policy ``{"policy": what it is, "torchscript": path, "onnx":
    path}``."""
    runs = policy_runs(source)
    exported = []
    for run, what in runs:
        target = out_dir
        if len(runs) > 1:
            target = Path(out_dir if out_dir is not None else Path(source) / "exported") / run.name
        exported.append({"policy": what, **export_policy(run, target)})
    return exported


def policy_metadata(source: str | Path) -> dict[str, str]:
    """What an exported policy's inputs and outputs mean, as ONNX metadata (string values, JSON where
    structured): ``warpcut.observations`` (the name of each input entry, :mod:`envs.observations`),
    ``warpcut.actions`` (the meaning of each action: discrete choices, or continuous axes in units of
    ``max_step_mm``), ``warpcut.scenario`` (the run's options) and ``warpcut.checkpoint``; only the last for
    a run of another env."""
    import json

    from agents.rl import is_run, load_options
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
    names = observation_names(
        options.num_fiducials, options.contour_features, options.observe_pinch, options.observe_plan
    )
    scenario = dataclasses.replace(options, device=None).to_dict()
    return {
        "warpcut.observations": json.dumps(names),
        "warpcut.actions": json.dumps(actions),
        "warpcut.scenario": json.dumps(scenario, default=str),
        "warpcut.checkpoint": str(checkpoint),
    }


def export_policy(source: str | Path, out_dir: str | Path | None = None) -> dict[str, Path]:
    """Write ``policy.pt`` (TorchScript) and ``policy.onnx`` for the actor of a run or checkpoint; the ONNX
    carries :func:`policy_metadata`.

    Args:
        source: Run directory (``best.pt`` if training validated, else ``latest.pt``) or a checkpoint.
        out_dir: Where to write; defaults to ``exported/`` beside the checkpoint.

    Returns:
        Paths of the files, under the keys "torchscript" and "onnx".
    """
    actor = load_policy(source)
    metadata = policy_metadata(source)
    out_dir = make_run_dir(out_dir if out_dir is not None else policy_checkpoint(source).parent / "exported")
    for name in ("policy.pt", "policy.onnx"):
        if (out_dir / name).is_dir():
            raise ValueError(f"{out_dir / name}: is a directory; remove it, or choose another --out")

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
    tmp_path = out_dir / f".{onnx_path.name}.tmp"
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
    return {"torchscript": torchscript_path, "onnx": onnx_path}


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
