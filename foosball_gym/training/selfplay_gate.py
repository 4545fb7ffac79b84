"""A gate on self-play's replacements: the learner's mean must beat its opponent's mean.

The replacement rule judges the games the learner trained in, where it explores (and its
opponents may too). What a league or ``foosball eval`` rates is the policy's mean, which can
play a different game: one run's generations rose in a league where they sampled their actions
(+0.52) and did not on their means (-0.20). A gate, as AlphaZero's evaluator, closes that gap:
when the rule grants a replacement, the learner's mean first plays ``games`` seeded games
against the newest opponent's mean and as many against the scripted side, and the replacement
stands only where it won more of the first than it lost, and scored at least one goal and no
fewer than it conceded against the scripted side. A refused replacement leaves the opponents
as they were; the rule's window starts anew either way.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass
from typing import Any

from foosball_gym.training.league import Player, _Arena, play_pair

# Gate games are served with seeds from here on, offset by the learner's step count, so that
# no two gates meet the same serves and none meets a league's (seeds 0 onwards).
GATE_SEED_BASE = 1_000_000


@dataclass
class GateVerdict:
    """What the learner's mean did at one gate, and whether its replacement stands."""

    timesteps: int
    games: int
    wins: int
    draws: int
    losses: int
    scripted_goals_for: int
    scripted_goals_against: int

    @property
    def passed(self) -> bool:
        return gate_passes(
            self.wins, self.losses, self.scripted_goals_for, self.scripted_goals_against
        )

    def record(self) -> dict[str, Any]:
        return {**asdict(self), "passed": self.passed}


def gate_passes(wins: int, losses: int, goals_for: int, goals_against: int) -> bool:
    """More wins than losses against the opponent, and against the scripted side at least one
    goal and no fewer goals than conceded (a keeper that never shoots has not learned)."""
    return wins > losses and goals_for >= 1 and goals_for >= goals_against


class ReplacementGate:
    """Plays the gate's games in one environment of the task the run trains on.

    Args:
        env_id, env_kwargs: the run's task.
        games: games against each of the newest opponent and the scripted side (at least 2;
            an even number gives both sides as many home games).
    """

    def __init__(self, env_id: str, env_kwargs: dict[str, Any] | None, games: int) -> None:
        if games < 2:
            raise ValueError(f"a gate needs at least 2 games, got {games}")
        self.env_id = env_id
        self.env_kwargs = dict(env_kwargs or {})
        self.games = int(games)
        self._arena: _Arena | None = None

    def judge(self, learner: Any, opponent: Any, timesteps: int) -> GateVerdict:
        """Play the learner against ``opponent`` and the scripted side, both on their means.

        ``learner`` and ``opponent`` are policy snapshots; copies of them act on the mean.
        """
        if self._arena is None:
            self._arena = _Arena(self.env_id, self.env_kwargs)
        me = Player("learner", _on_mean(learner))
        seed = GATE_SEED_BASE + int(timesteps)
        duel = play_pair(self._arena, me, Player("opponent", _on_mean(opponent)), self.games, seed)
        scripted = play_pair(self._arena, me, Player("scripted", None), self.games, seed)
        return GateVerdict(
            timesteps=int(timesteps),
            games=self.games,
            wins=duel.wins,
            draws=duel.draws,
            losses=duel.losses,
            scripted_goals_for=scripted.goals_a,
            scripted_goals_against=scripted.goals_b,
        )

    def close(self) -> None:
        if self._arena is not None:
            self._arena.close()
            self._arena = None


def _on_mean(snapshot: Any) -> Any:
    if getattr(snapshot, "deterministic", True):
        return snapshot
    mean = copy.copy(snapshot)
    mean.deterministic = True
    return mean
