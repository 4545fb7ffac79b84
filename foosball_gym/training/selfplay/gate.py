"""A gate on self-play's replacements: the learner's mean must earn them.

The replacement rule judges the games the learner trained in, where it explores (and its
opponents may too). What a league or ``foosball eval`` rates is the policy's mean, which can
play a different game: one run's generations rose in a league where they sampled their actions
(+0.52) and did not on their means (-0.20). A gate, as AlphaZero's evaluator, closes that gap.
When the rule grants a replacement, the means play ``games`` seeded games:

- the learner against the newest opponent, which it must not lose more of than it wins;
- the learner and the newest opponent each against the scripted side, on the same serves:
  the learner's goal difference there must be better than the opponent's (or equal, with
  more goals scored).

Between two sound keepers nearly every game is drawn (measured: 90-100 of 100), so the
head-to-head alone says little; the scripted side is the fixed yardstick that tells them
apart. Measuring both on the same fresh serves at every gate compares like with like, and a
generation's lucky gate is not the bar the next one has to clear. A refused replacement
leaves the opponents as they were; the rule's window starts anew either way.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass
from typing import Any

from foosball_gym.training.loading.loader import whole_action_options, whole_action_policy
from foosball_gym.training.selfplay.matches import Arena, Player, play_pair

# Gate games are served with seeds from here on, offset by the learner's step count, so that
# no two gates meet the same serves and none meets a league's (seeds 0 onwards).
GATE_SEED_BASE = 1_000_000


@dataclass
class GateVerdict:
    """What the means did at one gate, and whether the learner's replacement stands.

    ``wins``, ``draws``, ``losses``: the learner's against the newest opponent. ``goals_*``:
    the learner's against the scripted side; ``opponent_goals_*``: the newest opponent's
    against the scripted side, on the same serves.
    """

    timesteps: int
    games: int
    wins: int
    draws: int
    losses: int
    goals_for: int
    goals_against: int
    opponent_goals_for: int
    opponent_goals_against: int

    @property
    def passed(self) -> bool:
        return gate_passes(
            self.wins,
            self.losses,
            (self.goals_for, self.goals_against),
            (self.opponent_goals_for, self.opponent_goals_against),
        )

    def record(self) -> dict[str, Any]:
        return {**asdict(self), "passed": self.passed}


def gate_passes(
    wins: int, losses: int, learner: tuple[int, int], opponent: tuple[int, int]
) -> bool:
    """No more losses than wins against the opponent, and against the scripted side (goals
    for, goals against) a better goal difference than the opponent's, or an equal one with
    more goals scored."""
    mine = (learner[0] - learner[1], learner[0])
    theirs = (opponent[0] - opponent[1], opponent[0])
    return wins >= losses and mine > theirs


class ReplacementGate:
    """Plays the gate's games in one environment of the task the run trains on.

    Args:
        env_id, env_kwargs: the run's task.
        games: games in each of the three meetings (at least 2; an even number gives both
            sides as many home games).
    """

    def __init__(self, env_id: str, env_kwargs: dict[str, Any] | None, games: int) -> None:
        if games < 2:
            raise ValueError(f"a gate needs at least 2 games, got {games}")
        self.env_id = env_id
        self.env_kwargs = dict(env_kwargs or {})
        self.games = int(games)
        # A residual learner's snapshots play with their baseline, and a learner's with
        # slide_around_ball convert their slides, in games without the option.
        self._arena_kwargs = whole_action_options(self.env_kwargs)
        self._arena: Arena | None = None

    def judge(self, learner: Any, opponent: Any, timesteps: int) -> GateVerdict:
        """Play the learner against ``opponent``, and both against the scripted side.

        ``learner`` and ``opponent`` are policy snapshots; copies of them act on the mean.
        """
        if self._arena is None:
            self._arena = Arena(self.env_id, self._arena_kwargs)
        me = Player("learner", self._whole(_on_mean(learner)))
        them = Player("opponent", self._whole(_on_mean(opponent)))
        scripted = Player("scripted", None)
        seed = GATE_SEED_BASE + int(timesteps)
        duel = play_pair(self._arena, me, them, self.games, seed)
        mine = play_pair(self._arena, me, scripted, self.games, seed)
        theirs = play_pair(self._arena, them, scripted, self.games, seed)
        return GateVerdict(
            timesteps=int(timesteps),
            games=self.games,
            wins=duel.wins,
            draws=duel.draws,
            losses=duel.losses,
            goals_for=mine.goals_a,
            goals_against=mine.goals_b,
            opponent_goals_for=theirs.goals_a,
            opponent_goals_against=theirs.goals_b,
        )

    def _whole(self, snapshot: Any) -> Any:
        return whole_action_policy(snapshot, self.env_id, self.env_kwargs)[0]

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
