"""Nested weights and optimiser states on disk as tensors only, read back as numpy arrays.

``torch.load(weights_only=True)`` reads such a file without unpickling any object, so the
RLlib backend's checkpoints and self-play snapshots need no trust to be read.
"""

from __future__ import annotations

import io
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from foosball_gym.training.run_dir.files import write_bytes
from foosball_gym.training.run_dir.storage import check_torch_file


def _to_tensors(value: Any) -> Any:
    """``value`` with its numpy arrays as tensors, so ``torch.load(weights_only=True)`` reads it."""
    import torch as th

    if isinstance(value, Mapping):
        return {k: _to_tensors(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_to_tensors(v) for v in value]
    if isinstance(value, np.ndarray):
        return th.from_numpy(np.ascontiguousarray(value)).clone()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, th.Tensor):
        return value.detach().cpu().clone()
    return value


def _to_arrays(value: Any) -> Any:
    import torch as th

    if isinstance(value, Mapping):
        return {k: _to_arrays(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_to_arrays(v) for v in value]
    if isinstance(value, th.Tensor):
        return value.numpy()
    return value


def save_tensors(value: Any, path: Path) -> None:
    """Write ``value`` (mappings and lists of arrays and numbers) atomically."""
    import torch as th

    buffer = io.BytesIO()
    th.save(_to_tensors(value), buffer)
    write_bytes(path, buffer.getvalue())


def load_tensors(path: Path, limit: int | None = None) -> Any:
    """What :func:`save_tensors` wrote, its tensors as numpy arrays (refused, ValueError,
    where it says it inflates past ``limit`` bytes, :data:`~.storage.MODEL_SIZE_LIMIT` unless
    given)."""
    import torch as th

    check_torch_file(path, limit)
    return _to_arrays(th.load(path, map_location="cpu", weights_only=True))
