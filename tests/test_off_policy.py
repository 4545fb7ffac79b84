"""Off-policy runs (SAC, CrossQ) train, evaluate, and resume with the replay buffer they had, not
from an empty one."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3.common.buffers import ReplayBuffer  # noqa: E402

from foosball_gym.cli import main  # noqa: E402
from foosball_gym.training.sb3.replay import FIELDS, restore_replay, save_replay  # noqa: E402

# A small run, a checkpoint every 100 steps.
SMALL = ["--n-envs", "2", "--checkpoint-freq", "100", "--batch-size", "32"]
SMALL += ["--lr-schedule", "constant", "--eval-freq", "100000", "--eval-episodes", "1"]
SMALL += ["--no-progress"]


def train(*argv: str, algo: str = "sac") -> int:
    return main(["train", "Foosball-Block-v0", *argv, "--algo", algo, *SMALL])


def small_buffer(size: int = 64, n_envs: int = 2) -> ReplayBuffer:
    space = gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
    return ReplayBuffer(size, space, gym.spaces.Box(-1.0, 1.0, (2,), np.float32), n_envs=n_envs)


def fill(buffer: ReplayBuffer, adds: int, seed: int = 0) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(adds):
        obs, next_obs = rng.normal(size=(2, 3)), rng.normal(size=(2, 3))
        done = rng.random(2) < 0.2
        infos = [{"TimeLimit.truncated": bool(d and rng.random() < 0.5)} for d in done]
        buffer.add(obs, next_obs, rng.normal(size=(2, 2)), rng.normal(size=2), done, infos)


@pytest.mark.parametrize("adds", [5, 45])  # part of the buffer's 32 rows; past its end
def test_a_buffer_comes_back_as_it_was_written(tmp_path, adds):
    buffer = small_buffer()
    fill(buffer, adds)
    save_replay(buffer, tmp_path / "replay.pt")
    restored = small_buffer()
    assert restore_replay(restored, tmp_path / "replay.pt") == min(adds, 32) * 2
    assert (restored.pos, restored.full) == (buffer.pos, buffer.full) == (adds % 32, adds >= 32)
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(restored, name), getattr(buffer, name))


def test_a_buffer_that_does_not_fit_the_run_is_refused_with_what_differs(tmp_path):
    buffer = small_buffer()
    fill(buffer, 3)
    save_replay(buffer, tmp_path / "replay.pt")
    with pytest.raises(ValueError, match="buffer_size 32, where the run's buffer has 64"):
        restore_replay(small_buffer(size=128), tmp_path / "replay.pt")
    (tmp_path / "other.pt").write_bytes(b"not a buffer")
    with pytest.raises(ValueError, match="other.pt is not a replay buffer this run wrote") as e:
        restore_replay(small_buffer(), tmp_path / "other.pt")
    assert "\n" not in str(e.value) and "weights_only" not in str(e.value)  # one line, no advice


@pytest.mark.parametrize("algo", ["sac", "crossq"])
def test_a_resumed_run_goes_on_with_its_replay_buffer(tmp_path, capsys, algo):
    run = tmp_path / "run"
    assert train("--timesteps", "200", "--out", str(run), algo=algo) == 0
    # One buffer, the last checkpoint's: each is as large as the experience it holds.
    kept = [p.name for p in (run / "checkpoints").glob("replay_*.pt")]
    assert kept == ["replay_0000000200.pt"]
    capsys.readouterr()
    assert main(["train", "--resume", str(run), "--timesteps", "300", "--no-progress"]) == 0
    assert "with the 200 transitions of its replay buffer" in capsys.readouterr().out
    kept = [p.name for p in (run / "checkpoints").glob("replay_*.pt")]
    assert kept == ["replay_0000000300.pt"]


def test_a_checkpoint_from_before_buffers_were_kept_says_it_starts_empty(tmp_path, capsys):
    run = tmp_path / "run"
    assert train("--timesteps", "100", "--out", str(run)) == 0
    latest = run / "checkpoints" / "latest.json"
    latest.write_text(latest.read_text().replace(', "replay": "replay_0000000100.pt"', ""))
    capsys.readouterr()
    assert main(["train", "--resume", str(run), "--timesteps", "200", "--no-progress"]) == 0
    assert "SAC goes on from an empty one" in capsys.readouterr().out


def test_a_crossq_run_is_evaluated_by_its_folder(tmp_path, capsys):
    run = tmp_path / "run"
    assert train("--timesteps", "200", "--out", str(run), algo="crossq") == 0
    assert main(["eval", str(run), "--episodes", "2", "--seed", "3"]) == 0
    assert "episodes             2 (seeds 3..4)" in capsys.readouterr().out
