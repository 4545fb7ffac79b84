"""A run's life: one training at a time in a run, a resume after a kill that sets aside what
was recorded past the checkpoint, a full or read-only disk told in one line with nothing left
behind, and Ctrl-C heard during an evaluation."""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3.common.callbacks import BaseCallback  # noqa: E402

import foosball_gym  # noqa: E402
import foosball_gym.training.run_dir.files as run_files  # noqa: E402
import foosball_gym.training.sb3.callbacks as sb3_callbacks  # noqa: E402
from foosball_gym.cli import main  # noqa: E402
from foosball_gym.evaluation import EvalResult  # noqa: E402
from foosball_gym.training.config import TrainConfig  # noqa: E402
from foosball_gym.training.run_dir.best import read_best  # noqa: E402
from foosball_gym.training.run_dir.curve import EVAL_FIELDS, EvalCurve, read_curve  # noqa: E402
from foosball_gym.training.run_dir.lock import RunInUseError, run_lock  # noqa: E402
from foosball_gym.training.sb3.trainer import train  # noqa: E402
from foosball_gym.training.selfplay.history import (  # noqa: E402
    read_history,
    set_aside_generations,
    snapshot_file,
)
from foosball_gym.training.signals import Interrupted, SignalStop  # noqa: E402

SMALL = ["--n-envs", "1", "--n-steps", "64", "--batch-size", "64", "--eval-episodes", "1"]
SMALL += ["--no-progress", "--lr-schedule", "constant"]  # a resume may extend the run


def tiny(env_id: str = "Foosball-Block-v0", **settings) -> TrainConfig:
    base = {"n_envs": 1, "n_steps": 64, "batch_size": 64, "n_epochs": 1, "eval_episodes": 1}
    base["lr_schedule"] = "constant"  # a resume may extend the run
    return TrainConfig(env_id, **{**base, **settings})


class At(BaseCallback):
    """Runs ``action`` once, at the first step at or past ``steps`` where ``ready()`` holds."""

    def __init__(self, steps: int, action, ready=lambda: True) -> None:
        super().__init__()
        self.steps, self.action, self.ready = steps, action, ready
        self.done = False

    def _on_step(self) -> bool:
        if not self.done and self.num_timesteps >= self.steps and self.ready():
            self.done = True
            self.action()
        return True


def killed():
    # What a kill leaves: the process gone at once, nothing more written. (KeyboardInterrupt
    # from a callback, not a signal, so no checkpoint is written on the way out.)
    raise KeyboardInterrupt


@pytest.fixture
def fixed_evaluations(monkeypatch):
    """Evaluations that play nothing and score 0: the tests are of the records."""

    def evaluate(policy, env_id, env_kwargs=None, episodes=100, seed=0, **kwargs):
        return EvalResult(
            env_id=env_id,
            env_kwargs={},
            policy="policy",
            opponent=None,
            episodes=episodes,
            seed=seed,
            successes=0,
            success_rate=0.0,
            ci_low=0.0,
            ci_high=0.1,
            goals_for=0,
            goals_against=episodes,
            mean_reward=-1000.0,
            std_reward=0.0,
            mean_length=50.0,
        )

    monkeypatch.setattr(sb3_callbacks, "evaluate", evaluate)


def steps_of(run: Path) -> list[int]:
    return [int(r["timesteps"]) for r in read_curve(run / "eval.csv")]


def one_line_refusal(argv: list[str], capsys) -> str:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    err = capsys.readouterr().err
    assert exit_info.value.code == 2, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err


# -- one training at a time --------------------------------------------------------------


def test_a_second_training_or_resume_into_a_run_is_refused_while_the_first_runs(
    tmp_path, capsys, fixed_evaluations
):
    run = tmp_path / "run"
    refusals = []

    def second_and_third():
        for argv in (
            ["train", "Foosball-Block-v0", "--out", str(run), "--seed", "1", *SMALL],
            ["train", "--resume", str(run), "--no-progress"],
        ):
            refusals.append(one_line_refusal(argv, capsys))

    result = train(
        tiny(timesteps=256, eval_freq=64, checkpoint_freq=64),
        run,
        callbacks=[At(130, second_and_third)],
    )
    assert len(refusals) == 2
    for err in refusals:
        assert "is being written by another training" in err and "train.lock" in err
    # The run is the first training's alone.
    assert result.timesteps == 256 and steps_of(run) == [64, 128, 192, 256]
    assert json.loads((run / "config.json").read_text())["seed"] == 0
    # Once it ended, the run is free.
    assert main(["train", "--resume", str(run), "--timesteps", "320", "--no-progress"]) == 0


HOLD = """
import os, signal, sys
from foosball_gym.training.run_dir.lock import run_lock
with run_lock(sys.argv[1]):
    print("held", flush=True)
    if sys.argv[2] == "die":
        os.kill(os.getpid(), signal.SIGKILL)
    sys.stdin.read()
"""


def holder(run: Path, how: str) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(Path(foosball_gym.__file__).resolve().parents[1])}
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(run), how],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert proc.stdout is not None and proc.stdout.readline() == "held\n"
    return proc


def test_a_lock_is_held_while_its_process_lives_and_never_after(tmp_path):
    run = tmp_path / "run"
    alive = holder(run, "wait")
    with pytest.raises(RunInUseError, match="another training"):
        with run_lock(run):
            pass
    assert alive.stdin is not None
    alive.stdin.close()
    assert alive.wait() == 0
    dead = holder(run, "die")
    assert dead.wait() == -signal.SIGKILL and (run / "train.lock").exists()
    with run_lock(run):  # the dead process's lock went with it
        pass


def test_a_new_folder_left_empty_by_its_training_is_removed(tmp_path):
    run = tmp_path / "new"
    with run_lock(run):
        assert run.is_dir()
    assert not run.exists()


# -- a resume after a kill ---------------------------------------------------------------


def test_a_resume_after_a_kill_sets_aside_what_was_recorded_past_the_checkpoint(
    tmp_path, capsys, fixed_evaluations
):
    run = tmp_path / "run"
    config = tiny(timesteps=640, eval_freq=64, checkpoint_freq=256)
    with pytest.raises(KeyboardInterrupt):
        train(config, run, callbacks=[At(480, killed)])
    assert steps_of(run) == [64, 128, 192, 256, 320, 384, 448]
    assert json.loads((run / "checkpoints" / "latest.json").read_text())["timesteps"] == 256
    assert read_best(run)["timesteps"] == 448  # earned on the branch the kill lost

    assert main(["train", "--resume", str(run), "--no-progress"]) == 0
    said = capsys.readouterr().out
    lost = run / "lost" / "after_0000000256"
    assert f"set aside in {lost}" in said and "3 rows of eval.csv" in said
    assert steps_of(run) == [64, 128, 192, 256, 320, 384, 448, 512, 576, 640]
    assert [int(r["timesteps"]) for r in read_curve(lost / "eval.csv")] == [320, 384, 448]
    assert read_best(lost)["timesteps"] == 448 and (lost / "best" / "model.zip").is_file()
    # The run's best is its own, from the steps it went on with.
    assert read_best(run)["timesteps"] == 640
    # Wall time goes on from the checkpoint's row, not from the lost ones.
    rows = read_curve(run / "eval.csv")
    assert [r["wall_seconds"] for r in rows] == sorted(r["wall_seconds"] for r in rows)


def test_a_second_kill_at_the_same_checkpoint_keeps_both_lost_branches(tmp_path):
    from foosball_gym.training.resume import set_aside_after

    run = tmp_path / "run"
    run.mkdir()
    curve = EvalCurve(run, "t")
    for branch in (0, 1):
        rows = [64] if branch == 0 else []
        for steps in [*rows, 128 + branch, 192 + branch]:
            curve.append({**{k: 0.0 for k in EVAL_FIELDS}, "timesteps": steps})
        assert set_aside_after(run, 64, "t") is not None
        assert steps_of(run) == [64]
    lost = run / "lost"
    assert sorted(p.name for p in lost.iterdir()) == ["after_0000000064", "after_0000000064_2"]
    assert steps_of(lost / "after_0000000064") == [128, 192]
    assert steps_of(lost / "after_0000000064_2") == [129, 193]


def test_self_play_generations_made_past_the_checkpoint_are_set_aside(tmp_path):
    save = tmp_path / "selfplay"
    save.mkdir()
    records = [
        {"generation": g, "timesteps": t, "games": 2 * g, "rule": "net_score", "score": 0.0}
        for g, t in enumerate((0, 100, 250, 300, 420))
    ]
    (save / "history.json").write_text(json.dumps(records))
    for g in range(5):
        snapshot_file(save, g).write_bytes(b"w")
    (save / "generation_0004.zip").write_bytes(b"z")
    verdicts = [{"generation": g, "timesteps": t} for g, t in ((1, 240), (2, 290), (3, 410))]
    (save / "gate.jsonl").write_text("".join(json.dumps(v) + "\n" for v in verdicts))

    lost = tmp_path / "lost" / "selfplay"
    assert set_aside_generations(save, 250, lost) == 2
    assert [r["generation"] for r in read_history(save / "history.json")] == [0, 1, 2]
    assert [r["generation"] for r in read_history(lost / "history.json")] == [3, 4]
    assert sorted(p.name for p in lost.iterdir()) == [
        "gate.jsonl",
        "generation_0004.zip",
        "history.json",
        "opponent_0003.pt",
        "opponent_0004.pt",
    ]
    assert [
        json.loads(line)["timesteps"] for line in (save / "gate.jsonl").read_text().splitlines()
    ] == [240]
    assert set_aside_generations(save, 250, lost) == 0  # nothing more to set aside


def test_a_self_play_run_resumed_after_a_kill_keeps_only_generations_it_goes_on_from(
    tmp_path, capsys, fixed_evaluations
):
    run = tmp_path / "run"
    config = tiny(
        "Foosball-KeeperVsKeeper-v0",
        env_kwargs={"stagnation_steps": 20},
        selfplay_rule="net_score",
        selfplay_threshold=-1.0,
        selfplay_window=2,
        timesteps=1024,
        eval_freq=10_000,
        checkpoint_freq=256,
    )
    history = run / "selfplay" / "history.json"

    def past_checkpoint() -> bool:
        return read_history(history)[-1]["timesteps"] > 256

    with pytest.raises(KeyboardInterrupt):
        train(config, run, callbacks=[At(257, killed, past_checkpoint)])
    before = read_history(history)
    # The kill lands at the first generation past 256 steps, after the checkpoint of 256 or,
    # where learning made none until later, of 512: the run goes on from the last of them.
    latest = json.loads((run / "checkpoints" / "latest.json").read_text())["timesteps"]
    late = [r["generation"] for r in before if r["timesteps"] > latest]
    assert late

    assert main(["train", "--resume", str(run), "--no-progress"]) == 0
    after = read_history(history)
    # Kept: the generations up to the checkpoint; then those the resumed run made, numbered on.
    kept = [r for r in before if r["timesteps"] <= latest]
    assert after[: len(kept)] == kept
    steps = [r["timesteps"] for r in after]
    assert steps == sorted(steps)
    generations = [r["generation"] for r in after]
    assert generations == list(range(len(after)))
    for g in generations:
        assert snapshot_file(run / "selfplay", g).is_file()
    lost = run / "lost" / f"after_{latest:010d}" / "selfplay"
    assert [r["generation"] for r in read_history(lost / "history.json")] == late
    assert all((lost / snapshot_file(lost, g).name).is_file() for g in late)


# -- a full or read-only disk ------------------------------------------------------------


# TensorBoard's writer writes from a thread of its own; a full disk fails it there.
FULL_TENSORBOARD = """
import errno, sys
import tensorboard.summary.writer.record_writer as record_writer

def full(self, data):
    raise OSError(errno.ENOSPC, "No space left on device")

record_writer.RecordWriter.write = full
from foosball_gym.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_a_full_disk_under_tensorboard_on_resume_is_one_line_and_leaves_no_empty_log(tmp_path):
    run = tmp_path / "run"
    argv = ["train", "Foosball-Block-v0", "--timesteps", "128", "--eval-freq", "64"]
    assert main([*argv, "--out", str(run), *SMALL]) == 0
    logs_before = sorted(p.relative_to(run) for p in (run / "tb").rglob("*"))
    done = subprocess.run(
        [sys.executable, "-c", FULL_TENSORBOARD, "train", "--resume", str(run)]
        + ["--timesteps", "256", "--no-progress"],
        capture_output=True,
        text=True,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
        timeout=300,
    )
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
    assert "No space left on device" in lines[0]
    assert not [p for p in (run / "tb").rglob("*") if p.is_file() and p.stat().st_size == 0]
    # What the first sitting logged is kept.
    assert sorted(p.relative_to(run) for p in (run / "tb").rglob("*")) == logs_before


def test_a_full_disk_is_one_line_leaves_no_temporary_file_and_the_run_resumes(
    tmp_path, capsys, monkeypatch, fixed_evaluations
):
    run = tmp_path / "run"
    real = run_files._write_file

    def full_at_the_second_checkpoint(path, data):
        if path.name.startswith("model_0000000256"):
            with open(path, "wb") as f:
                f.write(data[: len(data) // 2])
            raise OSError(errno.ENOSPC, "No space left on device")
        real(path, data)

    monkeypatch.setattr(run_files, "_write_file", full_at_the_second_checkpoint)
    argv = ["train", "Foosball-Block-v0", "--timesteps", "512", "--checkpoint-freq", "128"]
    argv += ["--eval-freq", "128", "--out", str(run), *SMALL]
    err = one_line_refusal(argv, capsys)
    assert "No space left on device" in err and "model_0000000256.zip" in err
    assert f"foosball train --resume {run}" in err
    assert not [p for p in run.rglob("*") if ".tmp" in p.name]
    assert json.loads((run / "checkpoints" / "latest.json").read_text())["timesteps"] == 128
    monkeypatch.setattr(run_files, "_write_file", real)
    assert main(["train", "--resume", str(run), "--no-progress"]) == 0
    assert steps_of(run) == [128, 256, 384, 512]


def test_an_evaluation_row_is_written_whole_or_not_at_all(tmp_path, monkeypatch):
    curve = EvalCurve(tmp_path, "t")
    curve.append({**{k: 0.0 for k in EVAL_FIELDS}, "timesteps": 64})
    before = curve.csv.read_bytes()
    real_open = open

    class FullDisk:
        def __init__(self, f):
            self.f = f

        def write(self, text):
            self.f.write(text[:5])
            self.f.flush()
            raise OSError(errno.ENOSPC, "No space left on device")

        def __getattr__(self, name):
            return getattr(self.f, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

    def opening(path, mode="r", *args, **kwargs):
        f = real_open(path, mode, *args, **kwargs)
        return FullDisk(f) if mode == "a" else f

    monkeypatch.setattr(run_files, "open", opening, raising=False)
    with pytest.raises(OSError, match="No space"):
        curve.append({**{k: 0.0 for k in EVAL_FIELDS}, "timesteps": 128})
    assert curve.csv.read_bytes() == before


def namespaces_work() -> bool:
    """Whether this machine lets a process mount in a namespace of its own (unshare -rm)."""
    if shutil.which("unshare") is None:
        return False
    probe = subprocess.run(
        ["unshare", "-rm", "sh", "-c", "mount -t tmpfs -o size=1m tmpfs /tmp"],
        capture_output=True,
    )
    return probe.returncode == 0


def foosball_in_namespace(setup: str, argv: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(Path(foosball_gym.__file__).resolve().parents[1])}
    command = " ".join([sys.executable, "-m", "foosball_gym.cli", *argv])
    return subprocess.run(
        ["unshare", "-rm", "sh", "-c", f"{setup} && exec {command}"],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
    )


@pytest.mark.skipif(not namespaces_work(), reason="needs unshare -rm (mount namespaces)")
def test_a_read_only_run_given_to_resume_is_refused_in_one_line_untouched(
    tmp_path, fixed_evaluations
):
    run = tmp_path / "run"
    train(tiny(timesteps=128, eval_freq=64, checkpoint_freq=64), run)
    files = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    setup = f"mount --bind {run} {run} && mount -o remount,ro,bind {run}"
    done = foosball_in_namespace(
        setup, ["train", "--resume", str(run), "--timesteps", "256"], tmp_path
    )
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr and len(done.stderr.strip().splitlines()) == 1
    assert "Read-only file system" in done.stderr and "train.lock" in done.stderr
    assert {p: p.read_bytes() for p in run.rglob("*") if p.is_file()} == files


@pytest.mark.slow
@pytest.mark.skipif(not namespaces_work(), reason="needs unshare -rm (mount namespaces)")
def test_a_disk_that_fills_during_training_is_one_line_and_leaves_no_temporary_file(tmp_path):
    disk = tmp_path / "disk"
    disk.mkdir()
    setup = f"mount -t tmpfs -o size=3m tmpfs {disk}"
    argv = ["train", "Foosball-Block-v0", "--timesteps", "20000", "--checkpoint-freq", "1024"]
    argv += ["--eval-freq", "1024", "--out", str(disk / "run"), *SMALL]
    # The files are gone with the namespace: list them from inside it.
    listing = f"; find {disk} -name '*tmp*' >&2"
    env = {**os.environ, "PYTHONPATH": str(Path(foosball_gym.__file__).resolve().parents[1])}
    command = " ".join([sys.executable, "-m", "foosball_gym.cli", *argv])
    done = subprocess.run(
        ["unshare", "-rm", "sh", "-c", f"{setup} && {command}; echo rc=$? >&2{listing}"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=env,
    )
    lines = done.stderr.strip().splitlines()
    assert lines[-1] == "rc=2", done.stderr  # the find listed no temporary file
    assert "Traceback" not in done.stderr and len(lines) == 2, done.stderr
    assert "No space left on device" in lines[0]


# -- Ctrl-C during an evaluation ---------------------------------------------------------


def test_a_signal_stops_an_interruptible_block_where_it_lands():
    stop = SignalStop()
    events = []
    with stop.installed():
        with pytest.raises(Interrupted):
            with stop.interruptible():
                events.append("before")
                os.kill(os.getpid(), signal.SIGINT)
                events.append("after")
        events.append("outside")
        with pytest.raises(Interrupted):  # once stopped, the next block does not start
            with stop.interruptible():
                events.append("never")
    assert events == ["before", "outside"] and stop.signum == signal.SIGINT


def test_ctrl_c_during_an_evaluation_stops_it_at_once_and_the_resumed_run_makes_it_up(
    tmp_path, monkeypatch
):
    run = tmp_path / "run"
    real = sb3_callbacks.evaluate
    calls = {"before": 0, "after": 0, "signalled": False}

    def evaluate_and_press_ctrl_c(policy, *args, **kwargs):
        def acting(obs):
            if calls["signalled"]:
                calls["after"] += 1
            calls["before"] += 1
            if calls["before"] == 50:
                calls["signalled"] = True
                os.kill(os.getpid(), signal.SIGINT)
            return policy(obs)

        return real(acting, *args, **kwargs)

    monkeypatch.setattr(sb3_callbacks, "evaluate", evaluate_and_press_ctrl_c)
    config = tiny(timesteps=256, eval_freq=128, eval_episodes=200, checkpoint_freq=10_000)
    result = train(config, run)
    assert result.signal == signal.SIGINT and result.timesteps == 128
    assert calls == {"before": 50, "after": 0, "signalled": True}  # not one step more
    assert not (run / "eval.csv").exists()
    assert json.loads((run / "checkpoints" / "latest.json").read_text())["timesteps"] == 128

    monkeypatch.setattr(sb3_callbacks, "evaluate", real)
    config_file = run / "config.json"
    config_file.write_text(json.dumps({**json.loads(config_file.read_text()), "eval_episodes": 1}))
    assert train(None, run, resume=True).signal is None
    # The evaluation the signal stopped is the resumed run's first.
    assert steps_of(run) == [128, 256]
