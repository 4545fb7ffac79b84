"""Runs record the physics they were trained on; a model met with other physics warns."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import warnings
from importlib import metadata
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")

import foosball_gym  # noqa: E402
from foosball_gym.cli import main  # noqa: E402
from foosball_gym.table import PHYSICS_REVISION  # noqa: E402
from foosball_gym.training.config import TrainConfig  # noqa: E402
from foosball_gym.training.loading import (  # noqa: E402
    PhysicsMismatchWarning,
    UnknownPhysicsWarning,
    load_policy,
)
from foosball_gym.training.run_dir.physics import physics_record  # noqa: E402
from foosball_gym.training.sb3.trainer import train  # noqa: E402

CHECKPOINT = "checkpoints/model_0000000128.zip"


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A run of two PPO updates on the current physics, and the configuration it ran with."""
    run = tmp_path_factory.mktemp("physics") / "run"
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
    return run, config


def copy_with_record(run: Path, dst: Path, record: str) -> Path:
    """A copy of ``run`` whose config.json says ``record``: "current", "revision 1" or "none"
    (a run from before the record was kept)."""
    shutil.copytree(run, dst)
    config = json.loads((dst / "config.json").read_text())
    if record == "revision 1":
        config["physics"]["revision"] = 1
    elif record == "none":
        del config["physics"]
    (dst / "config.json").write_text(json.dumps(config, indent=2))
    return dst


def test_a_new_run_records_the_physics_it_was_trained_on(trained):
    run, config = trained
    saved = json.loads((run / "config.json").read_text())
    assert saved["physics"] == {
        "revision": PHYSICS_REVISION,
        "package_version": foosball_gym.__version__,
        "pybullet": metadata.version("pybullet"),
    }
    assert saved["physics"] == physics_record()
    # The record sits beside the configuration without becoming part of it.
    assert TrainConfig.load(run / "config.json") == config


@pytest.mark.parametrize("target", [".", CHECKPOINT])
def test_a_model_trained_on_the_current_physics_loads_without_a_warning(trained, target):
    run, _ = trained
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysicsMismatchWarning)
        load_policy(run / target)


@pytest.mark.parametrize("target", [".", CHECKPOINT])
@pytest.mark.parametrize("record", ["revision 1", "none"])
def test_a_model_trained_on_older_physics_warns_naming_both_revisions(
    trained, tmp_path, record, target
):
    run = copy_with_record(trained[0], tmp_path / "old", record)
    spec = run / target
    with pytest.warns(PhysicsMismatchWarning) as caught:
        loaded = load_policy(spec)
    assert loaded.env_id == "Foosball-Block-v0"  # the warning does not stop the model loading
    assert len(caught) == 1
    message = str(caught[0].message)
    assert str(spec) in message
    assert "revision 1" in message and f"revision {PHYSICS_REVISION}" in message
    assert "may differ" in message and "Retraining" in message


def test_a_bare_model_zip_s_revision_is_unknown_not_the_first(trained, tmp_path):
    # A zip with no run's config.json beside it may come from anywhere, from today's physics
    # as well: no revision is claimed for it.
    bare = tmp_path / "bare" / "model.zip"
    bare.parent.mkdir()
    shutil.copy(trained[0] / "model.zip", bare)
    with pytest.warns(UnknownPhysicsWarning) as caught:
        load_policy(bare)
    assert len(caught) == 1
    message = str(caught[0].message)
    assert str(bare) in message and "unknown" in message
    assert f"revision {PHYSICS_REVISION}" in message and "revision 1" not in message


@pytest.mark.parametrize("record", ["current", "revision 1", "none"])
def test_resuming_warns_on_other_physics_and_keeps_the_run_s_record(trained, tmp_path, record):
    run = copy_with_record(trained[0], tmp_path / "run", record)
    before = (run / "config.json").read_text()
    (run / "model.zip").unlink()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert main(["train", "--resume", str(run), "--no-progress"]) == 0
    assert (run / "model.zip").exists()
    mismatches = [w for w in caught if issubclass(w.category, PhysicsMismatchWarning)]
    if record == "current":
        assert not mismatches
    else:
        assert len(mismatches) == 1
        message = str(mismatches[0].message)
        assert "revision 1" in message and f"revision {PHYSICS_REVISION}" in message
    # The model stays mostly trained on the physics the record names, so it keeps warning.
    assert (run / "config.json").read_text() == before


@pytest.mark.parametrize("command", ["eval", "play", "eval a bare zip"])
def test_the_cli_shows_the_warning_once(trained, tmp_path, command):
    if command == "play":
        pytest.importorskip("canopen")
    run = copy_with_record(trained[0], tmp_path / "old", "none")
    warning = "PhysicsMismatchWarning"
    if command == "eval a bare zip":
        (tmp_path / "bare").mkdir()
        run = Path(shutil.copy(run / "model.zip", tmp_path / "bare" / "model.zip"))
        command, warning = "eval", "UnknownPhysicsWarning: "
    args = {
        "eval": [
            "--env",
            "Foosball-Block-v0",
            "--episodes",
            "1",
            "--json",
            str(tmp_path / "e.json"),
        ],
        # Lock-step, so that a loaded machine cannot trip the real-time watchdog first.
        "play": ["--table", "sim", "--lockstep", "--episodes", "1", "--camera", "320x180"]
        + ["--no-status"],
    }[command]
    # A fresh interpreter with Python's default warning filters, as a user's shell runs it.
    env = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"}
    env["PYTHONPATH"] = str(Path(foosball_gym.__file__).resolve().parents[1])
    done = subprocess.run(
        [sys.executable, "-m", "foosball_gym.cli", command, str(run), *args],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr.count(warning) == 1, done.stderr
    assert f"revision {PHYSICS_REVISION}" in done.stderr
