"""A self-play run's ``selfplay/`` folder: its snapshots, ``opponent_<generation>.pt``, and
``history.json``, one record per snapshot (when it was taken and why), from which a resumed
run rebuilds its pool of opponents and its rule's count.

Shared by the Stable-Baselines3 callback and the RLlib backend, whose snapshots differ (a
policy with its normalisation; a module's state) but whose history is the same. Needs
neither PyTorch nor either learning library.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from foosball_gym.training.run_dir.files import HISTORY_FILE, atomic_write_text, read_json
from foosball_gym.training.selfplay.rule import ReplacementRule

# What self-play's gate writes: its verdicts, and the generations that passed as models.
GATE_LOG = "gate.jsonl"
# The stalls a run found: one line each, when and against which generation.
STALL_LOG = "stalls.jsonl"


def snapshot_file(save_dir: Path, generation: int) -> Path:
    """Where the snapshot of ``generation`` is saved in ``save_dir``."""
    return save_dir / f"opponent_{generation:04d}.pt"


def generation_files(save_dir: Path, generation: int) -> list[Path]:
    """The files of ``generation`` in ``save_dir`` (its snapshot, and the model the gate
    saved where it passed one), those that are there."""
    name = f"generation_{generation:04d}"
    candidates = [snapshot_file(save_dir, generation), save_dir / f"{name}.zip"]
    candidates.append(save_dir / f"{name}_vecnormalize.json")
    return [c for c in candidates if c.exists()]


def read_history(path: Path) -> list[dict[str, Any]]:
    """A run's ``history.json``: one record per snapshot, oldest first; ValueError in one line
    where it is damaged."""
    records = read_json(path, list, "the run's snapshots, one record each")
    before = -1
    for k, record in enumerate(records):
        if not isinstance(record, dict):
            raise ValueError(f"{path}: record {k} is a {type(record).__name__}, not an object")
        for key in ("generation", "timesteps", "games"):
            value = record.get(key)
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise ValueError(
                    f"{path}: record {k}'s {key} must be a whole number, 0 or more, got {value!r}"
                )
        if record["generation"] <= before:
            raise ValueError(f"{path}: the generations must rise, record by record")
        before = record["generation"]
    return records


def set_aside_generations(save_dir: Path, timesteps: int, lost: Path) -> int:
    """Move the records, snapshots, gate verdicts and stalls made after ``timesteps`` (on a
    branch of the run that was lost) from ``save_dir`` into ``lost``; how many generations
    that was."""
    for log in (GATE_LOG, STALL_LOG):
        path = save_dir / log
        lines = path.read_text().splitlines(keepends=True) if path.exists() else []
        late = [line for line in lines if _verdict_steps(line, path) > timesteps]
        if late:
            lost.mkdir(parents=True, exist_ok=True)
            atomic_write_text(lost / log, "".join(late))
            atomic_write_text(path, "".join(line for line in lines if line not in late))
    path = save_dir / HISTORY_FILE
    if not path.exists():
        return 0
    records = read_history(path)
    kept = [r for r in records if r["timesteps"] <= timesteps]
    gone = records[len(kept) :]
    if not gone:
        return 0
    lost.mkdir(parents=True, exist_ok=True)
    for record in gone:
        for file in generation_files(save_dir, record["generation"]):
            shutil.move(file, lost / file.name)
    atomic_write_text(lost / HISTORY_FILE, json.dumps(gone, indent=1))
    atomic_write_text(path, json.dumps(kept, indent=1))
    return len(gone)


def history_record(
    generation: int,
    timesteps: int,
    games: int,
    rule: ReplacementRule,
    score: float | None,
    elo: float,
) -> dict[str, Any]:
    """One line of a run's ``selfplay/history.json``: a snapshot, when and why it was taken."""
    return {
        "generation": generation,
        "timesteps": int(timesteps),
        "games": int(games),
        "rule": rule.rule,
        "score": score,
        "elo": float(elo),
    }


def restored_elo(history: list[dict[str, Any]], generations: list[int]) -> float:
    """The mean rating of ``generations`` as ``history`` records them (0 where it has none:
    runs from before ratings were recorded)."""
    by_generation = {h["generation"]: h.get("elo") or 0.0 for h in history}
    return float(np.mean([by_generation.get(g, 0.0) for g in generations]))


def _verdict_steps(line: str, log: Path) -> int:
    try:
        steps = json.loads(line)["timesteps"]
    except (json.JSONDecodeError, KeyError, TypeError):
        steps = None
    if not isinstance(steps, int):
        raise ValueError(f"{log} is damaged: a line is not a record with its timesteps")
    return steps


class SnapshotHistory:
    """The records of a run's snapshots, kept with the replacement rule that judges them.

    Args:
        save_dir: the run's ``selfplay/``; None keeps the records in memory only.
        rule: the run's rule: a restore sets its count of games, and every change of the pool
            its opponents' rating.
        pool_size: how many of the latest snapshots play as opponents.
    """

    def __init__(self, save_dir: Path | None, rule: ReplacementRule, pool_size: int) -> None:
        self.save_dir = save_dir
        self.rule = rule
        self.pool_size = pool_size
        self.records: list[dict[str, Any]] = []

    def saved(self) -> bool:
        """Whether ``save_dir`` holds a history to go on from."""
        return self.save_dir is not None and (self.save_dir / HISTORY_FILE).exists()

    def restore(self) -> list[int]:
        """Read ``history.json``: the generations of the pool, oldest first. The rule counts
        on from the games played so far and rates the pool as it was rated."""
        assert self.save_dir is not None
        self.records = read_history(self.save_dir / HISTORY_FILE)
        if not self.records:
            raise ValueError(f"{self.save_dir / HISTORY_FILE} holds no generation")
        pool = [h["generation"] for h in self.records][-self.pool_size :]
        self.rule.games = self.rule.replaced_at = self.records[-1]["games"]
        if self.records[-1].get("rule") not in (None, self.rule.rule):
            # A stall switched the rule before the last replacement; a stall since then the
            # resumed run finds again after as many games.
            self.rule.fall_back()
        self.rule.opponent_elo = restored_elo(self.records, pool)
        return pool

    def add(
        self, generation: int, timesteps: int, score: float | None, elo: float, pool: list[int]
    ) -> None:
        """Record the snapshot of ``generation`` (its file written already), now in the pool
        of ``pool``'s generations, and write ``history.json``."""
        self.records.append(
            history_record(generation, timesteps, self.rule.games, self.rule, score, elo)
        )
        self.rule.opponent_elo = restored_elo(self.records, pool)
        if self.save_dir is not None:
            self.save_dir.mkdir(parents=True, exist_ok=True)
            atomic_write_text(self.save_dir / HISTORY_FILE, json.dumps(self.records, indent=1))
