"""A run's ``best/``: the model of its best evaluation so far, kept because PPO's success rate
can fall back after a peak."""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from foosball_gym.training.run_dir.files import BEST_DIR, BEST_RECORD, atomic_write_text, read_json


def read_best(run: Path) -> dict[str, Any] | None:
    """The row of ``eval.csv`` that earned the run's ``best/`` (None: no best yet); ValueError
    in one line where ``best.json`` is damaged."""
    record = Path(run) / BEST_DIR / BEST_RECORD
    if not record.exists():
        return None
    row = read_json(record, dict, "the evaluation that earned the best model")
    for key in ("success_rate", "timesteps"):
        if not isinstance(row.get(key), int | float) or isinstance(row.get(key), bool):
            raise ValueError(f"{record}: {key} must be a number, got {row.get(key)!r}")
    return row


class BestModel:
    """The best evaluation of the run in ``run`` so far; a resumed run goes on from its
    ``best/best.json`` (the row of ``eval.csv`` that earned it)."""

    def __init__(self, run: Path) -> None:
        self.dir = Path(run) / BEST_DIR
        self.record = self.dir / BEST_RECORD
        best = read_best(run)
        self.success_rate = -1.0 if best is None else float(best["success_rate"])

    def offer(self, row: Mapping[str, Any], save: Callable[[Path], None]) -> bool:
        """Keep the model evaluated in ``row`` where it did at least as well as the best so
        far: ``save(best_dir)`` writes it, then ``best.json`` records the row. Whether it
        was kept."""
        if row["success_rate"] < self.success_rate:
            return False
        self.success_rate = row["success_rate"]
        self.dir.mkdir(exist_ok=True)
        save(self.dir)
        atomic_write_text(self.record, json.dumps(row))
        return True
