"""TensorBoard scalars of an RLlib run, written where tensorboard is installed."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np


class TensorboardWriter:
    """TensorBoard scalars where tensorboard is installed; nothing otherwise."""

    def __init__(self, directory: Path) -> None:
        try:
            from torch.utils.tensorboard import SummaryWriter
        except ImportError:
            self._writer = None
            return
        directory.mkdir(parents=True, exist_ok=True)
        self._writer = SummaryWriter(str(directory))

    def scalars(self, values: Mapping[str, float | None], step: int) -> None:
        if self._writer is None:
            return
        for key, value in values.items():
            if value is not None and np.isfinite(value):
                self._writer.add_scalar(key, float(value), step)
        self._writer.flush()

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
