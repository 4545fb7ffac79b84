"""Shot distributions: where Block and Score serves start, how fast, and bank shots that really
reach the goal mouth off a side wall."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import table
from foosball_gym.sim import AWAY_SCORED, TableSim
from foosball_gym.tasks.serves import Shots

WIDE = {
    "speed_range": (2.0, 10.0),
    "serve_x_range": (-0.1, 0.45),
    "serve_y_range": (-table.BALL_LIMIT_Y, table.BALL_LIMIT_Y),
    "bank_share": 0.5,
}
# The foot's sole is above a ball on the table at this spin: the keeper is out of the way.
LIFTED = 1.7


def wide_shots(bank_share: float) -> Shots:
    return Shots.checked(
        WIDE["speed_range"], WIDE["serve_x_range"], WIDE["serve_y_range"], bank_share
    )


def first_wall_contact(position, velocity) -> float | None:
    """|y| at which a straight path from ``position`` along ``velocity`` meets a side wall
    before the home goal line, or None where it reaches the line first."""
    (x, y), (vx, vy) = position, velocity
    if vy == 0:
        return None
    to_wall = (math.copysign(table.BALL_LIMIT_Y, vy) - y) / vy
    to_line = (-table.GOAL_LINE_X - x) / vx
    return to_wall if to_wall < to_line else None


def test_shots_without_banks_draw_what_the_plain_serve_drew():
    # Seeded episodes of every existing run and shipped evaluation depend on this.
    a, b = np.random.default_rng(3), np.random.default_rng(3)
    plain = Shots((2.0, 7.0))
    for _ in range(50):
        position, velocity = plain.start(a)
        x, y = b.uniform(0.0, 0.4), b.uniform(-0.3, 0.3)
        target, speed = (
            b.uniform(-table.GOAL_MOUTH_HALF, table.GOAL_MOUTH_HALF),
            b.uniform(2.0, 7.0),
        )
        dx, dy = -table.GOAL_LINE_X - x, target - y
        norm = math.hypot(dx, dy)
        assert position == (x, y)
        assert velocity == pytest.approx((speed * dx / norm, speed * dy / norm))


def test_wide_shots_cover_the_ranges_and_bank_about_the_share_asked():
    rng = np.random.default_rng(0)
    shots = wide_shots(0.5)
    starts = [shots.start(rng) for _ in range(2000)]
    xs = np.array([p[0] for p, _ in starts])
    ys = np.array([p[1] for p, _ in starts])
    speeds = np.array([math.hypot(*v) for _, v in starts])
    assert -0.1 <= xs.min() < -0.09 and 0.44 < xs.max() <= 0.45
    assert ys.min() < -0.31 and ys.max() > 0.31
    assert 2.0 <= speeds.min() < 2.1 and 9.9 < speeds.max() <= 10.0
    banks = sum(first_wall_contact(p, v) is not None for p, v in starts)
    # Where a bank off either wall is too steep the shot goes straight: a few percent.
    assert 0.45 * 2000 <= banks <= 0.5 * 2000 + 60
    assert all(v[0] < 0 for _, v in starts)


def test_away_goal_shots_are_the_home_ones_mirrored():
    home, away = wide_shots(1.0), wide_shots(1.0)
    a, b = np.random.default_rng(5), np.random.default_rng(5)
    for _ in range(20):
        (p, v), (q, w) = home.start(a), away.start(b, table.AWAY)
        assert q == pytest.approx((-p[0], -p[1]))
        assert w == pytest.approx((-v[0], -v[1]))


def test_bank_shots_reach_the_goal_mouth_off_a_side_wall():
    """With the keeper lifted out of the way, nearly every bank shot is a goal: the
    distribution's bank shots are real shots at the goal, not misses a keeper gets for free."""
    sim = TableSim(["home_keeper"])
    rng = np.random.default_rng(11)
    shots = wide_shots(1.0)
    goals = bounced = 0
    n = 60
    try:
        for _ in range(n):
            position, velocity = shots.start(rng)
            sim.reset(slide=[0.0], spin=[LIFTED], ball_position=position, ball_velocity=velocity)
            for _ in range(150):
                sim.command("position", [0.0, LIFTED])
                _, _, _, vy = sim.ball_xy()
                goal, out = sim.step()
                bounced += math.copysign(1, sim.ball_xy()[3]) != math.copysign(1, vy)
                if goal or out:
                    goals += goal == AWAY_SCORED
                    break
    finally:
        sim.close()
    assert bounced >= n  # every shot turned at a wall
    assert goals >= n - 2  # measured: 299 of 300


def test_block_options_serve_the_wide_distribution():
    env = gym.make("Foosball-Block-v0", **WIDE)
    try:
        names = env.unwrapped.obs_builder.names
        xi, yi = names.index("ball_x"), names.index("ball_y")
        obs = [env.reset(seed=s)[0] for s in range(300)]
    finally:
        env.close()
    xs = np.array([o[xi] for o in obs])
    ys = np.array([o[yi] for o in obs])
    assert xs.min() < 0.0 and xs.max() > 0.4
    assert abs(ys).max() > 0.3


def test_score_incoming_takes_the_same_options():
    env = gym.make("Foosball-Score-v0", ball_start="incoming", **WIDE)
    try:
        obs, _ = env.reset(seed=0)
        assert env.observation_space.contains(obs)
    finally:
        env.close()


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"bank_share": 1.5}, r"bank_share must be a number in \[0, 1\], got 1.5"),
        ({"bank_share": "many"}, "bank_share must be a number"),
        ({"serve_x_range": (0.3, 0.7)}, r"serve_x_range must satisfy -0.1 <= low <= high <="),
        ({"serve_y_range": (-0.5, 0.0)}, "serve_y_range must satisfy"),
        ({"serve_y_range": 0.3}, r"serve_y_range must be a pair \(low, high\)"),
    ],
)
def test_bad_shot_options_say_what_is_allowed(kwargs, message):
    with pytest.raises(ValueError, match=message):
        gym.make("Foosball-Block-v0", **kwargs)
