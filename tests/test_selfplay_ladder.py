"""Self-play's curriculum over the scripted ladder: the listed rungs join the scripted games one
at a time (selfplay_ladder_steps), so a learner from nothing meets the still team first."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.env_util import make_vec_env  # noqa: E402

from foosball_gym.training import OpponentActionWrapper, SelfPlayVecEnv  # noqa: E402
from foosball_gym.training.config import TrainConfig  # noqa: E402
from foosball_gym.training.selfplay.ladder import rungs_in_play  # noqa: E402
from foosball_gym.training.selfplay.ladder_curriculum import LadderCurriculum  # noqa: E402

ENV = "Foosball-KeeperVsKeeper-v0"


class CountingAnchor:
    """A scripted stand-in that holds still and counts the steps it played."""

    def __init__(self) -> None:
        self.steps = 0

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        self.steps += 1
        return np.zeros(2, np.float32)


def _env(anchors, n_envs=2):
    venv = make_vec_env(
        ENV, n_envs=n_envs, seed=0, wrapper_class=OpponentActionWrapper,
        env_kwargs={"stagnation_steps": 20},
    )  # fmt: skip
    still = lambda obs: np.zeros((len(obs), 2), np.float32)  # noqa: E731
    return SelfPlayVecEnv(venv, still, 0, anchor=anchors, anchor_share=0.9)


@pytest.mark.parametrize(
    ("steps_done", "ladder_steps", "expected"),
    [(0, 1000, 1), (999, 1000, 1), (1000, 1000, 2), (2500, 1000, 3), (10**9, 1000, 4), (0, 0, 4)],
)
def test_the_first_rung_plays_from_the_start_and_one_more_joins_every_ladder_steps(
    steps_done, ladder_steps, expected
):
    assert rungs_in_play(steps_done, ladder_steps, 4) == expected


def test_the_next_rung_plays_only_once_the_run_reaches_its_steps():
    anchors = [CountingAnchor(), CountingAnchor()]
    env = _env(anchors)
    model = PPO("MlpPolicy", env, n_steps=128, batch_size=128, n_epochs=1, seed=0, device="cpu")
    ladder = LadderCurriculum(ladder_steps=768, n_levels=2)
    ladder.apply(env, 0)
    try:
        model.learn(768, callback=ladder)
        assert anchors[0].steps > 500 and anchors[1].steps == 0
        model.learn(2048, callback=ladder, reset_num_timesteps=False)
        assert anchors[1].steps > 100
    finally:
        env.close()


def test_a_rollout_in_the_workers_meets_only_the_rungs_in_play():
    anchors = [CountingAnchor(), CountingAnchor(), CountingAnchor()]
    env = _env(anchors)
    try:
        env.reset()
        env.anchors_in_play = 2
        plan = env.plan(slice(0, 2), env.pool, [[0], [1]])
        assert plan.anchors == anchors[:2]
        share = SelfPlayVecEnv.playing(env.venv, plan)
        draws = {share._draw(i % 2) for i in range(400)}
        assert draws == {-1, -2, 0}  # the two rungs in play and the snapshot, not the third
    finally:
        env.close()


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        (dict(selfplay_ladder_steps=-5), "must be a whole number of steps"),
        (dict(selfplay_ladder_steps=2.5), "must be a whole number of steps"),
        (dict(selfplay_ladder_steps=1000, selfplay_scripted_levels=[1]), "at least two of them"),
        (dict(selfplay_ladder_steps=1000, selfplay_scripted_levels=[]), "at least two of them"),
    ],
)
def test_a_ladder_that_cannot_be_climbed_is_refused(settings, message):
    config = TrainConfig(ENV, selfplay_scripted_share=0.5, **settings)
    with pytest.raises(ValueError, match=message):
        config.check()


def test_the_ladder_is_an_option_of_the_train_command():
    from cli import build_parser

    args = build_parser().parse_args(
        ["train", ENV, "--selfplay-scripted-share", "0.9", "--selfplay-scripted-levels",
         "0,1,2", "--selfplay-ladder-steps", "500000"]
    )  # fmt: skip
    assert args.selfplay_ladder_steps == 500000
