"""The batched vectorised env: its environments split over worker processes behave as SB3's own
DummyVecEnv of the same environments, seeded alike."""

from __future__ import annotations

import numpy as np
import pytest
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv

import foosball_gym  # noqa: F401
from foosball_gym.training.sb3.batched_vec_env import BatchedSubprocVecEnv
from foosball_gym.training.sb3.in_process_vec_env import InProcessVecEnv

ENV = "Foosball-Block-v0"


def _play(vec_env_cls: type, actions: np.ndarray, **kwargs: object) -> tuple[list, list]:
    venv = make_vec_env(ENV, n_envs=actions.shape[1], seed=7, vec_env_cls=vec_env_cls, **kwargs)
    try:
        steps: list = [venv.reset()]
        infos = []
        for action in actions:
            obs, reward, done, info = venv.step(action)
            steps += [obs, reward, done]
            infos.append(info)
        return steps, infos
    finally:
        venv.close()


@pytest.mark.parametrize("kind", ["batched", "batched, one share here", "in process"])
def test_the_vec_envs_give_the_steps_a_dummy_vec_env_gives(kind: str) -> None:
    actions = np.random.default_rng(0).uniform(-1, 1, (120, 5, 1)).astype(np.float32)
    dummy, dummy_infos = _play(DummyVecEnv, actions)
    if kind.startswith("batched"):
        # 5 environments over 2 workers: shares of 2 and 3 (or 3 and 2), not a whole division.
        kwargs = {"workers": 2, "here": kind.endswith("here")}
        batched, batched_infos = _play(BatchedSubprocVecEnv, actions, vec_env_kwargs=kwargs)
    else:
        batched, batched_infos = _play(InProcessVecEnv, actions)
    for a, b in zip(dummy, batched, strict=True):
        np.testing.assert_array_equal(a, b)
    finals = 0
    for step_a, step_b in zip(dummy_infos, batched_infos, strict=True):
        for info_a, info_b in zip(step_a, step_b, strict=True):
            assert info_a.keys() == info_b.keys()
            for key in info_a.keys() - {"terminal_observation", "episode"}:
                assert info_a[key] == info_b[key], key
            if "episode" in info_a:  # the Monitor's, with its wall time
                assert info_a["episode"]["r"] == info_b["episode"]["r"]
                assert info_a["episode"]["l"] == info_b["episode"]["l"]
            if "terminal_observation" in info_a:
                finals += 1
                np.testing.assert_array_equal(
                    info_a["terminal_observation"], info_b["terminal_observation"]
                )
    assert finals > 5  # episodes ended and were reset within the steps compared


@pytest.mark.parametrize("here", [False, True])
def test_calls_reach_the_environments_they_name(here: bool) -> None:
    venv = BatchedSubprocVecEnv(
        [lambda: __import__("gymnasium").make(ENV) for _ in range(5)], workers=2, here=here
    )
    try:
        assert venv.workers == 2
        venv.set_attr("marker", "x", indices=[1, 3])
        venv.set_attr("marker", "y", indices=[0, 2, 4])
        assert venv.get_attr("marker") == ["y", "x", "y", "x", "y"]
        assert venv.get_attr("marker", indices=[4, 1]) == ["y", "x"]
        assert len(venv.env_method("scripted_policy", indices=[2, 3])) == 2
        assert venv.env_is_wrapped(__import__("gymnasium").Wrapper) == [True] * 5
        assert venv.has_attr("marker")
    finally:
        venv.close()
        venv.close()  # twice is harmless, as SB3's own


@pytest.mark.parametrize("here", [False, True])
def test_a_failure_in_a_worker_is_raised_in_the_main_process_and_the_worker_lives_on(
    here: bool,
) -> None:
    venv = BatchedSubprocVecEnv(
        [lambda: __import__("gymnasium").make(ENV) for _ in range(2)], workers=2, here=here
    )
    try:
        for index in (0, 1):  # the share here, if there is one, and a worker's
            with pytest.raises(AttributeError, match="no_such_method"):
                venv.env_method("no_such_method", indices=[index])
        venv.reset()
        obs, _, _, _ = venv.step(np.zeros((2, 1), np.float32))
        assert obs.shape == (2, 6)
    finally:
        venv.close()


def test_more_workers_than_environments_is_refused_in_one_line() -> None:
    with pytest.raises(ValueError, match=r"workers must lie in \[1, 2\]"):
        BatchedSubprocVecEnv([lambda: __import__("gymnasium").make(ENV)] * 2, workers=3)


def test_a_run_trains_the_same_policy_with_its_environments_batched_or_in_process(
    tmp_path,
) -> None:
    import torch

    from foosball_gym.training.config import TrainConfig
    from foosball_gym.training.run_dir.storage import read_model_zip
    from foosball_gym.training.sb3.trainer import train

    weights = {}
    for vec_env in ("dummy", "batched"):
        config = TrainConfig(
            ENV, timesteps=512, n_envs=4, n_steps=64, batch_size=128, n_epochs=2, seed=5,
            vec_env=vec_env, eval_freq=10_000, eval_episodes=1, checkpoint_freq=10_000,
        )  # fmt: skip
        train(config, tmp_path / vec_env)
        _, params, _ = read_model_zip(tmp_path / vec_env / "model.zip")
        weights[vec_env] = params["policy"]
    assert weights["dummy"].keys() == weights["batched"].keys()
    for name, value in weights["dummy"].items():
        assert torch.equal(value, weights["batched"][name]), name


def test_in_process_infos_are_the_caller_s_to_keep() -> None:
    # Without SB3's deep copy, no later step may change what an earlier one returned.
    venv = make_vec_env(ENV, n_envs=2, seed=3, vec_env_cls=InProcessVecEnv)
    try:
        venv.reset()
        kept = []
        for _ in range(150):
            _, _, _, infos = venv.step(np.zeros((2, 1), np.float32))
            snapshot = [
                {k: np.copy(v) if k == "terminal_observation" else v for k, v in info.items()}
                for info in infos
            ]
            kept.append((infos, snapshot))
        finals = 0
        for infos, snapshot in kept:
            for info, then in zip(infos, snapshot, strict=True):
                assert info.keys() == then.keys()
                for key, value in then.items():
                    if key == "terminal_observation":
                        finals += 1
                        np.testing.assert_array_equal(info[key], value)
                    else:
                        assert info[key] == value, key
        assert finals > 2
    finally:
        venv.close()
