"""scripts/shot_lanes.py: each obstacles ball sorted by whether its straight lane is open, and
each first shot's angle, the figures the obstacles' runs are compared by in the baselines page."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from scripts_loader import load_script

from foosball_gym import table
from foosball_gym.policies.scripted import ScriptedTeam

OBSTACLES = {"ball_start": "resting", "obstacles": True}
BALLS = 12


@pytest.fixture(scope="module")
def lanes():
    return load_script("shot_lanes")


@pytest.fixture(scope="module")
def keepers():
    """The task's aiming keeper and the same keeper kicking straight only."""
    env = gym.make("Foosball-Score-v0", **OBSTACLES)
    names = env.unwrapped.obs_builder.names
    aiming = env.unwrapped.scripted_policy()
    straight = ScriptedTeam(names, ("home_keeper",), "both", volley=True, aim=False)
    env.close()
    return aiming, straight


def test_a_figurine_in_front_of_the_ball_shuts_the_lane_and_one_beside_it_does_not(lanes):
    names = ["ball_x", "ball_y", "away_keeper_slide_pos"]
    keeper, ball_x = table.rod("away_keeper"), table.rod("home_keeper").x + 0.02
    assert not lanes.straight_lane_open(names, np.array([ball_x, 0.0, 0.0]))
    assert lanes.straight_lane_open(names, np.array([ball_x, 0.0, keeper.slide_limit]))
    assert lanes.straight_lane_open(names, np.array([ball_x, 0.0, -keeper.slide_limit]))
    # The same keeper shuts the lane of a ball lying where its figurine stands.
    edge = keeper.figurine_y(keeper.slide_limit)[0]
    assert not lanes.straight_lane_open(names, np.array([ball_x, edge, keeper.slide_limit]))


def test_with_no_obstacle_rod_observed_it_says_to_place_them(lanes):
    with pytest.raises(ValueError, match="obstacles=True"):
        lanes.straight_lane_open(["ball_x", "ball_y", "home_keeper_slide_pos"], np.zeros(3))


def test_the_lanes_belong_to_the_balls_and_the_aimed_shots_to_the_keeper_that_aims(lanes, keepers):
    aiming, straight = keepers
    aimed = lanes.play(aiming, OBSTACLES, BALLS, seed=0)
    plain = lanes.play(straight, OBSTACLES, BALLS, seed=0)
    assert [b.seed for b in aimed] == list(range(BALLS))
    # Judged at the reset, before either keeper moves: the same balls, the same lanes.
    assert [b.lane_open for b in aimed] == [b.lane_open for b in plain]
    assert 0 < sum(b.lane_open for b in aimed) < BALLS

    def off_axis(balls):
        return sum(abs(b.first_shot_degrees) > lanes.AIMED for b in balls if b.first_shot_degrees)

    assert off_axis(aimed) >= BALLS // 3
    assert off_axis(plain) <= 1
    # The aiming keeper scores balls whose straight lane is shut; the straight one cannot
    # score those with its first shot.
    assert any(b.goal == 1 and not b.lane_open for b in aimed)
    text = lanes.summary(aimed)
    assert f"balls {BALLS}: scored {sum(b.goal == 1 for b in aimed)}" in text
    assert f"straight lane open {sum(b.lane_open for b in aimed)}" in text


def test_a_keeper_that_never_strikes_has_no_first_shot(lanes):
    balls = lanes.play(lambda obs: np.zeros(2, dtype=np.float32), OBSTACLES, 3, seed=0)
    assert all(b.first_shot_degrees is None and b.goal == 0 for b in balls)
    assert "the ball was never struck towards the goal" in lanes.summary(balls)


def test_the_command_writes_a_row_a_ball_and_refuses_a_policy_without_obstacles(
    lanes, tmp_path, capsys
):
    out = tmp_path / "balls.csv"
    lanes.main(["scripted", "--episodes", "3", "--seed", "5", "--csv", str(out)])
    printed = capsys.readouterr().out
    assert "scripted on balls 5-7" in printed
    rows = out.read_text().splitlines()
    assert rows[0] == "seed,lane_open,goal,first_shot_degrees"
    assert [r.split(",")[0] for r in rows[1:]] == ["5", "6", "7"]
    with pytest.raises(SystemExit):
        lanes.main(["builtin:score-resting", "--episodes", "1"])
    assert "without obstacles" in capsys.readouterr().err


def test_a_run_trained_on_shut_lanes_is_judged_on_the_tasks_own_balls(
    lanes, tmp_path, monkeypatch, capsys
):
    class Trained:
        env_id = lanes.ENV_ID
        env_kwargs = {**OBSTACLES, "shut_lane_share": 1.0, "obstacle_share": 0.5}
        reset = None

        def __call__(self, obs):
            return np.zeros(2, dtype=np.float32)

    monkeypatch.setattr(lanes.foosball_gym, "load_policy", lambda run, trust=False: Trained())
    out = tmp_path / "balls.csv"
    lanes.main(["runs/shut", "--episodes", "6", "--csv", str(out)])
    capsys.readouterr()
    judged = [r.split(",")[1] == "True" for r in out.read_text().splitlines()[1:]]
    own = [b.lane_open for b in lanes.play(Trained(), OBSTACLES, 6, seed=0)]
    assert judged == own
    assert any(own)  # a run's own balls here would all be shut


def test_the_task_balls_drop_the_shares_a_run_trained_on_and_keep_its_other_options(lanes):
    trained = {**OBSTACLES, "obstacle_share": 0.5, "shut_lane_share": 1.0, "slide_skip": 0.009}
    assert lanes.task_balls(trained) == {**OBSTACLES, "slide_skip": 0.009}
    assert "shut_lane_share" in trained  # the run's own options are left as they were
