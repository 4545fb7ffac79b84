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


# ---------------------------------------------------------------- any shot a player plays

ANY = {
    "speed_range": (2.0, 12.0),
    "serve_x_range": (-0.1, 0.45),
    "serve_y_range": (-table.BALL_LIMIT_Y, table.BALL_LIMIT_Y),
    "bank_share": 0.3,
    "bank_aim": "mirror",
    "double_bank_share": 0.1,
    "beside_mouth": 0.03,
    "rebound_share": 0.1,
}


def any_shots(**changes) -> Shots:
    kw = {**ANY, **changes}
    return Shots.checked(
        kw["speed_range"],
        kw["serve_x_range"],
        kw["serve_y_range"],
        kw["bank_share"],
        kw["double_bank_share"],
        kw["bank_aim"],
        kw["beside_mouth"],
        kw["rebound_share"],
    )


def mirrored_goal_line_y(position, velocity) -> tuple[float, int]:
    """Where a path bouncing off the side walls by equal angles meets the home goal line, and
    how many walls it met on the way."""
    (x, y), (vx, vy) = position, velocity
    unfolded = y + vy * (-table.GOAL_LINE_X - x) / vx
    walls = 0
    w = table.BALL_LIMIT_Y
    while abs(unfolded) > w:
        unfolded = math.copysign(2 * w, unfolded) - unfolded
        walls += 1
    return unfolded, walls


def test_seeded_wide_serves_are_what_they_were_before_the_new_kinds():
    # The first draws of the wide distribution (a bank among them) as they were served before
    # double banks, mirrored aims, shots beside the mouth and rebounds existed.
    rng = np.random.default_rng(3)
    expected = [
        ((-0.0528929580710066, -0.16988881799221767), (-2.6175673797025785, 0.8529422295625296)),
        ((0.1382198171300606, -0.013522387050091622), (-3.543047133750066, -3.709707119753697)),
        ((0.18420710044175007, -0.04477961282264825), (-9.595902629376942, 1.0216735747120769)),
    ]
    shots = wide_shots(0.5)
    for position, velocity in expected:
        got_position, got_velocity = shots.start(rng)
        assert got_position == pytest.approx(position, abs=1e-15)
        assert got_velocity == pytest.approx(velocity, abs=1e-12)


def test_straight_shots_beside_the_mouth_reach_past_the_posts():
    rng = np.random.default_rng(0)
    shots = any_shots(bank_share=0.0, double_bank_share=0.0, rebound_share=0.0)
    ends = [mirrored_goal_line_y(*shots.start(rng)) for _ in range(1000)]
    ys = np.array([y for y, walls in ends if walls == 0])
    half = table.GOAL_MOUTH_HALF + 0.03
    assert len(ys) == 1000
    assert abs(ys).max() <= half + 1e-9
    assert (abs(ys) > table.GOAL_HALF_WIDTH).mean() > 0.05  # some meet the end wall beside it


@pytest.mark.parametrize("kind, walls", [("bank_share", 1), ("double_bank_share", 2)])
def test_mirrored_banks_meet_the_walls_a_player_aims_off(kind, walls):
    rng = np.random.default_rng(1)
    shares = {"bank_share": 0.0, "double_bank_share": 0.0, "rebound_share": 0.0, kind: 1.0}
    shots = any_shots(**shares)
    ends = [mirrored_goal_line_y(*shots.start(rng)) for _ in range(500)]
    aimed = [y for y, n in ends if n == walls]
    # The few left over were too steep off either wall and went straight instead.
    assert len(aimed) >= 450
    assert all(n in (0, walls) for _, n in ends)
    assert max(abs(y) for y in aimed) <= table.GOAL_MOUTH_HALF + 0.03 + 1e-9


def test_rebounds_come_back_off_the_defence_at_a_quarter_of_the_shot_speed():
    rng = np.random.default_rng(2)
    shots = any_shots(rebound_share=1.0)
    defence = table.rod("home_defense").x
    for _ in range(300):
        (x, y), (vx, vy) = shots.start(rng)
        assert defence - 0.06 < x < defence
        assert vx < 0
        assert 0.25 * 2.0 <= math.hypot(vx, vy) <= 0.25 * 12.0 + 1e-9
        assert abs(mirrored_goal_line_y((x, y), (vx, vy))[0]) <= table.GOAL_MOUTH_HALF + 0.03


def test_banks_and_rebounds_at_the_away_goal_are_the_home_ones_mirrored():
    # Straight shots aim at a uniform point of the mouth on either side, not a mirrored one.
    mix = {"bank_share": 0.6, "double_bank_share": 0.4, "rebound_share": 0.3}
    home, away = any_shots(**mix), any_shots(**mix)
    a, b = np.random.default_rng(7), np.random.default_rng(7)
    for _ in range(50):
        (p, v), (q, w) = home.start(a), away.start(b, table.AWAY)
        assert q == pytest.approx((-p[0], -p[1]))
        assert w == pytest.approx((-v[0], -v[1]))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (
            {"bank_share": 0.6, "double_bank_share": 0.5},
            "bank_share \\+ double_bank_share must be at most 1",
        ),
        ({"double_bank_share": -0.1}, r"double_bank_share must be a number in \[0, 1\]"),
        ({"bank_aim": "magic"}, "unknown bank_aim 'magic'; allowed: model, mirror"),
        ({"beside_mouth": 0.5}, r"beside_mouth must be a number in \[0, 0.1\] m"),
        ({"beside_mouth": "wide"}, "beside_mouth must be a number"),
        ({"rebound_share": 2}, r"rebound_share must be a number in \[0, 1\]"),
    ],
)
def test_bad_any_shot_options_say_what_is_allowed(kwargs, message):
    with pytest.raises(ValueError, match=message):
        gym.make("Foosball-Block-v0", **kwargs)
