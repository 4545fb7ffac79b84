"""A pickled or deep-copied environment is an environment of its own, in the same state: it
steps as the original would, bit for bit, in this process or another, and neither moves nor
breaks the other; what cannot be copied is refused with a clear error."""

from __future__ import annotations

import copy
import gc
import pickle
import subprocess
import sys
import threading
from pathlib import Path

import cloudpickle
import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import ENV_IDS
from foosball_gym.registration import env_class

COPIERS = {
    "pickle": lambda env: pickle.loads(pickle.dumps(env)),
    "cloudpickle": lambda env: cloudpickle.loads(cloudpickle.dumps(env)),
    "deepcopy": copy.deepcopy,
}
# The seeds of the episodes after the first, one for each a run may end.
SEEDS = list(range(100, 200))
# Options beyond the grid's that keep state of their own: the filter and the camera, the
# dynamics drawn at each reset, the residual's baseline.
EXTRA_OPTIONS = [
    {"estimated_state": True, "camera_noise": {"drop_rate": 0.3, "latency_s": 0.02}},
    {"ball_friction_range": (0.05, 0.2), "drive_gain_range": (0.5, 2.0)},
    {"residual": 0.5, "stagnation_steps": 20},
]


def play(env: gym.Env, actions: np.ndarray, seeds: list[int]) -> list:
    """Every step's outcome for ``actions``; an ended episode restarts with the next seed."""
    out, seeds = [], list(seeds)
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        out.append((obs, reward, terminated, truncated, info))
        if terminated or truncated:
            out.append(env.reset(seed=seeds.pop(0)))
    return out


def assert_same_play(a: list, b: list) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x[0], y[0])
        assert x[1:] == y[1:]


def played(env_id: str, seed: int = 3, steps: int = 40, **kwargs) -> gym.Env:
    """An env of ``env_id`` in the middle of play: reset and ``steps`` random actions on."""
    env = gym.make(env_id, **kwargs)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    play(env, rng.uniform(-1, 1, (steps, *env.action_space.shape)), SEEDS)
    return env


def actions_for(env: gym.Env, steps: int, seed: int = 0) -> np.ndarray:
    shape = (steps, *env.action_space.shape)
    return np.random.default_rng(seed).uniform(-1, 1, shape).astype(np.float32)


def option_cases():
    for env_id in ENV_IDS:
        yield pytest.param(env_id, {}, id=f"{env_id}-defaults")
        for name, values in env_class(env_id).option_grid().items():
            for value in values[1:]:
                yield pytest.param(env_id, {name: value}, id=f"{env_id}-{name}={value}")
        for k, options in enumerate(EXTRA_OPTIONS):
            yield pytest.param(env_id, options, id=f"{env_id}-extra{k}")


@pytest.mark.parametrize("how", list(COPIERS))
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_a_copy_steps_as_the_original_would_bit_for_bit(env_id, how):
    original = played(env_id)
    twin = COPIERS[how](original)
    try:
        assert twin.unwrapped.sim is not original.unwrapped.sim
        actions = actions_for(original, 120)
        assert_same_play(play(twin, actions, SEEDS), play(original, actions, SEEDS))
    finally:
        original.close()
        twin.close()


@pytest.mark.parametrize("env_id, kwargs", list(option_cases()))
def test_every_option_set_copies_with_its_options_and_state(env_id, kwargs):
    original = played(env_id, steps=25, **kwargs)
    twin = pickle.loads(pickle.dumps(original))
    try:
        assert twin.spec.kwargs == original.spec.kwargs
        assert twin.unwrapped.obs_builder.names == original.unwrapped.obs_builder.names
        # The time limit's count, the simulator's and the random generator's state.
        assert twin._elapsed_steps == original._elapsed_steps
        assert twin.unwrapped.sim.physics_steps == original.unwrapped.sim.physics_steps
        assert twin.unwrapped.np_random.bit_generator.state == (
            original.unwrapped.np_random.bit_generator.state
        )
        actions = actions_for(original, 30)
        assert_same_play(play(twin, actions, SEEDS), play(original, actions, SEEDS))
    finally:
        original.close()
        twin.close()


@pytest.mark.parametrize("how", list(COPIERS))
def test_stepping_a_copy_leaves_the_original_where_it_was(how):
    # The witness is played as the original was: the original must go on as it does.
    original, witness = played("Foosball-Score-v0"), played("Foosball-Score-v0")
    twin = COPIERS[how](original)
    try:
        play(twin, actions_for(twin, 60, seed=1), SEEDS)
        actions = actions_for(original, 60, seed=2)
        assert_same_play(play(original, actions, SEEDS), play(witness, actions, SEEDS))
    finally:
        for env in (original, witness, twin):
            env.close()


@pytest.mark.parametrize("how", list(COPIERS))
def test_closing_or_dropping_either_leaves_the_other_working(how):
    original = played("Foosball-KeeperVsKeeper-v0")
    action = np.zeros(original.action_space.shape, np.float32)
    twin = COPIERS[how](original)
    twin.close()
    original.step(action)
    dropped = COPIERS[how](original)
    del dropped
    gc.collect()
    original.step(action)
    twin = COPIERS[how](original)
    original.close()
    twin.step(action)
    twin.reset(seed=0)
    twin.close()


def test_a_copy_of_a_closed_env_is_closed_and_one_never_reset_must_be_reset():
    closed = gym.make("Foosball-Block-v0")
    closed.reset(seed=0)
    closed.close()
    for twin in (pickle.loads(pickle.dumps(closed)), copy.deepcopy(closed)):
        with pytest.raises(gym.error.ClosedEnvironmentError):
            twin.reset(seed=0)
        twin.close()

    fresh = gym.make("Foosball-Block-v0")
    twin = pickle.loads(pickle.dumps(fresh))
    try:
        with pytest.raises(gym.error.ResetNeeded):
            twin.step(np.zeros(1, np.float32))
        np.testing.assert_array_equal(twin.reset(seed=5)[0], fresh.reset(seed=5)[0])
        actions = actions_for(fresh, 30)
        assert_same_play(play(twin, actions, SEEDS), play(fresh, actions, SEEDS))
    finally:
        fresh.close()
        twin.close()


def test_a_copy_renders_what_the_original_shows():
    original = played("Foosball-Score-v0", render_mode="rgb_array", render_width=96)
    original.render()
    twin = copy.deepcopy(original)
    try:
        np.testing.assert_array_equal(twin.render(), original.render())
    finally:
        original.close()
        twin.close()


# Run in another process: read the pickled envs and actions, play them, pickle back the play.
CHILD = """
import pickle, sys
sys.path.insert(0, {tests!r})
from test_copies import play
cases = pickle.load(open(sys.argv[1], "rb"))
pickle.dump([play(env, actions, seeds) for env, actions, seeds in cases], open(sys.argv[2], "wb"))
"""


def test_a_copy_unpickled_in_another_process_steps_as_the_original_bit_for_bit(tmp_path):
    """Bullet is deterministic: a world saved here and loaded there carries on identically."""
    envs = [played(env_id, seed=k) for k, env_id in enumerate(ENV_IDS)]
    envs.append(played("Foosball-Score-v0", **EXTRA_OPTIONS[0], **EXTRA_OPTIONS[1]))
    cases = [(env, actions_for(env, 90, seed=k), SEEDS) for k, env in enumerate(envs)]
    # cloudpickle's bytes as a trainer's subprocesses get them; pickle reads them back there.
    (tmp_path / "in.pkl").write_bytes(cloudpickle.dumps(cases))
    code = CHILD.format(tests=str(Path(__file__).parent))
    out = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path / "in.pkl"), str(tmp_path / "out.pkl")],
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0, out.stderr
    there = pickle.loads((tmp_path / "out.pkl").read_bytes())
    for (env, actions, seeds), theirs in zip(cases, there):
        assert_same_play(theirs, play(env, actions, seeds))
        env.close()


def keeper(obs):
    return np.zeros(2, np.float32)


def test_an_opponent_pickle_cannot_find_is_copied_by_value():
    env = gym.make("Foosball-KeeperVsKeeper-v0", opponent=lambda obs: np.full(2, 0.5, np.float32))
    env.reset(seed=0)
    try:
        for how in COPIERS:
            twin = COPIERS[how](env)
            opponent = twin.unwrapped.opponent
            assert opponent(twin.unwrapped.opponent_observation()).tolist() == [0.5, 0.5]
            twin.close()
        # A module-level function is pickled by name, as pickle always does.
        env.unwrapped.set_opponent(keeper)
        assert pickle.loads(pickle.dumps(env)).unwrapped.opponent is keeper
    finally:
        env.close()


def test_an_opponent_that_cannot_be_copied_is_refused_naming_it():
    class Locked:
        def __init__(self):
            self.lock = threading.Lock()

        def __call__(self, obs):
            return np.zeros(2, np.float32)

    made = gym.make("Foosball-KeeperVsKeeper-v0", opponent=Locked())
    env = gym.make("Foosball-KeeperVsKeeper-v0")
    try:
        env.unwrapped.set_opponent(Locked())
        for copied in (made, env):
            for how in ("pickle", "cloudpickle"):
                with pytest.raises(TypeError, match="cannot copy the game: its opponent .*Locked"):
                    COPIERS[how](copied)
        env.unwrapped.set_opponent(None)  # the scripted default copies
        default = type(env.unwrapped.opponent)
        assert type(pickle.loads(pickle.dumps(env)).unwrapped.opponent) is default
    finally:
        made.close()
        env.close()


def test_an_env_with_the_gui_open_is_refused(display):
    env = gym.make("Foosball-Block-v0", render_mode="human")
    try:
        for how in COPIERS:
            with pytest.raises(TypeError, match="GUI .* cannot be copied"):
                COPIERS[how](env)
    finally:
        env.close()
