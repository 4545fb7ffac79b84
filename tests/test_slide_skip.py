"""The option slide_skip: with slide_around_ball, a slide action other than 0 starts that far to
its side of the ball; past the flat of the foot, where a kick starts to turn."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import table
from foosball_gym.registration import check_env_options

BAND = 0.015
FLAT = table.FIGURINE_LEG_FLAT_HALF_WIDTH


def _first_shot_angle(action: float, **options) -> float:
    """The direction (degrees from the table's axis) of a resting ball's first shot, struck
    by the keeper standing at slide action ``action`` after a back-swing."""
    env = gym.make("Foosball-Score-v0", ball_start="resting", slide_around_ball=BAND, **options)
    try:
        obs, _ = env.reset(seed=0)
        names = env.unwrapped.obs_builder.names
        vx_at = names.index("ball_vx")
        for t in range(90):
            spin = -0.06 if t < 30 else 0.15
            obs, *_ = env.step(np.array([action, spin], dtype=np.float32))
            vx, vy = float(obs[vx_at]), float(obs[vx_at + 1])
            if math.hypot(vx, vy) > 1.0:
                return math.degrees(math.atan2(vy, vx))
        raise AssertionError("the keeper never struck the ball")
    finally:
        env.close()


def test_a_kick_off_the_flat_of_the_foot_goes_straight_wherever_on_the_flat():
    # Without the option the whole band below 9 mm is the flat: 0, 4 and 8 mm beside the
    # middle of the foot all send the ball along the table.
    for action in (0.0, 4e-3 / BAND, 8e-3 / BAND):
        assert abs(_first_shot_angle(action)) < 0.5


def test_past_the_flat_the_kick_turns_with_the_action_from_the_first_millimetre():
    angles = {a: _first_shot_angle(a, slide_skip=FLAT) for a in (0.0, 0.1, 0.3, -0.3)}
    assert abs(angles[0.0]) < 0.5
    # The ball meets the foot's rounded edge (3 mm round) 1.5 mm and 4.5 mm past the flat:
    # asin(offset / (edge radius + ball radius)) turns it about 4 and 13 degrees, away from
    # the side the figurine stands on.
    assert -7.0 < angles[0.1] < -2.0
    assert -16.0 < angles[0.3] < -10.0
    assert angles[-0.3] == pytest.approx(-angles[0.3], abs=1.5)


def test_the_figurine_stands_past_the_flat_either_side_of_the_ball():
    interface = check_env_options(
        "Foosball-Score-v0", {"slide_around_ball": BAND, "slide_skip": FLAT}
    ).interface
    names = interface.builder.names
    obs = np.zeros(len(names))
    obs[names.index("ball_y")] = 0.02
    keeper = table.rod("home_keeper")
    for action, expected in ((0.5, 0.02 + 0.5 * BAND + FLAT), (-0.5, 0.02 - 0.5 * BAND - FLAT)):
        slide = interface.table_action([action, 0.0], obs)[0] * keeper.slide_limit
        assert keeper.figurine_y(slide)[0] == pytest.approx(expected, abs=1e-9)
    slide = interface.table_action([0.0, 0.0], obs)[0] * keeper.slide_limit
    assert keeper.figurine_y(slide)[0] == pytest.approx(0.02, abs=1e-9)


@pytest.mark.parametrize("value", [-0.001, 0.05, True, "wide", float("nan"), None])
def test_a_skip_that_is_not_a_place_on_the_foot_is_refused(value):
    with pytest.raises(
        ValueError, match=r"slide_skip must be a number of metres in \[0, 0.02925\]"
    ):
        gym.make("Foosball-Score-v0", slide_around_ball=BAND, slide_skip=value)


def test_slide_skip_needs_the_band():
    with pytest.raises(ValueError, match="slide_skip needs slide_around_ball above 0"):
        gym.make("Foosball-Score-v0", slide_skip=FLAT)


def test_a_copy_of_the_learner_on_the_away_side_slides_past_the_flat_as_it_learned():
    from foosball_gym.training.loading.loader import whole_action_policy

    env_id = "Foosball-KeeperVsKeeper-v0"
    options = {"slide_around_ball": BAND, "slide_skip": FLAT, "stagnation_steps": 60}
    env = gym.make(env_id, **options)
    try:
        obs, _ = env.reset(seed=3)
    finally:
        env.close()
    player, played = whole_action_policy(lambda o: np.array([-0.4, 0.0]), env_id, options)
    # The away side's environment takes actions over the rods' travel: neither option.
    assert played == {"stagnation_steps": 60}
    gym.make(env_id, **played).close()
    ball_y = obs[player.interface.builder.names.index("ball_y")]
    keeper = table.rod("home_keeper")
    slide = player(obs)[0] * keeper.slide_limit
    assert keeper.figurine_y(slide)[0] == pytest.approx(ball_y - 0.4 * BAND - FLAT, abs=1e-6)
