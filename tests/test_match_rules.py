"""The rules of the two games: a dead ball out of every figurine's reach, first to N, the
match's length."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import table

STILL_FULL = np.zeros(8, dtype=np.float32)
STILL_KEEPER = np.zeros(2, dtype=np.float32)
UP = np.array([0.0, -0.25], dtype=np.float32)  # the keeper's feet up: a ball passes under


def steps_until_dead(env: gym.Env, action: np.ndarray, ball: tuple[float, float]) -> int:
    env.reset(seed=0, options={"ball_position": ball, "ball_velocity": (0.0, 0.0)})
    for step in range(1, 200):
        _, reward, terminated, truncated, info = env.step(action)
        if info["stagnated"]:
            assert reward == 0.0 and not info["goal"]
            return step
    raise AssertionError("the ball never died")


def test_a_foot_reaches_a_resting_ball_just_over_six_centimetres_out():
    offense = table.rod("home_offense")
    # Measured: a full swing moves a resting ball 0.06 m in front of the rod, not 0.065.
    assert 0.06 < table.FOOT_REACH_X < 0.065
    assert table.within_reach(offense, offense.x + 0.06, 0.0)
    assert not table.within_reach(offense, offense.x + 0.065, 0.0)
    # The outer figurine reaches a ball against the side wall; the keeper not the corners.
    assert table.within_reach(offense, offense.x + 0.03, table.BALL_LIMIT_Y)
    keeper = table.rod("away_keeper")
    assert table.within_reach(keeper, keeper.x, 0.15)
    assert not table.within_reach(keeper, keeper.x, 0.2)


def test_a_ball_at_rest_out_of_every_reach_is_dead_sooner_than_one_in_reach():
    env = gym.make("Foosball-FullGame-v0", opponent="scripted:0")
    try:
        # Between the home offense and the away defense: out of both rods' reach.
        gap = (table.rod("home_offense").x + table.rod("away_defense").x) / 2
        assert steps_until_dead(env, STILL_FULL, (gap, 0.05)) == 30
        # In front of a still figurine: still for stagnation_steps, a draw all the same.
        assert steps_until_dead(env, STILL_FULL, (table.rod("home_offense").x + 0.04, 0.0)) == 60
    finally:
        env.close()
    env = gym.make("Foosball-FullGame-v0", opponent="scripted:0", dead_ball_steps=0)
    try:
        assert steps_until_dead(env, STILL_FULL, (gap, 0.05)) == 60
    finally:
        env.close()


def test_a_dead_ball_in_a_match_is_served_again():
    env = gym.make("Foosball-KeeperVsKeeper-v0", continuous=True, opponent="scripted:0")
    try:
        env.reset(seed=0, options={"ball_position": (0.0, 0.1), "ball_velocity": (0.0, 0.0)})
        for step in range(1, 40):  # noqa: B007  (the step that ended it is checked)
            obs, _, terminated, truncated, info = env.step(STILL_KEEPER)
            assert not (terminated or truncated)
            if info["stagnated"]:
                break
        assert step == 30
        # Served again: at rest in front of a keeper.
        assert abs(abs(obs[-4]) - 0.497) < 0.01
    finally:
        env.close()


def score_on(env: gym.Env, x: float) -> dict:
    """Put a fast ball on its way into the goal at ``x``'s end and play until it is in."""
    env.unwrapped.game.sim.place_ball((x, 0.07), (3.0 if x > 0 else -3.0, 0.0))
    for _ in range(40):
        _, reward, terminated, truncated, info = env.step(UP)
        if info["goal"]:
            return {"terminated": terminated, "truncated": truncated, "reward": reward, **info}
    raise AssertionError("no goal")


def test_a_first_to_n_match_ends_when_a_side_has_its_goals():
    env = gym.make("Foosball-KeeperVsKeeper-v0", continuous=True, first_to=2, opponent=lambda o: UP)
    try:
        env.reset(seed=0)
        first = score_on(env, 0.45)
        assert not first["terminated"] and first["goals_for"] == 1
        against = score_on(env, -0.45)
        assert not against["terminated"] and against["goals_against"] == 1
        last = score_on(env, 0.45)
        assert last["terminated"] and not last["truncated"] and last["is_success"]
        assert (last["goals_for"], last["goals_against"], last["reward"]) == (2, 1, 1000.0)
    finally:
        env.close()


def test_a_match_lasts_its_match_seconds():
    env = gym.make("Foosball-KeeperVsKeeper-v0", continuous=True, match_seconds=0.5)
    try:
        env.reset(seed=0)
        for step in range(1, 100):  # noqa: B007
            _, _, terminated, truncated, _ = env.step(STILL_KEEPER)
            if terminated or truncated:
                break
        assert truncated and not terminated and step == 30
    finally:
        env.close()


def test_a_match_longer_than_the_registered_limit_plays_with_the_limit_raised():
    env = gym.make(
        "Foosball-KeeperVsKeeper-v0", continuous=True, match_seconds=40, max_episode_steps=2500
    )
    try:
        env.reset(seed=0)
        for step in range(1, 2501):  # noqa: B007
            _, _, terminated, truncated, _ = env.step(STILL_KEEPER)
            if terminated or truncated:
                break
        assert truncated and step == 2400
    finally:
        env.close()


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"first_to": 3}, "needs continuous=True"),
        ({"match_seconds": 30}, "needs continuous=True"),
        ({"continuous": True, "first_to": -1}, "first_to must be a whole number"),
        ({"continuous": True, "first_to": 1.5}, "first_to must be a whole number"),
        ({"continuous": True, "match_seconds": 0}, "match_seconds must be a number"),
        ({"continuous": True, "match_seconds": "long"}, "match_seconds must be a number"),
        ({"dead_ball_steps": -5}, "dead_ball_steps must be a whole number"),
    ],
)
def test_bad_match_rules_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        gym.make("Foosball-FullGame-v0", **kwargs)


def test_the_two_player_game_keeps_the_match_rules():
    pytest.importorskip("pettingzoo")
    from foosball_gym.multiagent import parallel_env

    game = parallel_env("Foosball-KeeperVsKeeper-v0", continuous=True, match_seconds=0.25)
    try:
        game.reset(seed=0)
        actions = {agent: STILL_KEEPER for agent in game.agents}
        for step in range(1, 40):  # noqa: B007
            _, _, terminations, truncations, _ = game.step(actions)
            if truncations["home"] or terminations["home"]:
                break
        assert truncations["home"] and step == 15
    finally:
        game.close()
    with pytest.raises(ValueError, match="max_cycles=3000 or more"):
        parallel_env("Foosball-KeeperVsKeeper-v0", continuous=True, match_seconds=50)


def test_evaluation_counts_the_serves_of_a_match_and_the_balls_off_the_table():
    from foosball_gym.evaluation import evaluate

    # Two still keepers: the ball served at rest in front of one lies still for a second, dead,
    # and is served again; the match's two seconds end as the second ball dies.
    result = evaluate(
        lambda obs: STILL_KEEPER,
        "Foosball-KeeperVsKeeper-v0",
        {"continuous": True, "match_seconds": 2},
        episodes=1,
        opponent="scripted:0",
        opponent_name="scripted:0",
    )
    assert (result.serves, result.off_table) == (2, 0)
    assert "serves               2" in result.table()
    assert "off the table        0 (0.0 % of serves)" in result.table()
    assert result.to_dict()["serves"] == 2


def test_the_default_serve_share_serves_as_before_seed_for_seed():
    default = gym.make("Foosball-KeeperVsKeeper-v0")
    even = gym.make("Foosball-KeeperVsKeeper-v0", home_serve_share=0.5)
    try:
        starts = [(default.reset(seed=s)[0], even.reset(seed=s)[0]) for s in range(10)]
    finally:
        default.close()
        even.close()
    assert all(np.array_equal(a, b) for a, b in starts)
    assert len({bool(a[-4] < 0) for a, _ in starts}) == 2  # both sides served


@pytest.mark.parametrize("share, side", [(0.0, 1.0), (1.0, -1.0)])
def test_a_match_serves_as_the_share_says(share, side):
    env = gym.make(
        "Foosball-KeeperVsKeeper-v0", continuous=True, opponent="scripted:0", home_serve_share=share
    )
    try:
        first, _ = env.reset(seed=0)
        env.reset(seed=0, options={"ball_position": (0.0, 0.1), "ball_velocity": (0.0, 0.0)})
        for _ in range(40):
            obs, _, _, _, info = env.step(STILL_KEEPER)
            if info["stagnated"]:
                break
    finally:
        env.close()
    # The ball's x, the observation's fourth entry from the end, on the first serve and on the
    # one after a dead ball: in front of the away keeper (x > 0) or the learner's (x < 0).
    assert first[-4] * side > 0.4 and obs[-4] * side > 0.4


@pytest.mark.parametrize("share", [-0.1, 1.5, "half"])
def test_a_bad_serve_share_is_refused(share):
    with pytest.raises(ValueError, match=r"home_serve_share must be a number in \[0, 1\]"):
        gym.make("Foosball-KeeperVsKeeper-v0", home_serve_share=share)
