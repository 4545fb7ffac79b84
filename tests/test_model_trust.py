"""Loading a model unpickles nothing unless trusted: a planted pickle never runs silently."""

from __future__ import annotations

import base64
import json
import pickle
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

import torch as th  # noqa: E402

from foosball_gym.cli import main  # noqa: E402
from foosball_gym.training.config import TrainConfig  # noqa: E402
from foosball_gym.training.loading import ModelLoadError, load_policy  # noqa: E402
from foosball_gym.training.loading.sb3_snapshot import PolicySnapshot  # noqa: E402
from foosball_gym.training.run_dir.storage import (  # noqa: E402
    ZIP_RECORD,
    statistics_beside,
    zip_statistics,
)
from foosball_gym.training.sb3.trainer import train  # noqa: E402

CHECKPOINT = "checkpoints/model_0000000128"


class Plant:
    """Unpickled, it writes ``marker``: what a crafted model file could do instead."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return exec, (f"open({str(self.marker)!r}, 'w').write('ran')",)


def planted(marker: Path) -> bytes:
    return pickle.dumps(Plant(marker))


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    run = tmp_path_factory.mktemp("trust") / "run"
    config = TrainConfig(
        "Foosball-Block-v0",
        timesteps=128,
        n_envs=1,
        n_steps=64,
        batch_size=64,
        n_epochs=1,
        eval_freq=10_000,
        eval_episodes=1,
        checkpoint_freq=64,
    )
    train(config, run)
    return run


@pytest.fixture
def run(trained, tmp_path):
    """A run as it was written before its statistics went into its zips."""
    return statistics_beside_zips(trained, tmp_path / "run")


def statistics_beside_zips(run: Path, dst: Path) -> Path:
    """``run`` as runs were written before the statistics went into the model zips: a
    ``vecnormalize.json`` beside each zip, named by ``checkpoints/latest.json`` for the last
    checkpoint."""
    shutil.copytree(run, dst)
    for path in sorted(dst.rglob("*.zip")):
        recorded, stats = zip_statistics(path)
        assert recorded
        with zipfile.ZipFile(path) as archive:
            entries = {n: archive.read(n) for n in archive.namelist() if n != ZIP_RECORD}
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
            for n, c in entries.items():
                archive.writestr(n, c)
        if stats is not None:
            stats.save(statistics_beside(path)[-1])
    pointer = dst / "checkpoints" / "latest.json"
    data = json.loads(pointer.read_text())
    data["vecnormalize"] = data["model"].replace(".zip", "_vecnormalize.json")
    pointer.write_text(json.dumps(data))
    return dst


def zip_data(path: Path) -> dict:
    with zipfile.ZipFile(path) as archive:
        return json.loads(archive.read("data"))


def rewrite_zip(path: Path, name: str, content: bytes) -> None:
    with zipfile.ZipFile(path) as archive:
        entries = {n: archive.read(n) for n in archive.namelist()}
    entries[name] = content
    with zipfile.ZipFile(path, "w") as archive:
        for n, c in entries.items():
            archive.writestr(n, c)


def test_a_new_run_stores_no_pickle(trained):
    assert not list(trained.rglob("*.pkl"))
    zips = list(trained.rglob("*.zip"))
    assert len(zips) >= 3  # final, best, checkpoints
    for path in zips:
        data = zip_data(path)
        assert not [k for k, v in data.items() if isinstance(v, dict) and ":serialized:" in v]
        recorded, stats = zip_statistics(path)
        assert recorded and len(stats.obs_mean) == 6 and stats.obs_count > 0, path
    # Nothing beside the zips to disagree with them.
    assert not list(trained.rglob("*vecnormalize*"))


def test_a_legacy_normalisation_pickle_is_refused_and_read_only_when_trusted(run, tmp_path):
    marker = tmp_path / "ran"
    (run / "vecnormalize.json").unlink()
    (run / "vecnormalize.pkl").write_bytes(planted(marker))
    with pytest.raises(ModelLoadError, match="pickle.*foosball migrate .* --trust-model"):
        load_policy(run)
    assert not marker.exists()
    # The plant is live: trusting the file runs it (and the loader then finds no statistics).
    with pytest.raises(ModelLoadError):
        load_policy(run, trust=True)
    assert marker.exists()


def test_a_pickle_beside_the_plain_statistics_is_never_read(run, tmp_path):
    marker = tmp_path / "ran"
    (run / "vecnormalize.pkl").write_bytes(planted(marker))
    (run / "checkpoints" / "model_0000000128_vecnormalize.pkl").write_bytes(planted(marker))
    load_policy(run)
    load_policy(run / f"{CHECKPOINT}.zip")
    assert not marker.exists()


def test_a_checkpoint_s_legacy_statistics_are_refused(run, tmp_path):
    marker = tmp_path / "ran"
    (run / f"{CHECKPOINT}_vecnormalize.json").unlink()
    (run / f"{CHECKPOINT}_vecnormalize.pkl").write_bytes(planted(marker))
    with pytest.raises(ModelLoadError, match="--trust-model"):
        load_policy(run / f"{CHECKPOINT}.zip")
    assert not marker.exists()


def test_the_pickled_fields_of_a_model_zip_are_not_evaluated(run, tmp_path):
    from stable_baselines3.common.save_util import json_to_data

    marker = tmp_path / "ran"
    data = zip_data(run / "model.zip")
    data["observation_space"][":serialized:"] = base64.b64encode(planted(marker)).decode()
    rewrite_zip(run / "model.zip", "data", json.dumps(data).encode())
    before = load_policy(run)
    assert not marker.exists()
    assert before.policy.observation_size == 6
    json_to_data(json.dumps(data))  # what SB3's own load would do: it runs the plant
    assert marker.exists()


@pytest.mark.parametrize("entry", ["policy.pth", "pytorch_variables.pth"])
def test_a_weights_entry_holding_an_object_is_refused(run, tmp_path, entry):
    marker = tmp_path / "ran"
    buffer = tmp_path / "entry.pth"
    th.save({"weights": Plant(marker)}, buffer)
    rewrite_zip(run / "model.zip", entry, buffer.read_bytes())
    with pytest.raises(ModelLoadError, match="cannot read"):
        load_policy(run)
    assert not marker.exists()


def test_a_pickled_self_play_snapshot_is_refused_unless_trusted(tmp_path):
    marker = tmp_path / "ran"
    path = tmp_path / "selfplay" / "opponent_0000.pt"
    path.parent.mkdir()
    th.save({"policy": Plant(marker), "obs_mean": None}, path)
    with pytest.raises(ValueError, match="--trust-model"):
        PolicySnapshot.load(path)
    assert not marker.exists()
    with pytest.raises(Exception):  # noqa: B017 - what the plant leaves behind is no snapshot
        PolicySnapshot.load(path, trust=True)
    assert marker.exists()


def test_the_cli_refuses_a_planted_run_with_exit_2_and_says_how_to_migrate(run, tmp_path, capsys):
    marker = tmp_path / "ran"
    (run / "vecnormalize.json").unlink()
    (run / "vecnormalize.pkl").write_bytes(planted(marker))
    with pytest.raises(SystemExit) as exit_info:
        main(["eval", str(run), "--episodes", "1"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "--trust-model" in err and "foosball migrate" in err and "Traceback" not in err
    assert not marker.exists()


def test_resuming_refuses_a_planted_checkpoint(run, tmp_path, capsys):
    marker = tmp_path / "ran"
    (run / "model.zip").unlink()
    (run / f"{CHECKPOINT}_vecnormalize.json").unlink()
    (run / f"{CHECKPOINT}_vecnormalize.pkl").write_bytes(planted(marker))
    pointer = json.loads((run / "checkpoints" / "latest.json").read_text())
    pointer["vecnormalize"] = "model_0000000128_vecnormalize.pkl"
    (run / "checkpoints" / "latest.json").write_text(json.dumps(pointer))
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "--resume", str(run), "--no-progress"])
    assert exit_info.value.code == 2
    assert "--trust-model" in capsys.readouterr().err
    assert not marker.exists()


def legacy_copy(run: Path, dst: Path) -> Path:
    """``run`` as a run from before plain files wrote it: VecNormalize's pickles."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    from foosball_gym.training.run_dir.storage import NormStats

    statistics_beside_zips(run, dst)
    venv = VecNormalize(make_vec_env("Foosball-Block-v0", n_envs=1))
    for path in sorted(dst.rglob("*vecnormalize.json")):
        NormStats.load(path).apply(venv)
        venv.save(str(path.with_name(path.name.replace(".json", ".pkl"))))
        path.unlink()
    venv.close()
    pointer = dst / "checkpoints" / "latest.json"
    data = json.loads(pointer.read_text())
    data["vecnormalize"] = data["vecnormalize"].replace(".json", ".pkl")
    pointer.write_text(json.dumps(data))
    return dst


def test_migrating_a_trusted_legacy_run_keeps_its_actions(trained, tmp_path, capsys):
    old = legacy_copy(trained, tmp_path / "old")
    with pytest.raises(ModelLoadError, match="foosball migrate"):
        load_policy(old)
    trusted = load_policy(old, trust=True).policy
    with pytest.raises(SystemExit) as exit_info:
        main(["migrate", str(old)])
    assert exit_info.value.code == 2 and "--trust-model" in capsys.readouterr().err
    assert main(["migrate", str(old), "--trust-model"]) == 0
    assert not list(old.rglob("*.pkl"))
    migrated = load_policy(old).policy
    obs = np.random.default_rng(0).normal(size=(64, 6))
    np.testing.assert_array_equal(migrated(obs), trusted(obs))
    # A migrated run resumes like a new one.
    (old / "model.zip").unlink()
    assert main(["train", "--resume", str(old), "--no-progress"]) == 0


def test_the_training_package_exports_load_policy_with_trust_off_by_default():
    import inspect

    from foosball_gym.training import load_policy as exported

    assert exported is load_policy
    assert inspect.signature(exported).parameters["trust"].default is False
