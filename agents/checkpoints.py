"""A training run's checkpoints: which file a run's policy, a resume or an export reads, reading one safely
(weights only; a damaged, truncated or foreign file named with what to use instead), and whether a policy
fits an env.

A run directory holds ``model_K.pt`` (after learning iteration K, 0-based, rsl-rl's naming), ``latest.pt`` (a
copy of the newest) and, where training validated, ``best.pt`` (the policy validation kept). Every checkpoint
describes its policy (``policy``: the actor's rsl-rl config, its observation shapes and actions), so it can be
rebuilt from the file alone (:func:`agents.policies.load_policy`).
"""

from __future__ import annotations

import re
from pathlib import Path

import torch

LATEST_CHECKPOINT = "latest.pt"
"""File name of the copy of the newest checkpoint in a run directory."""
BEST_CHECKPOINT = "best.pt"
"""File name of the checkpoint with the lowest validation error in a run directory."""

_MODEL_CHECKPOINT = re.compile(r"model_(\d+)\.pt")
"""rsl-rl's name of the checkpoint after learning iteration K (0-based): ``model_K.pt``."""

CHECKPOINT_KEYS = ("actor_state_dict", "optimizer_state_dict", "iter", "policy")
"""What every checkpoint of a run holds."""


def model_checkpoints(run_dir: str | Path) -> list[Path]:
    """The run directory's ``model_K.pt`` files, newest (highest K) first."""
    found = [
        (int(match[1]), p)
        for p in Path(run_dir).glob("model_*.pt")
        if (match := _MODEL_CHECKPOINT.fullmatch(p.name)) and p.is_file()
    ]
    return [p for _, p in sorted(found, reverse=True)]


def read_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> dict:
    """A checkpoint's contents (weights only: nothing in it is executed).

    Raises:
        FileNotFoundError: There is no file at ``path``.
        ValueError: ``path`` is a directory, or not a readable checkpoint (empty, truncated, damaged, or
            another kind of file); the message names the file and what to use instead.
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(
            f"{path}: is a directory, not a checkpoint file; give a run directory or one of its .pt files"
        )
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such checkpoint; give a run directory or one of its .pt files")
    why = _load_or_why(path, map_location)
    if isinstance(why, dict):
        return why
    raise ValueError(f"{path}: not a readable checkpoint ({why}); {_instead(path)}")


def _load_or_why(path: Path, map_location: str | torch.device = "cpu") -> dict | str:
    """``path``'s checkpoint, or why it is not one (e.g. "truncated or damaged?")."""
    with open(path, "rb") as f:
        head = f.read(4)
    if not head:
        return "an empty file: its write was cut short"
    try:
        state = torch.load(path, map_location=map_location, weights_only=True)
    except PermissionError:
        raise
    except Exception:  # torch raises EOFError, OSError 22, UnpicklingError, RuntimeError, KeyError, ...
        return "truncated or damaged?" if head.startswith(b"PK") else "not a PyTorch checkpoint file"
    missing = [k for k in CHECKPOINT_KEYS if not isinstance(state, dict) or k not in state]
    if missing:
        return f"not a checkpoint of 'warpcut train': no {', '.join(missing)}"
    return state


def _readable(path: Path) -> bool:
    return path.is_file() and isinstance(_load_or_why(path), dict)


def _instead(path: Path) -> str:
    """What to do about the unreadable checkpoint ``path``: which checkpoint of its run to use instead."""
    run = path.parent
    if path.suffix != ".pt":
        where = f" (such as {run})" if (run / "config.json").is_file() else ""
        return f"give a run directory written by 'warpcut train'{where}, or one of its .pt checkpoints"
    others = [p for p in (run / LATEST_CHECKPOINT, *model_checkpoints(run)) if p != path]
    fallback = next((p for p in others if _readable(p)), None)
    if fallback is None:
        return "the run has no other readable checkpoint: retrain it"
    if path.name == BEST_CHECKPOINT:
        return f"delete it to use the run's last policy ({fallback.name}), not the validated best, or retrain"
    if path.name == LATEST_CHECKPOINT:
        return f"delete it to fall back to {fallback.name} (the newest readable checkpoint), or retrain"
    return f"use another checkpoint (e.g. {fallback.name}, the newest readable one), or retrain"


def saved_nothing(path: str | Path) -> bool:
    """Whether ``path`` is a run directory that holds no checkpoint yet (stopped before its first one, e.g.
    killed): resuming it starts it from the beginning, with its own settings."""
    path = Path(path)
    return path.is_dir() and not (path / LATEST_CHECKPOINT).exists() and not model_checkpoints(path)


def resume_checkpoint(path: str | Path) -> tuple[Path, dict, str | None]:
    """The checkpoint to continue ``path`` from, its contents, and a note when it is not the run's
    ``latest.pt``.

    A checkpoint file is read as it is. A run directory resumes from ``latest.pt``, unless it is missing or
    unreadable (a run that never wrote one, or a damaged file) or older than the newest ``model_K.pt`` (its
    write failed): then from the newest readable ``model_K.pt``, and the note says so.

    Raises:
        FileNotFoundError: ``path`` does not exist, or the run directory holds no checkpoint.
        ValueError: A checkpoint file that cannot be read, or a run directory with no readable checkpoint.
    """
    path = Path(path)
    if not path.is_dir():
        return path, read_checkpoint(path), None
    latest = path / LATEST_CHECKPOINT
    models = model_checkpoints(path)
    if not latest.exists() and not models:
        raise FileNotFoundError(
            f"{path}: no checkpoint to resume from (no {LATEST_CHECKPOINT} or model_K.pt): start it again "
            "without resuming"
        )
    state, why = None, "missing"
    if latest.exists():
        found = _load_or_why(latest) if latest.is_file() else "not a file"
        state, why = (found, None) if isinstance(found, dict) else (None, found)
    done = (state.get("infos") or {}).get("iterations_done", state["iter"] + 1) if state is not None else -1
    skipped = []
    for model in models:
        if int(_MODEL_CHECKPOINT.fullmatch(model.name)[1]) + 1 <= done:
            break  # latest.pt is at least as new
        found = _load_or_why(model)
        if not isinstance(found, dict):
            skipped.append(model.name)
            continue
        why = why or f"older than {model.name} (its last write failed?)"
        unread = f" ({', '.join(skipped)} unreadable)" if skipped else ""
        return model, found, f"{path}: {LATEST_CHECKPOINT} {why}; resuming from {model.name}{unread}"
    if state is None:
        raise ValueError(
            f"{path}: no readable checkpoint to resume from ({LATEST_CHECKPOINT}: {why}"
            + (f"; unreadable: {', '.join(skipped)}" if skipped else "")
            + "); delete the run directory and retrain"
        )
    unread = f"{path}: newer checkpoints unreadable ({', '.join(skipped)}); resuming from {LATEST_CHECKPOINT}"
    return latest, state, unread if skipped else None


def latest_checkpoint(path: str | Path) -> Path:
    """``path`` if it is a file, else the run directory's ``latest.pt``, or its newest ``model_K.pt`` where
    it never wrote one (unread: see :func:`resume_checkpoint` for the checkpoint a resume reads)."""
    path = Path(path)
    if not path.is_dir():
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such checkpoint or run directory")
        return path
    if (path / LATEST_CHECKPOINT).exists():
        return path / LATEST_CHECKPOINT
    models = model_checkpoints(path)
    if not models:
        raise FileNotFoundError(
            f"{path}: no checkpoint ({LATEST_CHECKPOINT} or model_K.pt); give a run directory that "
            "'warpcut train' wrote"
        )
    return models[0]


def policy_checkpoint(path: str | Path) -> Path:
    """The checkpoint whose policy a run stands for: ``path`` if it is a file, else the run directory's
    ``best.pt`` (the validated best, when training validated) or its newest (:func:`latest_checkpoint`)."""
    path = Path(path)
    if path.is_dir() and (path / BEST_CHECKPOINT).exists():
        return path / BEST_CHECKPOINT
    return latest_checkpoint(path)


def policy_layout(actor_state: dict) -> tuple[int, int]:
    """``(observations, outputs)`` of an actor's state dict: the inputs of its MLP's first layer and the
    outputs of its last (discrete: actions times choices; continuous: the actions), or of its feedback path
    where it has one (:class:`agents.models.FeedbackMLP`)."""
    layers = sorted(
        (int(match[1]), value)
        for key, value in actor_state.items()
        if (match := re.fullmatch(r"mlp\.(?:body\.)?(\d+)\.weight", key)) and value.ndim == 2
    )
    if not layers:
        raise ValueError("actor state: no MLP layers (mlp.K.weight); not an rsl-rl MLP actor")
    feedback = actor_state.get("mlp.feedback.weight")
    if feedback is not None:  # its gains act on the moves (the last layer may also give scheduled gains)
        return int(layers[0][1].shape[1]), int(feedback.shape[0])
    return int(layers[0][1].shape[1]), int(layers[-1][1].shape[0])


def layout_difference(saved: tuple[int, int], expected: tuple[int, int], source: str) -> str | None:
    """How a policy of layout ``saved`` (``(observations, outputs)``, :func:`policy_layout`) does not fit
    the ``expected`` one of ``source`` (e.g. "the env"), in words; None when they are the same."""
    if saved[0] != expected[0]:
        return f"policy expects {saved[0]} observations, {source} gives {expected[0]}"
    if saved[1] != expected[1]:
        return f"policy has {saved[1]} action outputs, {source} needs {expected[1]}"
    return None


def layout_mismatch(saved: dict, expected: dict, source: str) -> str | None:
    """How the actor state ``saved`` (a checkpoint's) does not fit the actor state ``expected`` (built for
    ``source``, e.g. "the env"), in words; None when every tensor has the shape expected."""
    difference = layout_difference(policy_layout(saved), policy_layout(expected), source)
    if difference:
        return difference
    if set(saved) != set(expected):
        keys = sorted(set(saved) ^ set(expected))
        return f"policy network differs from {source}'s ({', '.join(keys[:4])})"
    for key, value in expected.items():
        if tuple(saved[key].shape) != tuple(value.shape):
            shapes = f"{tuple(saved[key].shape)}, {source}'s {tuple(value.shape)}"
            return f"policy network differs from {source}'s ({key}: {shapes})"
    return None


def start_from(runner, source: str | Path, gain: float = 1.0) -> None:
    """Load the policy of ``source`` (a run directory or checkpoint) into ``runner``'s fresh actor: its
    weights and observation normaliser (es then skips its warm-up: the normaliser has learnt already), its
    moves multiplied by ``gain`` (:func:`agents.models.scale_moves_`; 1: as they are, bit for bit).

    Raises:
        ValueError: not es, or the policy does not observe and act as the env does (the message names the
            checkpoint).
    """
    from agents.algorithms import ALGORITHMS, algorithm

    if not algorithm(runner.algo).fine_tunes:
        which = ", ".join(name for name, entry in ALGORITHMS.items() if entry.fine_tunes)
        raise ValueError(f"init: fine-tuning starts {which} from a generalist; train.algo is {runner.algo}")
    checkpoint = policy_checkpoint(source)
    state = read_checkpoint(checkpoint)["actor_state_dict"]
    actor = runner.alg.actor
    mismatch = layout_mismatch(state, actor.state_dict(), "the env's policy")
    if mismatch:
        raise ValueError(
            f"init: {checkpoint}: {mismatch}; train with the generalist's env settings (leave env.* unset)"
        )
    actor.load_state_dict(state)
    if gain != 1.0:
        from agents.models import scale_moves_

        scale_moves_(actor.mlp, gain)
    runner.alg._warm_up = False
