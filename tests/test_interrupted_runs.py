"""A run stopped before its end (Ctrl-C) has no final model.zip: ``foosball eval`` and
``foosball play`` given its folder play its best model, else its newest checkpoint, and say
which in one line."""

from __future__ import annotations

import json
import os
import shutil
import signal
from importlib.util import find_spec

import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3.common.callbacks import BaseCallback  # noqa: E402

from foosball_gym.cli import main  # noqa: E402
from foosball_gym.training.config import TrainConfig  # noqa: E402
from foosball_gym.training.sb3.trainer import train  # noqa: E402

needs_hardware = pytest.mark.skipif(
    any(find_spec(m) is None for m in ("can", "canopen", "cv2", "yaml")),
    reason='needs python-can, canopen, OpenCV and PyYAML: pip install -e ".[hardware]"',
)


class CtrlC(BaseCallback):
    """Presses Ctrl-C once, at the first step at or past ``steps``."""

    def __init__(self, steps: int) -> None:
        super().__init__()
        self.steps, self.done = steps, False

    def _on_step(self) -> bool:
        if not self.done and self.num_timesteps >= self.steps:
            self.done = True
            os.kill(os.getpid(), signal.SIGINT)
        return True


@pytest.fixture(scope="module")
def stopped(tmp_path_factory):
    """A run stopped by Ctrl-C at 300 of its 1024 steps: evaluated at 128 and 256 steps (its
    best/), checkpoints at 256 and where it stopped, no model.zip."""
    run = tmp_path_factory.mktemp("stopped") / "run"
    config = TrainConfig(
        "Foosball-Block-v0",
        timesteps=1024,
        n_envs=1,
        n_steps=64,
        batch_size=64,
        n_epochs=1,
        eval_freq=128,
        eval_episodes=1,
        checkpoint_freq=256,
    )
    result = train(config, run, callbacks=[CtrlC(300)])
    assert result.signal == signal.SIGINT and 256 < result.timesteps < 320
    assert not (run / "model.zip").exists() and (run / "best" / "model.zip").is_file()
    return run


def eval_of(run, tmp_path, capsys) -> tuple[list[str], dict]:
    out = tmp_path / "eval.json"
    assert main(["eval", str(run), "--episodes", "2", "--json", str(out)]) == 0
    return capsys.readouterr().out.splitlines(), json.loads(out.read_text())


def test_eval_of_a_stopped_run_plays_its_best_model_and_says_so(stopped, tmp_path, capsys):
    lines, result = eval_of(stopped, tmp_path, capsys)
    best = json.loads((stopped / "best" / "best.json").read_text())
    assert lines[0] == (
        f"{stopped} has no model.zip: playing its best model, {stopped}/best/model.zip "
        f"(success {best['success_rate']:.0%} at {best['timesteps']:,} steps)"
    )
    assert result["policy"] == f"{stopped}/best/model.zip"
    assert result["env_id"] == "Foosball-Block-v0"  # its run's config.json, one level up


def test_eval_of_a_stopped_run_without_a_best_model_plays_its_newest_checkpoint(
    stopped, tmp_path, capsys
):
    run = tmp_path / "run"
    shutil.copytree(stopped, run)
    shutil.rmtree(run / "best")
    latest = json.loads((run / "checkpoints" / "latest.json").read_text())
    newest = run / "checkpoints" / f"model_{latest['timesteps']:010d}.zip"
    assert latest["timesteps"] > 256 and newest.is_file()  # the one Ctrl-C wrote
    lines, result = eval_of(run, tmp_path, capsys)
    assert lines[0] == (
        f"{run} has no model.zip nor best/model.zip: playing its newest checkpoint, {newest}"
    )
    assert result["policy"] == str(newest)


@needs_hardware
def test_play_of_a_stopped_run_plays_its_best_model_and_says_so(stopped, capsys):
    argv = ["play", str(stopped), "--table", "sim", "--episodes", "1", "--camera", "320x180"]
    assert main([*argv, "--no-status", "--lockstep"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(
        f"{stopped} has no model.zip: playing its best model, {stopped}/best/model.zip"
    )
    assert "1 episodes of Foosball-Block-v0" in out


def test_a_folder_with_no_model_at_all_is_refused_in_one_line(stopped, tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(stopped / "config.json", run)
    with pytest.raises(SystemExit) as exit_info:
        main(["eval", str(run)])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.splitlines() == [
        f"foosball eval: error: {run} is a directory without model.zip, best/model.zip or a "
        "checkpoint: not a run of foosball_gym, nor an RL Zoo run (<env>/args.yml), nor an "
        "exported RLlib policy"
    ]
