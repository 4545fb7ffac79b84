"""When self-play replaces its opponent (the paper's rule, docs/self-play.md), and the learner's
rating while it trains.

Shared by the Stable-Baselines3 callback and the RLlib backend, so both follow one rule.
Needs neither PyTorch nor either learning library.

The paper's rule is the default: a snapshot of the learner becomes the opponent once it wins
at least ``threshold`` (20 %) of the last ``window`` games. The older net-score rule,
(wins - losses) / games above ``threshold``, is kept as an option; it cannot fire when most
games are drawn, which is what two good keepers mostly play. The ``winning`` rule asks for
both a win rate of ``threshold`` and more wins than losses: under the paper's rule alone a
learner that loses as often as it wins still replaces its opponent, and generations churn
without getting stronger (measured: 47 generations within about 70 Elo of the first).
The ``significant`` rule asks that the learner beats its opponents beyond chance: among the
window's decisive games its wins must be more than a fair coin gives at the one-sided level
``threshold`` (a sign test). It judges the window once, when full, and then starts it anew
whatever the verdict, so that the level holds for each verdict; a sliding window judged after
every game would replace on chance far more often than the level says.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

SELFPLAY_RULES = ("win_rate", "net_score", "winning", "significant")


def default_threshold(rule: str) -> float:
    """The threshold a rule takes when none is given: a test level for ``significant``."""
    if rule not in SELFPLAY_RULES:
        raise ValueError(f"unknown self-play rule {rule!r}; allowed: {', '.join(SELFPLAY_RULES)}")
    return 0.05 if rule == "significant" else 0.2


def check_rule(rule: str, threshold: float) -> None:
    """Raise ValueError for an unknown rule or a threshold the rule can never meet sensibly."""
    if rule not in SELFPLAY_RULES:
        raise ValueError(f"unknown self-play rule {rule!r}; allowed: {', '.join(SELFPLAY_RULES)}")
    # Written `not a < x <= b`, so that NaN fails too.
    if rule in ("win_rate", "winning") and not 0 < threshold <= 1:
        raise ValueError(f"the {rule} rule's threshold must lie in (0, 1], got {threshold}")
    if rule == "net_score" and not -1 <= threshold < 1:
        raise ValueError(f"the net_score rule's threshold must lie in [-1, 1), got {threshold}")
    if rule == "significant" and not 0 < threshold < 0.5:
        raise ValueError(
            f"the significant rule's threshold is a test level and must lie in (0, 0.5), "
            f"got {threshold}"
        )


def game_result(info: Mapping[str, Any]) -> int:
    """+1 won, -1 lost, 0 drawn, from the info of a game's last step (of the learner's side)."""
    return int(np.sign(info.get("goals_for", 0) - info.get("goals_against", 0)))


def sign_test(wins: int, losses: int) -> float:
    """The one-sided p-value of ``wins`` or more wins in ``wins + losses`` fair coin tosses."""
    n = wins + losses
    if n == 0:
        return 1.0
    return sum(math.comb(n, k) for k in range(wins, n + 1)) / 2.0**n


def performance_elo(results: np.ndarray, opponent_elo: float) -> float:
    """The Elo rating that expects the score the learner made against ``opponent_elo``.

    A win scores 1, a draw 1/2; all wins or all losses are taken as half a game short of it,
    so the rating stays finite (at most 400·log10(2n - 1) from the opponent's).
    """
    n = len(results)
    score = float(np.sum(np.asarray(results) + 1) / 2)
    score = min(max(score, 0.5), n - 0.5) / n
    return opponent_elo + 400.0 * math.log10(score / (1.0 - score))


@dataclass(frozen=True)
class Stall:
    """Self-play that went ``since`` games without replacing its opponent: what the last
    window of games was, and the rule that judges from now on."""

    games: int
    since: int
    win_rate: float
    draw_rate: float
    loss_rate: float
    rule: str
    threshold: float
    fallback: str | None
    fallback_threshold: float | None

    def message(self, generation: int, timesteps: int) -> str:
        """One line for the run's log."""
        then = (
            f"judging by the {self.fallback} rule ({self.fallback_threshold:g}) from now on"
            if self.fallback
            else "the rule stays"
        )
        return (
            f"self-play stalled at {timesteps:,} steps: no new opponent in {self.since:,} games "
            f"against generation {generation} (the last window won {self.win_rate:.0%}, drawn "
            f"{self.draw_rate:.0%}, lost {self.loss_rate:.0%}; the {self.rule} rule asks "
            f"{_asks(self.rule, self.threshold)}); {then}"
        )

    def record(self, generation: int, timesteps: int) -> dict[str, Any]:
        """A line of the run's ``selfplay/stalls.jsonl``."""
        return {"generation": generation, "timesteps": int(timesteps), **asdict(self)}


def _asks(rule: str, threshold: float) -> str:
    if rule == "win_rate":
        return f"a win rate of {threshold:.0%}"
    if rule == "winning":
        return f"a win rate of {threshold:.0%} and more wins than losses"
    if rule == "significant":
        return f"more wins than losses among decisive games, at the {threshold:g} level"
    return f"a net score above {threshold:+.2f}"


class ReplacementRule:
    """Counts finished games (+1 won, 0 drawn, -1 lost) and says when the opponent is beaten.

    Args:
        rule: ``"win_rate"`` (wins / games at least ``threshold``), ``"net_score"``
            ((wins - losses) / games above ``threshold``), ``"winning"`` (wins / games at
            least ``threshold`` and more wins than losses) or ``"significant"`` (the wins
            among decisive games pass a one-sided sign test at level ``threshold``).
        threshold: see ``rule``.
        window: the last this many games are judged; none is judged before the window is full.
        stall_games: after this many games without a replacement self-play has stalled:
            :meth:`take_stall` says so once, and the ``fallback`` rule, with its default
            threshold, judges from then on (0: never). The paper's rule cannot fire against an
            opponent that draws nearly every game, and would leave the learner against its
            first copy for good.
        fallback: the rule a stall switches to; None keeps the rule.

    The learner's Elo rating is its performance over the window against its opponents, whose
    ratings are the learner's at the moment each was frozen (generation 0 rates 0); set
    ``opponent_elo`` whenever the opponents change. With a pool of several opponents it is
    their mean rating.
    """

    def __init__(
        self,
        rule: str = "win_rate",
        threshold: float = 0.2,
        window: int = 100,
        stall_games: int = 0,
        fallback: str | None = None,
    ) -> None:
        check_rule(rule, threshold)
        if window < 1:
            raise ValueError(f"window must be at least 1 game, got {window}")
        if stall_games < 0:
            raise ValueError(f"stall_games must be 0 (never) or more, got {stall_games}")
        if fallback is not None:
            default_threshold(fallback)  # raises for an unknown rule
        self.rule = rule
        self.threshold = float(threshold)
        self.window = int(window)
        self.stall_games = int(stall_games)
        self.fallback = fallback
        self.results: deque[int] = deque(maxlen=self.window)
        self.games = 0
        self.opponent_elo = 0.0
        # The count of games when the opponent last changed (or judging began).
        self.replaced_at = 0
        self._stall: Stall | None = None
        self._stall_reported = False

    def score(self) -> float:
        """The rule's measure over the games in the window."""
        res = np.array(self.results)
        if self.rule in ("win_rate", "winning"):
            return float((res > 0).mean())
        if self.rule == "significant":
            return sign_test(int((res > 0).sum()), int((res < 0).sum()))
        return float(res.mean())

    def elo(self) -> float | None:
        """The learner's rating over the window (None before its first game)."""
        if not self.results:
            return None
        return performance_elo(np.array(self.results), self.opponent_elo)

    def record(self, result: int) -> tuple[float, float] | None:
        """Count one game; where it earns a new opponent, the rule's score and the learner's
        rating, else None.

        The window starts empty again after a replacement: the games before it were played
        against the old opponent. Under the ``significant`` rule it also starts anew after a
        verdict against replacing (the score is then the test's p-value).
        """
        self.results.append(int(result))
        self.games += 1
        if (
            self.stall_games
            and not self._stall_reported
            and self.games - self.replaced_at >= self.stall_games
        ):
            self._stalled()
        if len(self.results) < self.window:
            return None
        score = self.score()
        if self.rule == "win_rate":
            due = score >= self.threshold
        elif self.rule == "winning":
            due = score >= self.threshold and sum(self.results) > 0
        elif self.rule == "significant":
            due = score < self.threshold
            if not due:
                self.results.clear()
        else:
            due = score > self.threshold
        if not due:
            return None
        elo = self.elo()
        assert elo is not None  # the window is full
        self.results.clear()
        self.replaced_at = self.games
        self._stall_reported = False
        return score, elo

    def take_stall(self) -> Stall | None:
        """The stall the last game found, once; None where it found none."""
        stall, self._stall = self._stall, None
        return stall

    def fall_back(self) -> bool:
        """Judge by the fallback rule from now on; whether the rule changed."""
        if self.fallback is None or self.fallback == self.rule:
            return False
        self.rule, self.threshold = self.fallback, default_threshold(self.fallback)
        return True

    def _stalled(self) -> None:
        res = np.array(self.results)
        rule, threshold = self.rule, self.threshold
        changed = self.fall_back()
        self._stall = Stall(
            games=self.games,
            since=self.games - self.replaced_at,
            win_rate=float((res > 0).mean()),
            draw_rate=float((res == 0).mean()),
            loss_rate=float((res < 0).mean()),
            rule=rule,
            threshold=threshold,
            fallback=self.rule if changed else None,
            fallback_threshold=self.threshold if changed else None,
        )
        self._stall_reported = True
        if changed and self.rule == "significant":
            # Its verdicts are on whole windows of games judged afresh.
            self.results.clear()

    def rates(self) -> dict[str, float]:
        """What TensorBoard shows: the window's rates and the learner's rating."""
        if not self.results:
            return {}
        res = np.array(self.results)
        return {
            "selfplay/win_rate": float((res > 0).mean()),
            "selfplay/loss_rate": float((res < 0).mean()),
            "selfplay/draw_rate": float((res == 0).mean()),
            "selfplay/net_score": float(res.mean()),
            "selfplay/games": self.games,
            "selfplay/elo": performance_elo(res, self.opponent_elo),
        }
