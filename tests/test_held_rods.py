"""Holding some of the learner's rods at the action 0 in training games (rods_held_share)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import foosball_gym  # noqa: F401  (registers the environments)
from foosball_gym.training.config import TrainConfig
from foosball_gym.training.held_rods import HeldRodsWrapper

ENV = "Foosball-FullGame-v0"
RODS = ("keeper", "defense", "midfield", "offense")


def _wrapped(share: float) -> HeldRodsWrapper:
    return HeldRodsWrapper(gym.make(ENV, opponent="scripted:0"), share)


def test_a_held_rod_stays_where_the_action_0_puts_it_and_a_free_one_follows_the_action():
    env = _wrapped(0.5)
    names = env.unwrapped.obs_builder.names
    try:
        for seed in range(20):
            env.reset(seed=seed)
            if env.held.any() and not env.held.all():
                break
        held, free = RODS[int(np.argmax(env.held))], RODS[int(np.argmin(env.held))]
        for _ in range(40):
            obs, *_ = env.step(np.full(8, 0.6, np.float32))
        value = dict(zip(names, obs, strict=True))
        slide = {rod: next(v for n, v in value.items() if rod in n and "slide_pos" in n)
                 for rod in (held, free)}  # fmt: skip
        assert abs(slide[held]) < 1e-3 < abs(slide[free])
    finally:
        env.close()


def test_each_game_draws_its_rods_anew_leaves_one_free_and_repeats_with_its_seed():
    env = _wrapped(0.9)
    try:
        draws = []
        for seed in range(30):
            env.reset(seed=seed)
            draws.append(tuple(env.held))
        assert all(not all(d) for d in draws)  # at least one rod left to the learner
        assert len(set(draws)) > 3
        env.reset(seed=7)
        assert tuple(env.held) == draws[7]
        action = env.action(np.ones(8, np.float32))
        assert list(action.reshape(4, 2).any(axis=1)) == [not h for h in draws[7]]
    finally:
        env.close()


def test_holding_rods_leaves_the_serves_as_they_were():
    plain, held = gym.make(ENV, opponent="scripted:0"), _wrapped(0.5)
    try:
        for seed in (0, 3):
            np.testing.assert_array_equal(plain.reset(seed=seed)[0], held.reset(seed=seed)[0])
            # The next game's serve, unseeded, comes from the environment's own generator,
            # which the draw of held rods must leave alone.
            np.testing.assert_array_equal(plain.reset()[0], held.reset()[0])
    finally:
        plain.close()
        held.close()


@pytest.mark.parametrize(
    ("env_id", "share", "message"),
    [
        (ENV, 1.0, r"in \[0, 1\)"),
        (ENV, -0.1, r"in \[0, 1\)"),
        (ENV, "half", "must be a number"),
        (ENV, True, "must be a number"),
        ("Foosball-Block-v0", 0.5, "drives 1 rod, so it needs 0"),
    ],
)
def test_a_share_that_cannot_hold_rods_is_refused(env_id, share, message):
    config = TrainConfig(env_id, rods_held_share=share)
    with pytest.raises(ValueError, match=message):
        config.check()


def test_the_training_envs_hold_rods_when_the_run_asks():
    pytest.importorskip("stable_baselines3")
    from foosball_gym.training.sb3.vec_env import make_env

    config = TrainConfig(ENV, n_envs=2, vec_env="dummy", rods_held_share=0.5, normalize=False,
                         normalize_reward=False)  # fmt: skip
    config.check()
    venv = make_env(config)
    try:
        venv.reset()
        held = venv.get_attr("held")
        assert len(held) == 2 and all(h.shape == (4,) for h in held)
    finally:
        venv.close()


def test_holding_rods_is_an_option_of_the_train_command():
    from cli import build_parser

    args = build_parser().parse_args(["train", ENV, "--rods-held-share", "0.5"])
    assert args.rods_held_share == 0.5
