"""An environment's options are its class's keyword arguments, described once in its docstring,
and the one table of ids is what Gymnasium and the real table read."""

from __future__ import annotations

import dataclasses
import inspect
import re
import typing

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import ENV_IDS, table
from foosball_gym.envs.base import FoosballEnv
from foosball_gym.envs.options import EnvOptions, GameOptions, SharedOptions, docstring_arguments
from foosball_gym.registration import (
    ENVS,
    check_env_options,
    env_class,
    make_task,
    task_interface,
)

# The options whose default is the task's own, not the one every environment shares.
TASK_DEFAULTS = {"action_regularisation_weight", "opponent_prismatic_only", "stagnation_steps"}
SECTIONS = [
    "Description",
    "Action Space",
    "Observation Space",
    "Rewards",
    "Starting State",
    "Episode End",
    "Arguments",
    "Version History",
]


def first_steps(env: gym.Env, seed: int = 5, steps: int = 30) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    obs = [env.reset(seed=seed)[0]]
    for _ in range(steps):
        action = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        obs.append(env.step(action)[0])
    return obs


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_the_signature_lists_every_option_with_its_default(env_id):
    cls = env_class(env_id)
    params = inspect.signature(cls).parameters
    assert params, cls
    for name, p in params.items():
        assert p.kind is inspect.Parameter.KEYWORD_ONLY, name  # no **kwargs hides an option
        assert p.default is not inspect.Parameter.empty, name
        assert p.annotation is not inspect.Parameter.empty, name
    # Every option given its default makes the environment the id makes with none.
    every = gym.make(env_id, **{name: p.default for name, p in params.items()})
    plain = gym.make(env_id)
    try:
        assert every.observation_space == plain.observation_space
        for a, b in zip(first_steps(every), first_steps(plain)):
            np.testing.assert_array_equal(a, b)
    finally:
        every.close()
        plain.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_an_unknown_option_names_every_option_there_is(env_id):
    names = inspect.signature(env_class(env_id)).parameters
    for make in (
        lambda: gym.make(env_id, warp=3),
        lambda: task_interface(env_id, {"warp": 3}),
        lambda: check_env_options(env_id, {"warp": 3}),
    ):
        with pytest.raises(TypeError, match="has no option 'warp'; allowed: ") as err:
            make()
        allowed = str(err.value).split("allowed: ")[1]
        assert all(re.search(rf"\b{name}\b", allowed) for name in names)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_each_option_is_described_once_in_the_docstrings(env_id):
    cls = env_class(env_id)
    options = set(inspect.signature(cls).parameters)
    described = [
        name
        for klass in cls.__mro__
        if issubclass(klass, FoosballEnv)
        for names, _ in _entries(klass)
        for name in names
    ]
    assert sorted(described) == sorted(set(described)), "an option described twice"
    own = {name for names, _ in _entries(cls) for name in names}
    assert own <= options, own - options
    assert options <= set(described), options - set(described)
    assert set(cls.argument_docs()) >= options


def _entries(klass: type) -> list[tuple[list[str], str]]:
    return docstring_arguments(klass.__dict__.get("__doc__") or "")


def test_the_shared_docstring_describes_only_options_some_environment_takes():
    everyone = {
        name for entry in ENVS for name in inspect.signature(env_class(entry.id)).parameters
    }
    shared = {name for names, _ in _entries(FoosballEnv) for name in names}
    assert shared <= everyone, shared - everyone


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_the_docstring_has_gymnasiums_sections(env_id):
    doc = inspect.getdoc(env_class(env_id))
    assert re.findall(r"^## (.+)$", doc, flags=re.MULTILINE) == SECTIONS


def test_options_every_environment_shares_default_alike():
    signatures = [inspect.signature(env_class(entry.id)).parameters for entry in ENVS]
    shared = set.intersection(*(set(s) for s in signatures)) - TASK_DEFAULTS
    assert {"goal_reward", "shaping", "residual", "physics_hz"} <= shared
    for name in shared:
        assert len({repr(s[name].default) for s in signatures}) == 1, name
    # The simulator's own defaults: the table's numbers.
    physics = {name: signatures[0][name].default for name in ("physics_hz", "control_hz")}
    physics |= {n: signatures[0][n].default for n in ("contact_travel", "rolling_resistance")}
    assert physics == {
        "physics_hz": table.PHYSICS_HZ,
        "control_hz": table.CONTROL_HZ,
        "contact_travel": table.CONTACT_TRAVEL,
        "rolling_resistance": table.ROLLING_RESISTANCE,
    }


def test_the_physics_options_are_checked_before_a_world_is_built(monkeypatch):
    import foosball_gym.sim

    def no_world(*args, **kwargs):
        raise AssertionError("a world was built")

    gym.make("Foosball-Block-v0", physics_hz=480, control_hz=120).close()
    monkeypatch.setattr(foosball_gym.sim.TableSim, "__init__", no_world)
    for check in (
        lambda: gym.make("Foosball-Block-v0", physics_hz=250),
        lambda: check_env_options("Foosball-Block-v0", {"physics_hz": 250}),
    ):
        with pytest.raises(ValueError, match="whole multiple of control_hz"):
            check()


def test_the_shared_options_are_declared_once_with_their_types_and_defaults():
    """The typed declaration (what mypy and an editor read) and the defaults name the same
    options with the same types, and every environment's signature lists them all with those
    types and, but where its task says otherwise, those defaults."""
    declared = typing.get_type_hints(GameOptions)
    fields = {f.name: f for f in dataclasses.fields(SharedOptions)}
    assert list(declared) == [*list(fields)[1:], "opponent"]  # opponent: games only
    assert set(typing.get_type_hints(EnvOptions)) == set(declared) - {"opponent"}
    hints = typing.get_type_hints(SharedOptions)
    assert all(hints[name] == declared[name] for name in declared)
    for entry in ENVS:
        cls = env_class(entry.id)
        params = inspect.signature(cls).parameters
        two_player = entry.task().layout.opponent
        shared = [name for name in params if name in fields]
        assert shared == [n for n in fields if two_player or n != "opponent"], entry.id
        for name in shared:
            assert params[name].default == getattr(cls.defaults, name), (entry.id, name)
            if two_player or name != "opponent_prismatic_only":
                assert params[name].annotation == declared[name], (entry.id, name)
        own = inspect.signature(cls.__init__).parameters
        assert not set(own) & set(fields), "a shared option written out again"
        # A user's subclass lists them as its base does.
        assert inspect.signature(type("Mine", (cls,), {})) == inspect.signature(cls)


@pytest.mark.parametrize(
    "env_id, kwargs",
    [
        ("Foosball-Block-v0", {}),
        ("Foosball-Block-v0", {"speed_range": (2, 10), "bank_share": 0.5}),
        ("Foosball-Score-v0", {"ball_start": "incoming", "obstacles": True}),
        ("Foosball-KeeperVsKeeper-v0", {"continuous": True, "stagnation_steps": 0}),
        ("Foosball-FullGame-v0", {"opponent_prismatic_only": True}),
    ],
)
def test_the_real_table_builds_the_task_the_environment_plays(env_id, kwargs):
    task, options = make_task(env_id, kwargs)
    env = gym.make(env_id, **kwargs)
    try:
        assert type(task) is type(env.unwrapped.task)
        assert vars(task) == vars(env.unwrapped.task)
        assert options["stagnation_steps"] == env.unwrapped.game.stagnation_steps
    finally:
        env.close()


@pytest.mark.parametrize("entry", ENVS, ids=lambda e: e.id)
def test_a_task_and_its_environment_give_its_options_the_same_defaults(entry):
    # The task's keyword arguments are the environment's too, each written in both signatures:
    # a default changed in one place only would make a task built without its environment
    # (Task(), as the PettingZoo games and scripts do) another task.
    env_defaults = env_class(entry.id).option_defaults()
    task_params = inspect.signature(entry.task).parameters
    assert task_params, entry.task
    for name, p in task_params.items():
        assert name in env_defaults, name
        assert p.default == env_defaults[name], name


def test_gymnasium_registers_the_table():
    assert ENV_IDS == tuple(entry.id for entry in ENVS)
    for entry in ENVS:
        spec = gym.spec(entry.id)
        assert (spec.entry_point, spec.max_episode_steps) == (entry.env, entry.max_episode_steps)
        cls = env_class(entry.id)
        assert issubclass(cls, FoosballEnv)
        # The class is where the docs site finds it: foosball_gym.envs.<module>.<Class>.
        assert entry.env == f"{cls.__module__}:{cls.__name__}"
        assert cls.__module__.startswith("foosball_gym.envs.")
