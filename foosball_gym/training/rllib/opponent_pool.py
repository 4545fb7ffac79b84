"""The RLlib backend's pool of frozen opponents and its replacement rule, kept on the driver.

The opponents are the learner's module states, saved as tensors in the run's ``selfplay/``
and played by the modules ``opponent_<generation>``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from foosball_gym.training.config import TrainConfig, stall_fallback
from foosball_gym.training.rllib.env_runner import opponent_id
from foosball_gym.training.run_dir.files import append_text
from foosball_gym.training.run_dir.tensors import load_tensors, save_tensors
from foosball_gym.training.selfplay.history import STALL_LOG, SnapshotHistory, snapshot_file
from foosball_gym.training.selfplay.rule import ReplacementRule, Stall


class OpponentPool:
    """The generations the learner plays, the latest ``config.selfplay_pool`` of its snapshots,
    and the rule that says when it has beaten them."""

    def __init__(self, config: TrainConfig, save_dir: Path) -> None:
        assert config.selfplay_threshold is not None  # config.check() sets the rule's default
        self.rule = ReplacementRule(
            config.selfplay_rule,
            config.selfplay_threshold,
            config.selfplay_window,
            config.selfplay_stall_games,
            stall_fallback(config),
        )
        self.pool_size = config.selfplay_pool
        self.save_dir = save_dir
        self.history = SnapshotHistory(save_dir, self.rule, self.pool_size)
        self.pool: list[int] = []  # generations
        self._stalls: list[Stall] = []

    @property
    def generation(self) -> int:
        return self.pool[-1] if self.pool else 0

    @property
    def games(self) -> int:
        return self.rule.games

    @property
    def module_ids(self) -> tuple[str, ...]:
        return tuple(opponent_id(g) for g in self.pool)

    def restore(self) -> dict[str, Any]:
        """The pool's weights by module id, from ``history.json`` and the snapshots."""
        self.pool = self.history.restore()
        return {opponent_id(g): load_tensors(snapshot_file(self.save_dir, g)) for g in self.pool}

    def add(self, state: Mapping[str, Any], timesteps: int, score: float | None, elo: float) -> int:
        """Record a snapshot of the learner's ``state``; returns its generation."""
        generation = self.generation + 1 if self.pool else 0
        self.save_dir.mkdir(parents=True, exist_ok=True)
        save_tensors(state, snapshot_file(self.save_dir, generation))
        self.pool = (self.pool + [generation])[-self.pool_size :]
        self.history.add(generation, timesteps, score, elo, self.pool)
        return generation

    def judge(self, games: list[int]) -> tuple[float, float] | None:
        """Count ``games``; the rule's score and the learner's rating where they earn a new
        snapshot, or None.

        The games after the one that earns it are dropped, not counted towards the next
        opponent: they were played against the pool as it was.
        """
        for result in games:
            replaced = self.rule.record(int(result))
            stall = self.rule.take_stall()
            if stall is not None:
                self._stalls.append(stall)
            if replaced is not None:
                return replaced
        return None

    def take_stalls(self, timesteps: int) -> list[str]:
        """The stalls the games judged since the last call found, each written to
        ``stalls.jsonl``: a line for the run's log each."""
        lines = []
        for stall in self._stalls:
            self.save_dir.mkdir(parents=True, exist_ok=True)
            record = stall.record(self.generation, timesteps)
            append_text(self.save_dir / STALL_LOG, json.dumps(record) + "\n")
            lines.append(stall.message(self.generation, timesteps))
        self._stalls.clear()
        return lines

    def rates(self) -> dict[str, float | None]:
        rates = self.rule.rates()
        return {"selfplay/generation": self.generation, **rates} if rates else {}
