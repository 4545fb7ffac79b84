"""The self-play replacement rule (the paper's rule, docs/self-play.md) and the learner's
rating, without a learner."""

from __future__ import annotations

import math
import re

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym.training.selfplay.history import restored_elo
from foosball_gym.training.selfplay.rule import (
    ReplacementRule,
    performance_elo,
    sign_test,
)

WIN, DRAW, LOSS = 1, 0, -1


def play(rule, results):
    """Feed games; the replacements they earned, as (game number, score, elo)."""
    fired = []
    for i, result in enumerate(results, 1):
        replaced = rule.record(result)
        if replaced is not None:
            fired.append((i, *replaced))
    return fired


def test_the_papers_rule_fires_on_a_fifth_of_wins_among_draws():
    # 20 wins and 80 draws: what two keepers that mostly stop everything play.
    games = [WIN] * 20 + [DRAW] * 80
    fired = play(ReplacementRule("win_rate", 0.2, window=100), games)
    assert [(n, score) for n, score, _ in fired] == [(100, 0.2)]
    # The net score of the same games is 0.2, not above it: the old rule never fires.
    assert play(ReplacementRule("net_score", 0.2, window=100), games) == []


def test_below_the_threshold_nothing_fires_and_the_window_must_be_full():
    assert play(ReplacementRule("win_rate", 0.2, window=100), [WIN] * 19 + [DRAW] * 81) == []
    assert play(ReplacementRule("win_rate", 0.2, window=100), [WIN] * 99) == []


def test_the_window_starts_over_after_a_replacement():
    rule = ReplacementRule("win_rate", 0.5, window=4)
    fired = play(rule, [WIN] * 4 + [LOSS] * 2 + [WIN] * 2 + [WIN] * 4)
    # Game 8 judges games 5-8 (two losses, two wins), not 1-4 again.
    assert [n for n, *_ in fired] == [4, 8, 12]
    assert rule.games == 12


def test_net_score_rule_counts_losses_against_wins():
    games = [WIN] * 50 + [LOSS] * 25 + [DRAW] * 25
    fired = play(ReplacementRule("net_score", 0.2, window=100), games)
    assert [(n, score) for n, score, _ in fired] == [(100, 0.25)]


def test_winning_rule_asks_for_the_win_rate_and_a_lead():
    # 30 % wins but as many losses: the paper's rule replaces, the winning rule waits.
    level = [WIN] * 30 + [LOSS] * 30 + [DRAW] * 40
    assert [n for n, *_ in play(ReplacementRule("win_rate", 0.2, window=100), level)] == [100]
    assert play(ReplacementRule("winning", 0.2, window=100), level) == []
    ahead = [WIN] * 25 + [LOSS] * 24 + [DRAW] * 51
    fired = play(ReplacementRule("winning", 0.2, window=100), ahead)
    assert [(n, score) for n, score, _ in fired] == [(100, 0.25)]
    # A lead without the win rate is not enough either.
    assert play(ReplacementRule("winning", 0.2, window=100), [WIN] * 10 + [DRAW] * 90) == []


def test_sign_test_is_the_binomial_tail():
    # 9 or more heads in 10 fair tosses: (10 + 1) / 1024.
    assert sign_test(9, 1) == pytest.approx(11 / 1024)
    assert sign_test(0, 0) == 1.0 and sign_test(0, 5) == 1.0
    assert sign_test(5, 5) > 0.5


def test_significant_rule_replaces_only_beyond_chance():
    # 14 of 20 decisive games among draws: p = 0.058, not below 0.05.
    level = [WIN] * 14 + [LOSS] * 6 + [DRAW] * 20
    assert play(ReplacementRule("significant", 0.05, window=40), level) == []
    ahead = [WIN] * 15 + [LOSS] * 5 + [DRAW] * 20
    fired = play(ReplacementRule("significant", 0.05, window=40), ahead)
    assert [n for n, *_ in fired] == [40]
    assert fired[0][1] == pytest.approx(sign_test(15, 5))
    # The paper's rule would replace on the level games, where chance explains the lead.
    assert [n for n, *_ in play(ReplacementRule("win_rate", 0.2, window=40), level)] == [40]


def test_significant_rule_judges_each_window_once():
    # A verdict against replacing empties the window: game 80 judges games 41-80 alone, and
    # no game in between is judged on a window that still holds the first block.
    rule = ReplacementRule("significant", 0.05, window=40)
    games = [LOSS] * 20 + [DRAW] * 20 + [WIN] * 16 + [LOSS] * 4 + [DRAW] * 20
    fired = play(rule, games)
    assert [n for n, *_ in fired] == [80]
    assert rule.rates() == {}


def test_under_equal_play_the_significant_rule_replaces_at_about_its_level():
    rng = np.random.default_rng(0)
    games = rng.choice([WIN, DRAW, LOSS], size=40 * 500).tolist()
    fired = play(ReplacementRule("significant", 0.05, window=40), games)
    # A sign test on ~27 decisive games is conservative: at most 5 % of 500 verdicts.
    assert len(fired) <= 0.05 * 500


@pytest.mark.parametrize(
    "rule, threshold",
    [
        ("win_rate", 0.0),
        ("winning", 0.0),
        ("win_rate", 1.5),
        ("win_rate", math.nan),
        ("net_score", 1.0),
        ("significant", 0.5),
        ("significant", 0.0),
        ("elo", 0.2),
    ],
)
def test_bad_rules_and_thresholds_are_refused(rule, threshold):
    with pytest.raises(ValueError, match="allowed|must lie"):
        ReplacementRule(rule, threshold)


def test_performance_rating_is_elos_expected_score():
    # Scoring 3 of 4 (75 %) is expected of a player 191 Elo above its opponent.
    results = np.array([WIN, WIN, DRAW, DRAW])
    elo = performance_elo(results, 100.0)
    assert elo == pytest.approx(100.0 + 400 * math.log10(3), abs=1e-9)
    expected = 1 / (1 + 10 ** ((100.0 - elo) / 400))
    assert expected == pytest.approx(0.75)
    # All draws: level with the opponent; all wins: finite.
    assert performance_elo(np.zeros(10), 50.0) == pytest.approx(50.0)
    assert math.isfinite(performance_elo(np.ones(10), 0.0))


def test_ratings_rise_as_each_generation_beats_the_last():
    rule = ReplacementRule("win_rate", 0.2, window=10)
    history = [{"generation": 0, "elo": 0.0}]
    for generation in range(1, 4):
        ((_, _, elo),) = play(rule, [WIN] * 3 + [DRAW] * 7)
        history.append({"generation": generation, "elo": elo})
        rule.opponent_elo = restored_elo(history, [generation])
    elos = [h["elo"] for h in history]
    assert all(b > a for a, b in zip(elos, elos[1:]))
    assert rule.rates() == {}  # the window starts empty after a replacement


def test_self_play_trains_without_the_still_ball_draw_unless_asked():
    from foosball_gym.training.config import TrainConfig

    config = TrainConfig("Foosball-KeeperVsKeeper-v0")
    config.check()
    assert config.self_play and config.env_kwargs["stagnation_steps"] == 0
    asked = TrainConfig("Foosball-KeeperVsKeeper-v0", env_kwargs={"stagnation_steps": 60})
    asked.check()
    assert asked.env_kwargs["stagnation_steps"] == 60
    scripted = TrainConfig("Foosball-KeeperVsKeeper-v0", self_play=False)
    scripted.check()
    assert "stagnation_steps" not in scripted.env_kwargs
    # A continuous match serves a still ball again: the rule that does so stays.
    match = TrainConfig("Foosball-KeeperVsKeeper-v0", env_kwargs={"continuous": True})
    match.check()
    assert "stagnation_steps" not in match.env_kwargs
    assert gym.make(match.env_id, **match.env_kwargs).unwrapped.game.stagnation_steps == 60


def test_each_rule_takes_its_own_default_threshold():
    from foosball_gym.training.config import TrainConfig

    for rule, threshold in (("win_rate", 0.2), ("winning", 0.2), ("significant", 0.05)):
        config = TrainConfig("Foosball-KeeperVsKeeper-v0", selfplay_rule=rule)
        config.check()
        assert config.selfplay_threshold == threshold
    with pytest.raises(ValueError, match="test level"):
        TrainConfig(
            "Foosball-KeeperVsKeeper-v0", selfplay_rule="significant", selfplay_threshold=0.6
        ).check()


def test_a_run_from_before_the_rule_was_an_option_keeps_the_net_score(tmp_path):
    import json

    from foosball_gym.training.config import TrainConfig

    path = tmp_path / "config.json"
    path.write_text(json.dumps({"env_id": "Foosball-KeeperVsKeeper-v0", "self_play": True}))
    assert TrainConfig.load(path).selfplay_rule == "net_score"
    new = TrainConfig("Foosball-KeeperVsKeeper-v0")
    new.check()
    new.save(path)
    assert TrainConfig.load(path).selfplay_rule == "win_rate"


def test_a_rule_that_cannot_fire_against_a_drawing_opponent_stalls_and_falls_back():
    from foosball_gym.training.selfplay.rule import ReplacementRule

    # The learner against its first copy: 6 wins, 85 draws, 9 losses in every 100 games.
    games = [1] * 6 + [0] * 85 + [-1] * 9
    rule = ReplacementRule("win_rate", 0.2, 100, stall_games=300, fallback="significant")
    for result in games * 3:
        assert rule.record(result) is None
        stall = rule.take_stall()
        if stall:
            found = stall
    assert found.games == found.since == 300 and found.rule == "win_rate"
    assert (found.win_rate, found.draw_rate, found.loss_rate) == (0.06, 0.85, 0.09)
    assert found.fallback == "significant" and found.fallback_threshold == 0.05
    assert rule.rule == "significant" and rule.take_stall() is None
    # Once the learner wins clearly more of the decisive games, an opponent is earned ...
    replaced = [rule.record(r) for r in [1] * 12 + [0] * 86 + [-1] * 2]
    assert replaced[-1] is not None and rule.replaced_at == 400
    # ... and a stall against the new opponent is told again, the rule staying.
    for result in games * 3:
        rule.record(result)
    again = rule.take_stall()
    assert again is not None and again.fallback is None and rule.rule == "significant"


def test_without_a_stall_limit_a_rule_never_stalls():
    from foosball_gym.training.selfplay.rule import ReplacementRule

    rule = ReplacementRule("win_rate", 0.2, 10)
    for _ in range(10_000):
        rule.record(0)
        assert rule.take_stall() is None
    assert rule.rule == "win_rate"


def test_a_resumed_run_judges_by_the_rule_its_stall_switched_to(tmp_path):
    from foosball_gym.training.selfplay.history import SnapshotHistory
    from foosball_gym.training.selfplay.rule import ReplacementRule

    first = ReplacementRule("win_rate", 0.2, 10, stall_games=20, fallback="significant")
    history = SnapshotHistory(tmp_path, first, 1)
    history.add(0, 0, None, 0.0, [0])
    for _ in range(20):
        first.record(0)
    assert first.take_stall() is not None and first.rule == "significant"
    history.add(1, 5000, 0.01, 50.0, [1])  # a replacement under the fallback rule
    resumed = ReplacementRule("win_rate", 0.2, 10, stall_games=20, fallback="significant")
    SnapshotHistory(tmp_path, resumed, 1).restore()
    assert (resumed.rule, resumed.threshold) == ("significant", 0.05)
    assert resumed.games == resumed.replaced_at == 20


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"selfplay_stall_fallback": "ladder"}, "unknown selfplay_stall_fallback 'ladder'"),
        ({"selfplay_stall_games": 50}, "at least a window of games (100), got 50"),
    ],
)
def test_bad_stall_settings_are_refused(settings, message):
    from foosball_gym.training.config import TrainConfig

    with pytest.raises(ValueError, match=re.escape(message)):
        TrainConfig("Foosball-KeeperVsKeeper-v0", **settings).check()
