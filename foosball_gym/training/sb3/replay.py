"""An off-policy run's replay buffer, kept beside its last checkpoint as tensors.

SB3 holds a SAC run's experience in memory only (its ``save_replay_buffer`` pickles, which a run
folder never asks a reader to trust): without this a resumed run went on from an empty buffer,
its first updates drawn from the few thousand steps since the restart.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from foosball_gym.training.run_dir.files import CHECKPOINT_DIR, read_latest
from foosball_gym.training.run_dir.tensors import load_tensors, save_tensors

#: The buffer's arrays (``next_observations`` is None in SB3's memory-saving mode).
FIELDS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")
# Room in a file for its counters and the torch archive's own records.
_OVERHEAD = 2**20


def replay_file(steps: int) -> str:
    """The file name of the buffer written with the checkpoint at ``steps``."""
    return f"replay_{steps:010d}.pt"


def _arrays(buffer: Any) -> dict[str, np.ndarray]:
    return {n: a for n in FIELDS if isinstance(a := getattr(buffer, n, None), np.ndarray)}


def save_replay(buffer: Any, path: Path) -> None:
    """Write the filled part of an SB3 ``ReplayBuffer`` to ``path``, atomically."""
    filled = buffer.buffer_size if buffer.full else buffer.pos
    value: dict[str, Any] = {
        "pos": int(buffer.pos),
        "full": bool(buffer.full),
        "buffer_size": int(buffer.buffer_size),
        "n_envs": int(buffer.n_envs),
    }
    value.update({name: array[:filled] for name, array in _arrays(buffer).items()})
    save_tensors(value, path)


def restore_replay(buffer: Any, path: Path) -> int:
    """Fill an SB3 ``ReplayBuffer`` with what :func:`save_replay` wrote; returns the transitions
    restored (each of ``n_envs`` environments' steps counted once).

    Raises:
        ValueError: the file is not such a buffer, or not one of this buffer's size and shape
            (the message names the file and what differs).
    """
    arrays = _arrays(buffer)
    limit = sum(a.nbytes for a in arrays.values()) + _OVERHEAD
    try:
        value = load_tensors(path, limit)
    except ValueError as err:  # larger than this buffer could have written
        raise ValueError(f"{path} is not a replay buffer this run wrote: {err}") from None
    except Exception:  # noqa: BLE001 - torch's own text is pages long and says to unpickle
        raise ValueError(
            f"{path} is not a replay buffer this run wrote: not a file of plain tensors"
        ) from None
    if not isinstance(value, dict):
        raise ValueError(f"{path} is not a replay buffer this run wrote")
    for key, want in (("buffer_size", buffer.buffer_size), ("n_envs", buffer.n_envs)):
        if value.get(key) != want:
            raise ValueError(f"{path}: {key} {value.get(key)!r}, where the run's buffer has {want}")
    pos, full = value.get("pos"), value.get("full")
    if not isinstance(full, bool) or not isinstance(pos, int) or not 0 <= pos < buffer.buffer_size:
        raise ValueError(f"{path}: its position {pos!r} or fill {full!r} is not a buffer's")
    filled = buffer.buffer_size if full else pos
    for name, array in arrays.items():
        saved = value.get(name)
        shape = (filled, *array.shape[1:])
        if not isinstance(saved, np.ndarray) or saved.shape != shape:
            got = getattr(saved, "shape", None)
            raise ValueError(f"{path}: {name} of shape {got}, where the run's takes {shape}")
        array[:filled] = saved
    buffer.pos, buffer.full = pos, full
    return filled * buffer.n_envs


def write_run_replay(model: Any, out: Path, steps: int) -> str | None:
    """Write an off-policy model's buffer for the checkpoint at ``steps``; returns its file name
    for the checkpoint's pointer (None for a model without one, PPO)."""
    buffer = getattr(model, "replay_buffer", None)
    if buffer is None:
        return None
    name = replay_file(steps)
    save_replay(buffer, out / CHECKPOINT_DIR / name)
    return name


def drop_old_replays(out: Path, keep: str) -> None:
    """Remove the buffers of earlier checkpoints (each as large as the buffer's filled part),
    once the pointer names ``keep``."""
    for path in (out / CHECKPOINT_DIR).glob("replay_*.pt"):
        if path.name != keep:
            path.unlink(missing_ok=True)


def restore_run_replay(model: Any, out: Path) -> int | None:
    """Fill an off-policy model's buffer from the run's last checkpoint; returns the transitions
    restored, 0 where the checkpoint holds none (a run from before buffers were kept), None for
    a model without a buffer.

    Raises:
        ValueError: the buffer the checkpoint names is missing or does not fit the run.
    """
    buffer = getattr(model, "replay_buffer", None)
    if buffer is None:
        return None
    pointer = read_latest(out) or {}
    name = pointer.get("replay")
    if not name:
        return 0
    path = out / CHECKPOINT_DIR / name
    if not path.is_file():
        raise ValueError(f"cannot resume {out}: its checkpoint's replay buffer {path} is missing")
    return restore_replay(buffer, path)
