"""The league: a self-play run's generations, the scripted side and added models round-robin,
rated by Elo."""

from __future__ import annotations

import json

import numpy as np
import pytest

from foosball_gym.training.selfplay.league import (
    League,
    Player,
    pick_generations,
    rising,
    run_league,
    run_players,
)

pytest.importorskip("stable_baselines3")

from foosball_gym.cli import main  # noqa: E402

ENV = "Foosball-KeeperVsKeeper-v0"
# Games end once the ball lies still for a third of a second: a league of seconds.
QUICK = {"stagnation_steps": 20}


def still(obs):
    """A keeper that stays in the middle of its goal, upright."""
    return np.zeros(2, dtype=np.float32)


def test_a_league_plays_every_pair_on_the_same_serves_and_rates_them():
    players = [Player("scripted", None), Player("still", still), Player("still too", still)]
    league = run_league(players, ENV, QUICK, games=4, seed=5)
    assert [(p.a, p.b) for p in league.pairs] == [(0, 1), (0, 2), (1, 2)]
    assert all(p.wins + p.draws + p.losses == 4 for p in league.pairs)
    # The same serves for every pair: the two identical players score alike against the
    # scripted side, and against each other every game is the same from both sides.
    first, second, mirror = league.pairs
    assert (first.wins, first.draws, first.losses) == (second.wins, second.draws, second.losses)
    assert mirror.wins == mirror.losses
    assert league.ratings.anchor == "scripted" and league.ratings.elo[0] == 0
    assert league.ratings.elo[1] == pytest.approx(league.ratings.elo[2], abs=1e-6)
    again = run_league(players, ENV, QUICK, games=4, seed=5)
    assert again.to_dict()["pairs"] == league.to_dict()["pairs"]
    table = league.table()
    assert "Elo relative to scripted" in table and "still too" in table


def test_leagues_refuse_one_player_twins_and_one_player_tasks():
    with pytest.raises(ValueError, match="at least two players"):
        run_league([Player("scripted", None)], ENV, QUICK)
    with pytest.raises(ValueError, match="different names"):
        run_league([Player("a", still), Player("a", still)], ENV, QUICK)
    with pytest.raises(ValueError, match="two-player task"):
        run_league([Player("a", still), Player("b", still)], "Foosball-Block-v0")


def test_generations_are_spread_with_the_first_and_last_kept():
    assert pick_generations(range(20), 5) == [0, 5, 10, 14, 19]
    assert pick_generations([3, 1, 2], 8) == [1, 2, 3]


def test_foosball_league_rates_a_self_play_run(tmp_path, capsys):
    run = tmp_path / "run"
    argv = ["train", ENV, "--timesteps", "2048", "--n-envs", "2", "--n-steps", "256"]
    argv += ["--batch-size", "128", "--eval-freq", "100000", "--eval-episodes", "1"]
    argv += ["--env-kwarg", "stagnation_steps=20", "--selfplay-window", "2"]
    argv += ["--selfplay-rule", "net_score", "--selfplay-threshold", "-1"]
    argv += ["--out", str(run), "--no-progress", "--seed", "3"]
    assert main(argv) == 0
    history = json.loads((run / "selfplay" / "history.json").read_text())
    assert len(history) >= 3 and all("elo" in h for h in history)
    capsys.readouterr()

    argv = ["league", str(run), "--games", "2", "--generations", "3", "--add", str(run)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "rank correlation of rating with training steps" in out
    report = json.loads((run / "league.json").read_text())
    names = [p["name"] for p in report["players"]]
    # Three generations spread over the run, its final policy, the added model, the scripted.
    assert len(names) == 6 and names[0] == "gen 0" and names[3:] == ["final", str(run), "scripted"]
    assert report["env_kwargs"]["stagnation_steps"] == 20
    assert len(report["pairs"]) == 15
    assert (run / "league.png").stat().st_size > 0

    # Rated as the stochastic policies a run with sampled opponents played: each player
    # samples, and the seed makes the league repeatable.
    players, _ = run_players(run, 2, sampled=True)
    obs = np.zeros((1, 10), dtype=np.float32)
    for player in players:
        actions = np.array([np.asarray(player.policy(obs)).ravel() for _ in range(5)])
        assert np.ptp(actions, axis=0).max() > 0, player.name
    mean_only, _ = run_players(run, 2)
    assert np.ptp([mean_only[0].policy(obs) for _ in range(5)], axis=0).max() == 0
    sampled = []
    for _ in range(2):
        argv = ["league", str(run), "--games", "2", "--generations", "2", "--sampled"]
        assert main([*argv, "--seed", "1", "--out", str(tmp_path)]) == 0
        sampled.append(json.loads((tmp_path / "league.json").read_text())["pairs"])
    assert sampled[0] == sampled[1]


def test_foosball_league_needs_a_self_play_run(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["league", str(tmp_path)])
    assert exit_info.value.code == 2
    assert "is not a run directory" in capsys.readouterr().err
    (tmp_path / "config.json").write_text(json.dumps({"env_id": "Foosball-Block-v0"}))
    with pytest.raises(SystemExit):
        main(["league", str(tmp_path)])
    assert "needs a run trained with self-play" in capsys.readouterr().err


def test_rank_correlation_of_ratings_with_steps():
    from foosball_gym.ratings import Ratings

    players = [Player(f"gen {g}", still, g, 100 * g) for g in range(4)] + [Player("x", still)]
    elo = np.array([0.0, 10.0, 30.0, 20.0, 99.0])
    league = League(players, ENV, {}, 1, 0)
    league.ratings = Ratings([p.name for p in players], elo, elo, elo, "gen 0")
    assert rising(league) == pytest.approx(0.8)
