"""Shots past defenders that react: how far a defender's drive gets it in time, and the shots
planned against it."""

from __future__ import annotations

import inspect
import math

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import table
from foosball_gym.policies import reach, shots
from foosball_gym.sim import TableSim, drive_acceleration

KEEPER = table.rod("away_keeper")
DEFENSE = table.rod("away_defense")


def test_the_reach_model_drives_the_slide_as_the_simulator_does():
    gain = inspect.signature(TableSim).parameters["slide_gain"].default
    assert reach.SLIDE_GAIN == gain
    # The keeper, told to go 0.1 m, comes within BLOCK of it when the model says it does.
    env = gym.make("Foosball-KeeperVsKeeper-v0", opponent="scripted:0")
    target = 0.1
    try:
        env.reset(seed=0, options={"ball_position": (0.0, 0.3), "ball_velocity": (0.0, 0.0)})
        dt = env.unwrapped.dt
        for step in range(1, 30):  # noqa: B007
            obs, *_ = env.step(np.array([target / 0.123, 0.0], dtype=np.float32))
            if obs[0] >= target - reach.BLOCK:
                break
    finally:
        env.close()
    assert reach.cover_time("keeper", target) == pytest.approx(step * dt, abs=dt)
    assert drive_acceleration(table.rod("home_keeper"), "slide") == pytest.approx(96.6, abs=0.1)


def test_a_defender_moves_only_after_its_reaction_and_as_far_as_its_drive_takes_it():
    assert reach.move_distance("keeper", reach.REACTION) == 0.0
    near, far = reach.move_distance("keeper", 0.03), reach.move_distance("keeper", 0.06)
    assert 0.0 < near < far < 0.15
    assert np.allclose(reach.move_distances("keeper", np.array([0.03, 0.06])), [near, far])


def test_a_shot_a_far_keeper_can_reach_is_blocked_and_one_a_near_defense_cannot_passes():
    # A straight shot from the offense at a keeper standing in its path: blocked however
    # fast; aimed at the far post from off the middle, past a keeper that follows the ball.
    keeper_at_ball = [(KEEPER, -0.08)]  # the away keeper's slide -0.08 is world y +0.08
    assert shots.margins(0.26, 0.08, np.array([0.0]), keeper_at_ball)[0] < 0.0
    far_post = math.atan2(-0.07 - 0.08, table.GOAL_LINE_X - 0.26)
    assert shots.margins(0.26, 0.08, np.array([far_post]), keeper_at_ball)[0] > 0.0
    # Standing keepers block less than reacting ones.
    angles = np.radians(np.arange(-30.0, 31.0, 1.0))
    assert np.all(
        shots.margins(0.26, 0.08, angles, keeper_at_ball, react=False)
        >= shots.margins(0.26, 0.08, angles, keeper_at_ball) - 1e-12
    )


def test_the_planned_shot_goes_where_the_defenders_cannot_reach():
    defenders = [(DEFENSE, 0.0), (KEEPER, -0.08)]
    angle, margin = shots.plan_reacting_shot(0.26, 0.08, defenders)
    assert margin > 0.0 and angle < 0.0  # across, to the far side of the goal
    assert shots.plan_shot_past(0.26, 0.08, defenders) == angle


def test_the_corner_shot_banks_into_the_corner_away_from_the_keeper():
    for keeper_y, side in ((0.05, -1.0), (-0.05, 1.0)):
        angle = shots.corner_shot(-0.475, 0.0, KEEPER, -keeper_y)
        assert np.sign(angle) == side
        ys, slope = shots._paths(-0.475, 0.0, np.array([angle]), [table.BALL_LIMIT_X])
        assert side * ys[-1][0] == pytest.approx(shots.CORNER_MIDDLE, abs=0.01)
        assert ys[-1][0] * slope[0] < 0  # coming back towards the middle


def test_a_planned_shot_is_judged_by_the_worst_of_its_aim_and_its_likely_errors():
    # The plan judges an angle and the angles its error allows either side in one pass; it
    # must choose exactly what judging each set of angles apart chooses.
    from foosball_gym.policies.aiming import ANGLE_ERROR, ANGLE_ERROR_SLOPE

    rods = [table.rod(f"away_{role}") for role in ("keeper", "defense", "midfield", "offense")]
    rng = np.random.default_rng(5)
    for _ in range(150):
        x0, y0 = rng.uniform(-0.6, 0.5), rng.uniform(-0.32, 0.32)
        defenders = [(r, rng.uniform(-r.slide_limit, r.slide_limit)) for r in rods]
        react = bool(rng.random() < 0.5)
        angles = shots._ANGLES
        error = ANGLE_ERROR + ANGLE_ERROR_SLOPE * np.abs(angles)
        score = np.minimum.reduce(
            [shots.margins(x0, y0, angles + d, defenders, react) for d in (-error, 0.0, error)]
        )
        penalised = score - 0.001 * np.abs(angles)  # straighter shots win ties
        best = int(np.argmax(penalised))
        assert shots.plan_reacting_shot(x0, y0, defenders, react) == (
            float(angles[best]),
            float(penalised[best] + 0.001 * abs(angles[best])),
        )
