"""Starts and serves: no figurine starts inside the ball, on any rod, and a serve always ends."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import table
from foosball_gym.tasks.base import GAP_Y, REACH_X, Start, clear_of_ball, figurine_at_ball

# What crashed `foosball play scripted --env Foosball-Score-v0 --table sim --lockstep
# --episodes 60 --seed 9191` in its 19th serve: the keeper slid to exactly one gap beside the
# ball compared as still touching it, and was slid to the same place forever.
CRASH_SLIDE = -0.06863198667206995
CRASH_BALL = (-0.49935467315781346, -0.03885310894631742)


def touching(rod: table.Rod, slide: float, ball: tuple[float, float]) -> bool:
    """The test's own reading of "a figurine touches the ball": closer than the gap, by more
    than a nanometre."""
    return abs(ball[0] - rod.x) < REACH_X and any(
        abs(y - ball[1]) < GAP_Y - 1e-9 for y in rod.figurine_y(slide)
    )


def test_the_keeper_one_gap_beside_the_ball_is_clear_of_it():
    keeper = table.rod("home_keeper")
    slide = clear_of_ball(keeper, CRASH_SLIDE, CRASH_BALL)
    assert abs(keeper.figurine_y(slide)[0] - CRASH_BALL[1]) == pytest.approx(GAP_Y, abs=1e-12)
    assert not touching(keeper, slide, CRASH_BALL)


@pytest.mark.parametrize("rod", table.RODS, ids=lambda r: r.name)
def test_every_placement_of_every_rod_ends_clear_of_the_ball(rod):
    rng = np.random.default_rng(sum(map(ord, rod.name)))
    moved = 0
    for _ in range(5_000):
        # A ball on or near the rod's line, around one of its figurines (a uniform draw over
        # the whole field is too coarse a float to meet the rounding that recursed), and in
        # a quarter of the draws the rod slid to put that figurine exactly one gap beside it.
        slide = float(rng.uniform(-rod.slide_limit, rod.slide_limit))
        k = int(rng.integers(len(rod.figurine_offsets)))
        by = rod.figurine_y(slide)[k] + float(rng.uniform(-1.5, 1.5)) * GAP_Y
        if abs(by) > table.BALL_LIMIT_Y:
            continue
        ball = (rod.x + float(rng.uniform(-1.2, 1.2)) * REACH_X, by)
        if rng.uniform() < 0.25:
            side = 1.0 if rng.uniform() < 0.5 else -1.0
            edge = rod.direction * (by + side * GAP_Y) - rod.figurine_offsets[k]
            if abs(edge) <= rod.slide_limit:
                slide = edge
        result = clear_of_ball(rod, slide, ball)
        assert abs(result) <= rod.slide_limit, (rod.name, slide, ball)
        assert not touching(rod, result, ball), (rod.name, slide, ball)
        assert figurine_at_ball(rod, result, ball) is None
        if result != slide:
            moved += 1
            assert touching(rod, slide, ball), "a figurine clear of the ball was moved"
            # Beside the ball, not across the table: one gap from it at most.
            assert abs(result - slide) <= 2 * GAP_Y
    assert moved > 500  # the loop did put figurines in the ball's way


def test_a_serve_beside_a_keeper_one_gap_from_the_ball_is_played():
    env = gym.make("Foosball-Score-v0")
    try:
        env.reset(seed=0)
        game = env.unwrapped.game
        game.positions[0] = CRASH_SLIDE
        game.task.sample_start = lambda rng, *a, **k: Start([0.0], [0.0], CRASH_BALL, (0.0, 0.0))
        game.serve(np.random.default_rng(0))
        assert game.ball[:2] == pytest.approx(CRASH_BALL, abs=1e-9)
    finally:
        env.close()


def test_starts_beside_the_ball_are_as_they_were_to_the_last_bit():
    """Seeded episodes stay what they were: where the old, recursive search ended, the slide
    is the same float (these values are what it gave)."""
    keeper, defense = table.rod("home_keeper"), table.rod("away_defense")
    cases = [
        (keeper, 0.0, (keeper.x + 0.025, 0.0), 0.036250000000000004),
        (keeper, 0.0, (keeper.x + 0.025, 0.02), -0.016250000000000004),
        (keeper, 0.0, (keeper.x + 0.025, -0.03), 0.0062500000000000056),
        (keeper, 0.0, (keeper.x + 0.025, 0.1), 0.0),
        (defense, 0.0, (defense.x, -0.1235), -0.036250000000000004),
        (defense, 0.1, (defense.x, 0.02), 0.06724999999999999),
        (defense, -0.17, (defense.x, 0.3), -0.14024999999999999),
    ]
    for rod, slide, ball, before in cases:
        assert clear_of_ball(rod, slide, ball) == before


@pytest.mark.slow
def test_the_play_command_that_crashed_plays_its_60_serves():
    """The command that crashed, run as a user runs it (in a process of its own: inside the
    test process, on a loaded machine, the play stack stopped on a late drive answer)."""
    argv = ["play", "scripted", "--env", "Foosball-Score-v0", "--table", "sim", "--lockstep"]
    argv += ["--episodes", "60", "--seed", "9191", "--no-status"]
    done = subprocess.run(
        [sys.executable, "-m", "foosball_gym.cli", *argv], capture_output=True, text=True
    )
    assert "RecursionError" not in done.stderr
    assert done.returncode == 0, done.stderr[-2000:]
    assert "60 episodes of Foosball-Score-v0" in done.stdout
