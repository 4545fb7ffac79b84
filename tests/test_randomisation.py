"""Domain randomisation: documented options, off by default, seeded, within their ranges."""

from __future__ import annotations

import gymnasium as gym
import pytest

RANGES = {
    "ball_friction_range": (0.05, 0.2),
    "ball_restitution_range": (0.3, 0.7),
    "ball_mass_range": (0.018, 0.026),
    "drive_gain_range": (0.5, 1.5),
}


def test_randomisation_is_off_by_default(make_env):
    env = make_env("Foosball-Block-v0")
    _, info = env.reset(seed=0)
    sim = env.unwrapped.sim
    assert "dynamics" not in info
    assert (sim.ball_friction, sim.ball_restitution, sim.ball_mass) == (0.1, 0.5, 0.022)


def test_each_episode_draws_its_dynamics_within_the_ranges(make_env):
    env = make_env("Foosball-Score-v0", **RANGES)
    sim = env.unwrapped.sim
    drawn = []
    for seed in range(20):
        _, info = env.reset(seed=seed)
        d = info["dynamics"]
        drawn.append(d)
        for key, (lo, hi) in RANGES.items():
            assert lo <= d[key[: -len("_range")]] <= hi
        assert sim.ball_friction == d["ball_friction"] and sim.ball_mass == d["ball_mass"]
        assert sim.slide_gain == pytest.approx(48.0 * d["drive_gain"])
    assert len({d["ball_mass"] for d in drawn}) == 20
    # Seeded: the same seed draws the same dynamics.
    assert env.reset(seed=3)[1]["dynamics"] == drawn[3]


def test_heavier_slower_responding_world_changes_the_game(make_env):
    """The drawn values reach the physics: a sluggish drive lags behind a brisk one."""
    lags = []
    for gain in (0.3, 1.5):
        env = gym.make("Foosball-Block-v0", drive_gain_range=(gain, gain))
        env.reset(seed=0, options={"ball_position": (0.3, 0.3), "ball_velocity": (0.0, 0.0)})
        for _ in range(3):
            obs, *_ = env.step([1.0])
        lags.append(obs[0])
        env.close()
    assert lags[0] < lags[1]


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"ball_restitution_range": (0.5, 1.5)}, "ball_restitution_range"),
        ({"ball_mass_range": (0.03, 0.02)}, "low <= high"),
        ({"drive_gain_range": 2.0}, "pair"),
    ],
)
def test_bad_ranges_are_rejected(kwargs, message):
    with pytest.raises(ValueError, match=message):
        gym.make("Foosball-Block-v0", **kwargs)
