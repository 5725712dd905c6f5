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


def export_policy(source: str | Path, out_dir: str | Path | None = None) -> dict[str, Path]:
    """Write ``policy.pt`` (TorchScript) and ``policy.onnx`` for the actor of a run or checkpoint.

    Args:
        source: Run directory (``best.pt`` if training validated, else ``latest.pt``) or a checkpoint.
        out_dir: Where to write; defaults to ``exported/`` beside the checkpoint.

    Returns:
        Paths of the files, under the keys "torchscript" and "onnx".
    """
    actor = load_policy(source)
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
            torch.onnx.export(
                onnx_model,
                (example,),
                tmp_path,
                opset_version=ONNX_OPSET,
                input_names=onnx_model.input_names,
                output_names=onnx_model.output_names,
                dynamic_shapes=({0: torch.export.Dim("batch")},),
                external_data=False,
                verbose=False,
            )
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
