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
from warpcut.io import write_atomic

ONNX_OPSET = 18
"""ONNX opset of ``policy.onnx`` (rsl-rl's choice)."""


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
    ``max_step_mm``), ``warpcut.options`` (the run's :class:`~envs.options.PatternCutOptions` as JSON: its
    fields are ``gymnasium.make("warpcut/PatternCut-v0", **options)``'s keyword arguments) and
    ``warpcut.checkpoint``; only the last for a run of another env."""
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
    names = observation_names(options.num_fiducials, options.contour_features)
    scenario = dataclasses.replace(options, device=None).to_dict()
    return {
        "warpcut.observations": json.dumps(names),
        "warpcut.actions": json.dumps(actions),
        "warpcut.options": json.dumps(scenario),
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
