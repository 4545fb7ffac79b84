"""The scripted ladders of the two games: every level exists, is named ``scripted:N`` wherever a
policy or an opponent is, plain ``scripted`` is the top, bad levels are refused, and the top
scores."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import table
from foosball_gym.cli import main
from foosball_gym.policies.attack import AttackingTeam
from foosball_gym.policies.ladder import (
    FULL_GAME_LADDER,
    KEEPER_LADDER,
    StandStill,
    describe,
    parse_scripted,
)
from foosball_gym.policies.scripted import (
    KICK_ANGLE,
    WIND_UP_ANGLE,
    ScriptedTeam,
    slide_for,
)
from foosball_gym.registration import scripted_policy

LADDERS = {"Foosball-FullGame-v0": FULL_GAME_LADDER, "Foosball-KeeperVsKeeper-v0": KEEPER_LADDER}


def play(env: gym.Env, policy, seed: int) -> dict:
    obs, info = env.reset(seed=seed)
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(policy(obs))
        done = terminated or truncated
    return info


@pytest.mark.parametrize("env_id", list(LADDERS))
def test_every_level_plays_from_standing_still_to_the_attacking_top(env_id):
    ladder = LADDERS[env_id]
    assert ladder[0].name == "still" and ladder[-1].name == "attacking"
    # The scripted team before the ladder is kept on it as a level.
    assert "kicking" in [level.name for level in ladder]
    env = gym.make(env_id)
    obs, _ = env.reset(seed=0)
    try:
        for n in range(len(ladder)):
            policy = scripted_policy(env_id, level=n)
            action = np.asarray(policy(obs))
            assert env.action_space.contains(action.astype(np.float32)), (n, action)
        assert isinstance(scripted_policy(env_id, level=0), StandStill)
        assert type(scripted_policy(env_id, level=1)) is ScriptedTeam
        assert isinstance(scripted_policy(env_id), AttackingTeam)
    finally:
        env.close()
    assert describe(ladder).splitlines()[0].startswith("scripted:0  still")


@pytest.mark.parametrize("env_id", list(LADDERS))
def test_plain_scripted_is_the_top_as_baseline_and_default_opponent(env_id):
    env = gym.make(env_id)
    try:
        obs, _ = env.reset(seed=3)
        top = env.unwrapped.scripted_level(len(LADDERS[env_id]) - 1)
        for policy in (env.unwrapped.scripted_policy(), env.unwrapped.game.opponent):
            assert type(policy) is type(top)
            assert np.array_equal(policy(obs), top(obs))
    finally:
        env.close()


def test_the_top_plays_as_the_aiming_level_where_it_cannot_see_its_joints():
    # Figurine centres instead of joint values: no wind-up can be timed.
    on_figurines = scripted_policy("Foosball-FullGame-v0", {"observe_figurines": True})
    assert type(on_figurines) is ScriptedTeam and on_figurines.aim
    # A camera's estimate: it kicks and aims, but does not deflect.
    estimated = scripted_policy("Foosball-FullGame-v0", {"estimated_state": True})
    assert isinstance(estimated, AttackingTeam) and not estimated.deflect


def test_a_level_is_an_opponent_by_name_in_the_options_and_set_opponent():
    env = gym.make("Foosball-KeeperVsKeeper-v0", opponent="scripted:0")
    try:
        assert isinstance(env.unwrapped.opponent, StandStill)
        env.unwrapped.set_opponent("scripted:1")
        assert type(env.unwrapped.opponent) is ScriptedTeam
        env.unwrapped.set_opponent("scripted")
        assert isinstance(env.unwrapped.opponent, AttackingTeam)
        with pytest.raises(ValueError, match=r"scripted:0 \(still\), scripted:1 \(kicking\)"):
            env.unwrapped.set_opponent("scripted:3")
        with pytest.raises(ValueError, match="callable obs -> action, 'scripted'"):
            env.unwrapped.set_opponent("builtin:keeper-vs-keeper")
    finally:
        env.close()


def test_bad_levels_are_refused_naming_the_levels_there_are():
    with pytest.raises(ValueError, match=r"no scripted level 4; its levels are scripted:0"):
        scripted_policy("Foosball-FullGame-v0", level=4)
    with pytest.raises(ValueError, match="no scripted level -1"):
        scripted_policy("Foosball-FullGame-v0", level=-1)
    with pytest.raises(ValueError, match="has no scripted ladder"):
        scripted_policy("Foosball-Block-v0", level=0)
    with pytest.raises(ValueError, match="must be a whole number"):
        parse_scripted("scripted:top")
    with pytest.raises(ValueError, match="names no scripted team"):
        parse_scripted("scripts")
    assert parse_scripted("scripted") is None and parse_scripted("scripted:2") == 2


def test_the_eval_command_takes_levels_as_policy_and_opponent(capsys):
    argv = ["eval", "--policy", "scripted:1", "Foosball-KeeperVsKeeper-v0", "--episodes", "1"]
    assert main([*argv, "--opponent", "scripted:0", "--env-kwarg", "stagnation_steps=20"]) == 0
    out = capsys.readouterr().out
    assert "policy               scripted:1" in out and "opponent             scripted:0" in out
    for bad in (["--opponent", "scripted:5"], ["--policy", "scripted:5"]):
        with pytest.raises(SystemExit):
            main([*argv[:2], "scripted", *argv[3:], *bad])
        assert "its levels are scripted:0 (still)" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["eval", "--policy", "scripted:x", "Foosball-FullGame-v0"])
    assert "must be a whole number" in capsys.readouterr().err


def test_the_league_command_rates_levels_without_a_run(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    argv = ["league", "--env", "Foosball-KeeperVsKeeper-v0", "--add", "scripted:0"]
    quick = ["--games", "2", "--env-kwarg", "match_seconds=5", "--env-kwarg", "continuous=True"]
    assert main([*argv, *quick, "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "scripted:0" in out and "Elo relative to scripted" in out
    assert (tmp_path / "league.json").is_file()
    with pytest.raises(SystemExit):
        main(argv)
    assert "needs --env ENV_ID (the game) and --out DIR" in capsys.readouterr().err


def test_the_play_command_takes_a_level():
    from foosball_gym.cli.common import CliError
    from foosball_gym.cli.play import _policy

    args = build_play_args("scripted:0")
    policy, env_id, _, _ = _policy(args)
    assert isinstance(policy, StandStill) and env_id == "Foosball-FullGame-v0"
    with pytest.raises(CliError, match="no scripted level 9"):
        _policy(build_play_args("scripted:9"))


def build_play_args(model: str):
    from foosball_gym.cli import build_parser

    return build_parser().parse_args(
        ["play", model, "--table", "sim", "--env", "Foosball-FullGame-v0"]
    )


@pytest.mark.parametrize(
    "env_id, seconds, at_least",
    # Seeds 0-2 measured: 2, 3 and 3 goals in a minute of the full game, 3, 3 and 3 in 10 s of
    # keeper against keeper, none conceded; a broken attack scores none.
    [("Foosball-FullGame-v0", 60, 1), ("Foosball-KeeperVsKeeper-v0", 10, 2)],
)
def test_the_top_of_the_ladder_scores_against_a_team_that_stands_still(env_id, seconds, at_least):
    env = gym.make(env_id, continuous=True, match_seconds=seconds, opponent="scripted:0")
    try:
        info = play(env, env.unwrapped.scripted_policy(), seed=0)
    finally:
        env.close()
    assert info["goals_for"] >= at_least and info["goals_against"] == 0, info


@pytest.mark.slow
@pytest.mark.parametrize("env_id", list(LADDERS))
def test_each_level_outscores_the_one_below_it(env_id):
    # docs/results/ladder.md has the league; this is the same order, on fewer matches.
    env = gym.make(env_id, continuous=True)
    try:
        for n in range(1, len(LADDERS[env_id])):
            env.unwrapped.set_opponent(f"scripted:{n - 1}")
            policy = env.unwrapped.scripted_level(n)
            scored = conceded = 0
            for seed in range(20):
                info = play(env, policy, seed)
                scored += info["goals_for"]
                conceded += info["goals_against"]
            assert scored > 2 * conceded + 5, (n, scored, conceded)
    finally:
        env.close()


class _PickedShot(AttackingTeam):
    picked: float | None = 0.0

    def shot_angle(self, x, y, defenders):
        return self.picked


def test_a_team_that_picks_its_own_shots_swings_or_holds_as_it_picks():
    # The offence, wound up and lined up behind a resting ball in front of it: a straight shot
    # swings at once, and a shot_angle of None keeps the foot wound up and lined up.
    env = gym.make("Foosball-FullGame-v0")
    try:
        obs, _ = env.reset(seed=0)
        names = env.unwrapped.obs_builder.names
    finally:
        env.close()
    rods = [f"home_{role}" for role in table.ROLES]
    offence = table.rod("home_offense")
    put = {
        "ball_x": offence.x + 0.03,
        "ball_y": 0.05,
        "ball_vx": 0.0,
        "ball_vy": 0.0,
        "home_offense_spin_pos": -1.4,
        "home_offense_slide_pos": slide_for(offence, 0.05),
    }
    obs = np.array(obs, dtype=np.float64)
    for name, value in put.items():
        obs[names.index(name)] = value
    team = _PickedShot(names, rods)
    assert team.shooter(obs) == 3
    assert team(obs)[7] == pytest.approx(KICK_ANGLE / table.SPIN_LIMIT)
    team.picked = None
    assert team(obs)[7] == pytest.approx(WIND_UP_ANGLE / table.SPIN_LIMIT)
    assert team(obs)[6] == pytest.approx(put["home_offense_slide_pos"] / offence.slide_limit)
