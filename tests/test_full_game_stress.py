"""Random-action steps of the full game: the physics stays sane."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import table

# A figurine can squeeze the ball against a wall or the floor with its drive's full force, so
# the ball may sink in by up to the travel the simulator allows per physics step near a contact
# (9 mm seen); "outside" means its centre crossed the wall or the surface.
SINK = 0.75 * table.BALL_RADIUS


def test_full_game_with_random_actions_keeps_the_ball_on_the_table():
    episodes, goals = random_play(12_000)
    assert episodes > 20 and goals > 10  # 82 and 50 seen


@pytest.mark.slow
def test_fifty_thousand_random_full_game_steps_keep_the_ball_on_the_table():
    episodes, goals = random_play(50_000)
    assert episodes > 10 and goals > 0


def random_play(steps: int) -> tuple[int, int]:
    """Plays ``steps`` random actions, checking every step; the episodes and goals seen."""
    env = gym.make("Foosball-FullGame-v0")
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (steps, 8)).astype(np.float32)
    sim = env.unwrapped.sim
    episodes = goals = outs = 0
    try:
        env.reset(seed=0)
        for a in actions:
            obs, reward, terminated, truncated, info = env.step(a)
            assert np.isfinite(obs).all() and np.isfinite(reward)
            x, y, z = sim.ball_state().position
            if not info["out_of_table"]:
                assert z >= table.BALL_RADIUS - SINK, (x, y, z)
                assert abs(y) <= table.FIELD_HALF_WIDTH - table.BALL_RADIUS + SINK, (x, y, z)
                in_mouth = abs(y) <= table.GOAL_HALF_WIDTH
                limit = table.POCKET_BACK_X if in_mouth else table.FIELD_HALF_LENGTH
                assert abs(x) <= limit - table.BALL_RADIUS + SINK, (x, y, z)
                if abs(x) > table.GOAL_LINE_X:
                    assert info["goal"] != 0  # past the goal line only through the goal
            goals += info["goal"] != 0
            outs += info["out_of_table"]
            if terminated or truncated:
                episodes += 1
                env.reset()
    finally:
        env.close()
    return episodes, goals
