"""Minari datasets: ``foosball dataset`` records play that loads back and replays exactly, and
Minari's own recorder takes every environment with its infos."""

from __future__ import annotations

import json
from importlib.util import find_spec

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import ENV_IDS
from foosball_gym.cli import main
from foosball_gym.registration import scripted_policy

minari = pytest.importorskip("minari")
needs_train = pytest.mark.skipif(
    find_spec("stable_baselines3") is None or find_spec("torch") is None,
    reason='needs the train extra: pip install -e ".[train]"',
)

BLOCK = "Foosball-Block-v0"
DATASET = "foosball/block/scripted-v0"


@pytest.fixture
def datasets(tmp_path, monkeypatch):
    """A folder of Minari's datasets of the test's own, as Minari finds it by default."""
    root = tmp_path / "datasets"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    return root


def record(root, *extra: str, episodes: int = 3, seed: int = 7, dataset: str = DATASET) -> int:
    argv = ["dataset", "--policy", "scripted", BLOCK, "--dataset-id", dataset]
    argv += ["--episodes", str(episodes), "--seed", str(seed), "--data-path", str(root)]
    return main([*argv, *extra])


def episode_seeds(dataset) -> list[int]:
    ids = list(dataset.episode_indices)
    return [int(m["seed"]) for m in dataset.storage.get_episode_metadata(ids)]


def assert_replays(dataset, policy=None) -> None:
    """Every episode of ``dataset`` is what its environment, made again from the dataset,
    gives for the episode's seed and actions, infos included; with ``policy``, its actions are
    the policy's."""
    env = dataset.recover_environment()
    try:
        for episode, seed in zip(dataset.iterate_episodes(), episode_seeds(dataset)):
            obs, info = env.reset(seed=seed)
            infos = [info]
            np.testing.assert_array_equal(episode.observations[0], obs)
            for t, action in enumerate(episode.actions):
                if policy is not None:
                    expected = np.clip(np.asarray(policy(obs), np.float32), -1, 1)
                    np.testing.assert_array_equal(action, expected)
                obs, reward, terminated, truncated, info = env.step(action)
                infos.append(info)
                np.testing.assert_array_equal(episode.observations[t + 1], obs)
                assert episode.rewards[t] == reward
                assert (episode.terminations[t], episode.truncations[t]) == (terminated, truncated)
            assert terminated or truncated  # whole episodes only
            assert_columns(episode.infos, infos)
    finally:
        env.close()


def assert_columns(stored: dict, infos: list[dict]) -> None:
    """Minari's columns of infos (a dict's keys nested alike) hold each step's values."""
    assert set(stored) == set(infos[0])
    for key, values in stored.items():
        if isinstance(values, dict):
            assert_columns(values, [info[key] for info in infos])
        else:
            assert list(values) == [info[key] for info in infos], key


def test_foosball_dataset_records_seeded_episodes_that_minari_loads_and_replays(datasets, capsys):
    assert record(datasets, "--author", "A. Keeper", "--description", "three blocks") == 0
    out = capsys.readouterr().out
    assert out.startswith("recorded 3 episodes (")
    assert f'minari.load_dataset("{DATASET}") with MINARI_DATASETS_PATH={datasets}' in out
    dataset = minari.load_dataset(DATASET)
    assert dataset.total_episodes == 3 and episode_seeds(dataset) == [7, 8, 9]
    assert dataset.spec.env_spec.id == BLOCK and dataset.spec.env_spec.kwargs == {}
    assert_replays(dataset, scripted_policy(BLOCK))
    metadata = dataset.storage.metadata
    assert metadata["author"] == {"A. Keeper"} and metadata["description"] == "three blocks"
    assert metadata["algorithm_name"] == "scripted"
    assert minari.list_local_datasets().keys() == {DATASET}  # nothing else left beside it


def test_a_dataset_keeps_the_environments_options_and_randomised_dynamics(datasets, capsys):
    options = ["--env-kwarg", "ball_start=incoming", "--env-kwarg", "ball_mass_range=(0.02,0.03)"]
    argv = ["dataset", "--policy", "scripted", "Foosball-Score-v0", "--episodes", "2"]
    argv += ["--dataset-id", "foosball/score/incoming-v1", *options]
    assert main(argv) == 0  # into MINARI_DATASETS_PATH, Minari's own place
    dataset = minari.load_dataset("foosball/score/incoming-v1")
    kwargs = {"ball_start": "incoming", "ball_mass_range": [0.02, 0.03]}
    assert dataset.spec.env_spec.kwargs == kwargs
    episode = next(dataset.iterate_episodes())
    masses = episode.infos["dynamics"]["ball_mass"]
    assert len(masses) == len(episode.actions) + 1 and len(set(masses)) == 1
    assert_replays(dataset, scripted_policy("Foosball-Score-v0", kwargs))
    assert "Foosball-Score-v0 with ball_start='incoming'" in dataset.storage.metadata["description"]


@needs_train
def test_foosball_dataset_records_a_learned_model(datasets, capsys):
    from foosball_gym import load_policy

    argv = ["dataset", "builtin:block", "--dataset-id", "foosball/block/learned-v0"]
    assert main([*argv, "--episodes", "2", "--seed", "3"]) == 0
    dataset = minari.load_dataset("foosball/block/learned-v0")
    assert dataset.storage.metadata["algorithm_name"] == "builtin:block"
    policy = load_policy("builtin:block")
    # The environment the model was trained on, which it plays by default.
    assert dataset.spec.env_spec.kwargs == json.loads(json.dumps(policy.env_kwargs))
    assert_replays(dataset, policy)


def test_an_existing_dataset_is_replaced_only_when_asked_and_only_once_recorded(datasets, capsys):
    from foosball_gym.datasets import record_dataset

    assert record(datasets, episodes=2) == 0
    with pytest.raises(SystemExit) as exit_info:
        record(datasets, episodes=1)
    assert exit_info.value.code == 2
    assert "exists already" in capsys.readouterr().err
    assert minari.load_dataset(DATASET).total_episodes == 2

    keeper = scripted_policy(BLOCK)
    calls = []

    def fails_midway(obs):
        calls.append(obs)
        if len(calls) == 100:
            raise RuntimeError("the policy broke")
        return keeper(obs)

    with pytest.raises(RuntimeError, match="the policy broke"):
        record_dataset(fails_midway, BLOCK, DATASET, episodes=3, overwrite=True)
    assert minari.load_dataset(DATASET).total_episodes == 2  # the old one, whole
    assert [p.name for p in datasets.iterdir()] == ["foosball"]  # no half-made recording

    assert record(datasets, "--force", episodes=1) == 0
    assert minari.load_dataset(DATASET).total_episodes == 1
    assert sorted(p.name for p in (datasets / "foosball" / "block").iterdir()) == [
        "namespace_metadata.json",
        "scripted-v0",
    ]


def test_a_folder_that_is_not_a_dataset_is_never_replaced(datasets, capsys):
    kept = datasets / "foosball" / "block" / "scripted-v0" / "notes.txt"
    kept.parent.mkdir(parents=True)
    kept.write_text("mine")
    with pytest.raises(SystemExit) as exit_info:
        record(datasets, "--force", episodes=1)
    assert exit_info.value.code == 2
    assert "is not a Minari dataset" in capsys.readouterr().err
    assert kept.read_text() == "mine"


@pytest.mark.parametrize(
    "argv, message",
    [
        (
            ["--policy", "scripted", "Foosball-Nothing-v0", "--dataset-id", "ab/c-v0"],
            "unknown environment 'Foosball-Nothing-v0'",
        ),
        (
            ["--policy", "scripted", BLOCK, "--dataset-id", "ab/c-v0", "--episodes", "0"],
            "argument --episodes: must be at least 1, got 0",
        ),
        (
            ["--policy", "scripted", BLOCK, "--dataset-id", "ab/c-v0", "--episodes", "two"],
            "argument --episodes: expected a whole number, got 'two'",
        ),
        (
            ["--policy", "scripted", BLOCK, "--dataset-id", "ab/c-v0", "--seed", "-1"],
            "argument --seed: must be 0 or more",
        ),
        (
            ["--policy", "scripted", BLOCK, "--dataset-id", "block-scripted"],
            "a dataset id is NAMESPACE/NAME-vN",
        ),
        (
            ["--policy", "scripted", BLOCK, "--dataset-id", "foosball/" + "b" * 300 + "-v0"],
            "of at most 200 characters; bbbbbbbbbbbbbbbbbbbb... has 303",
        ),
        (["--policy", "scripted", BLOCK], "the following arguments are required: --dataset-id"),
        (
            ["--policy", "scripted", BLOCK, "--dataset-id", "ab/c-v0", "--env-kwarg", "warp=3"],
            "has no option 'warp'",
        ),
        (
            ["--policy", "scripted", BLOCK, "--dataset-id", "ab/c-v0", "--env", BLOCK],
            "--env is for a MODEL",
        ),
        (
            ["--policy", "scripted", BLOCK, "--dataset-id", "ab/c-v0", "--data-path", "/dev/null"],
            "--data-path /dev/null: /dev/null is a file, not a folder",
        ),
        pytest.param(
            ["builtin:block", "--env", "Foosball-Score-v0", "--dataset-id", "ab/c-v0"],
            "expects observations of size 6 of Foosball-Block-v0, but Foosball-Score-v0 gives 8",
            marks=needs_train,
        ),
    ],
)
def test_a_bad_input_exits_with_status_2_and_one_line_naming_it(argv, message, datasets, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["dataset", *argv])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if ": error: " in line]
    assert len(errors) == 1 and message in errors[0], err
    assert errors[0].startswith("foosball dataset") and "Traceback" not in err
    assert not datasets.exists() or not any(datasets.iterdir())


def test_options_a_dataset_cannot_keep_are_refused_before_recording(datasets):
    from foosball_gym.datasets import record_dataset

    game = "Foosball-KeeperVsKeeper-v0"
    with pytest.raises(ValueError, match="not plain data"):
        record_dataset(scripted_policy(game), game, "ab/c-v0", {"opponent": lambda obs: [0, 0]})
    assert not datasets.exists() or not any(datasets.iterdir())


def test_without_the_datasets_extra_the_command_names_it(datasets, capsys, monkeypatch):
    import foosball_gym.datasets as module

    real = module.find_spec
    monkeypatch.setattr(module, "find_spec", lambda name: None if name == "jax" else real(name))
    with pytest.raises(SystemExit) as exit_info:
        record(datasets)
    assert exit_info.value.code == 2
    assert 'pip install -e ".[datasets]"' in capsys.readouterr().err


def test_dataset_help_says_how_to_load_what_it_records(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["dataset", "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    for option in ("--policy", "--dataset-id", "--episodes", "--seed", "--env-kwarg"):
        assert option in out, option
    for option in ("--data-path", "--author", "--description", "--force"):
        assert option in out, option
    assert "minari.load_dataset" in " ".join(out.split())
    assert "(100)" in out  # the library's default episode count


# Minari's advice for datasets to be published.
@pytest.mark.filterwarnings("ignore:`\\w+` is set to None")
@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("kwargs", [{}, {"drive_gain_range": (0.9, 1.1)}], ids=["", "randomised"])
def test_minaris_recorder_records_every_environment_with_its_infos(env_id, kwargs, datasets):
    collector = minari.DataCollector(gym.make(env_id, **kwargs), record_infos=True)
    try:
        for seed in (0, 1):
            _, info = collector.reset(seed=seed)
            for _ in range(4):
                collector.step(collector.action_space.sample())
        dataset = collector.create_dataset(
            "foosball/recorder-v0", algorithm_name="random", author="tests", description="-"
        )
    finally:
        collector.close()
    assert dataset.total_episodes == 2 and dataset.total_steps == 8
    episode = next(dataset.iterate_episodes())
    assert set(episode.infos) == set(info)
    assert all(len(v) == 5 for k, v in episode.infos.items() if k != "dynamics")
    if kwargs:
        assert episode.infos["dynamics"]["drive_gain"].shape == (5,)
