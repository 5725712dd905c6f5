"""What a ``.rrd`` recording holds, read back from the file: :func:`read_summary` (``warpcut replay``)."""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path


@dataclass
class RecordingSummary:
    """What a ``.rrd`` file holds, read back from it."""

    application_id: str
    """The rerun application id."""
    frames: int
    """Distinct ``step`` values recorded."""
    first_step: int
    last_step: int
    duration_s: float
    """Simulated time from the first to the last frame (s)."""
    entity_paths: list[str]
    """Every entity with data, sorted."""


def is_complete(path: str | os.PathLike) -> bool:
    """Whether the ``.rrd`` file at ``path`` was finished: it ends in rerun's footer (a file cut short, e.g.
    by a full disk, does not; rerun then only warns and reads what it can)."""
    from rerun.chunk import RrdReader

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            RrdReader(Path(path))
        except (OSError, ValueError, RuntimeError):
            return False
    return not any("no footer" in str(w.message) for w in caught)


def read_summary(path: str | os.PathLike) -> RecordingSummary:
    """Read a recording back: its frames, entity paths and duration.

    Raises:
        FileNotFoundError: There is no file at ``path``.
        ValueError: The file is not a readable rerun recording.
    """
    from rerun.chunk import RrdReader

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such recording")
    try:
        with warnings.catch_warnings():
            # A file without rerun's footer (cut short) is read by scanning it: said by the error, if any.
            warnings.simplefilter("ignore")
            reader = RrdReader(path)
            recordings = reader.recordings()
        if not recordings:
            raise ValueError("it holds no recording")
        steps, durations, entities = set(), [], set()
        for chunk in reader.stream(store=recordings[0]):
            if chunk.entity_path.startswith("/__"):
                continue
            entities.add(chunk.entity_path)
            batch = chunk.to_record_batch()
            if "step" in batch.schema.names:
                steps.update(batch.column("step").to_pylist())
            if "sim_time" in batch.schema.names:
                durations.extend(v / 1e9 for v in batch.column("sim_time").cast("int64").to_pylist())
    except (OSError, ValueError, RuntimeError) as exc:
        raise ValueError(f"{path}: not a readable rerun recording ({str(exc).splitlines()[0]})") from None
    return RecordingSummary(
        application_id=recordings[0].application_id,
        frames=len(steps),
        first_step=min(steps, default=0),
        last_step=max(steps, default=0),
        duration_s=(max(durations) - min(durations)) if durations else 0.0,
        entity_paths=sorted(entities),
    )
