"""Training: runs through the library and the CLI, checkpoints and resume, evaluation."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3.common.callbacks import BaseCallback  # noqa: E402

import foosball_gym  # noqa: E402
from foosball_gym.cli import main  # noqa: E402
from foosball_gym.evaluation import evaluate, wilson_interval  # noqa: E402
from foosball_gym.training.config import TrainConfig  # noqa: E402
from foosball_gym.training.loading import ModelLoadError, load_policy  # noqa: E402
from foosball_gym.training.run_dir.curve import read_curve  # noqa: E402
from foosball_gym.training.sb3.trainer import train  # noqa: E402

SMALL = [
    "--n-envs",
    "2",
    "--n-steps",
    "256",
    "--batch-size",
    "128",
    "--eval-episodes",
    "5",
    "--no-progress",
]


def test_cli_trains_block_and_the_result_evaluates_through_the_cli(tmp_path, capsys):
    run = tmp_path / "block"
    assert (
        main(
            [
                "train",
                "Foosball-Block-v0",
                "--timesteps",
                "3000",
                "--eval-freq",
                "1000",
                "--checkpoint-freq",
                "1024",
                "--out",
                str(run),
                *SMALL,
            ]
        )
        == 0
    )
    for name in (
        "model.zip",
        "config.json",
        "eval.csv",
        "eval.png",
        "checkpoints/latest.json",
        "best/model.zip",
    ):
        assert (run / name).exists(), name
    assert list((run / "tb").rglob("events.out.tfevents.*"))
    config = json.loads((run / "config.json").read_text())
    assert config["env_id"] == "Foosball-Block-v0" and config["net_arch"] == [64, 64]
    curve = read_curve(run / "eval.csv")
    assert [int(r["timesteps"]) for r in curve] == [1000, 2000, 3000, 3072]
    assert all(0 <= r["success_rate"] <= 1 for r in curve)

    out = tmp_path / "eval.json"
    assert main(["eval", str(run), "--episodes", "12", "--seed", "5", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "success rate" in printed and "95 % CI" in printed
    result = json.loads(out.read_text())
    assert result["episodes"] == 12 and result["seed"] == 5
    assert result["env_id"] == "Foosball-Block-v0"
    assert result["ci_low"] <= result["success_rate"] <= result["ci_high"]


def test_env_kwargs_reach_the_environment(tmp_path):
    run = tmp_path / "score"
    main(
        [
            "train",
            "Foosball-Score-v0",
            "--timesteps",
            "512",
            "--eval-freq",
            "512",
            "--env-kwarg",
            "ball_start=incoming",
            "--env-kwarg",
            "goal_reward=50.0",
            "--out",
            str(run),
            *SMALL,
        ]
    )
    config = json.loads((run / "config.json").read_text())
    assert config["env_kwargs"] == {"ball_start": "incoming", "goal_reward": 50.0}
    loaded = load_policy(run)
    assert loaded.env_kwargs == {"ball_start": "incoming", "goal_reward": 50.0}


class StopAt(BaseCallback):
    """Interrupts training the way Ctrl-C would."""

    def __init__(self, steps: int) -> None:
        super().__init__()
        self.steps = steps

    def _on_step(self) -> bool:
        if self.num_timesteps >= self.steps:
            raise KeyboardInterrupt
        return True


def test_an_interrupted_run_resumes_from_its_last_checkpoint(tmp_path):
    run = tmp_path / "run"
    config = TrainConfig(
        "Foosball-Block-v0",
        timesteps=4096,
        n_envs=2,
        n_steps=256,
        batch_size=128,
        eval_freq=1024,
        eval_episodes=3,
        checkpoint_freq=1024,
        lr_schedule="constant",  # extended below, which a decaying rate refuses
    )
    with pytest.raises(KeyboardInterrupt):
        train(config, run, callbacks=[StopAt(2600)])
    pointer = json.loads((run / "checkpoints" / "latest.json").read_text())
    assert pointer["timesteps"] == 2048
    assert not (run / "model.zip").exists()
    assert main(["train", "--resume", str(run), "--no-progress"]) == 0
    assert (run / "model.zip").exists()
    steps = [int(r["timesteps"]) for r in read_curve(run / "eval.csv")]
    assert steps[-1] == 4096 and steps == sorted(steps)

    # A finished run goes on, with --timesteps, past where it was to stop.
    physics = json.loads((run / "config.json").read_text())["physics"]
    assert main(["train", "--resume", str(run), "--timesteps", "5120", "--no-progress"]) == 0
    steps = [int(r["timesteps"]) for r in read_curve(run / "eval.csv")]
    assert steps[-1] == 5120 and steps == sorted(steps)
    saved = json.loads((run / "config.json").read_text())
    assert saved["timesteps"] == 5120 and saved["physics"] == physics
    with pytest.raises(SystemExit):
        main(["train", "--resume", str(run), "--timesteps", "4096", "--no-progress"])
    with pytest.raises(ValueError, match="extends a resumed run"):
        train(config, tmp_path / "new", timesteps=8192)


def test_a_run_whose_learning_rate_decays_over_its_length_is_not_extended(tmp_path):
    TrainConfig("Foosball-Block-v0", timesteps=4096, lr_schedule="linear").save(
        tmp_path / "config.json"
    )
    with pytest.raises(ValueError, match="start the decay over"):
        train(None, tmp_path, resume=True, timesteps=8192)


def test_evaluation_is_reproducible_and_counts_successes():
    import gymnasium as gym

    from foosball_gym.policies.scripted import ScriptedKeeper

    env = gym.make("Foosball-Block-v0")
    keeper = ScriptedKeeper(env.unwrapped.obs_builder.names)
    env.close()
    a = evaluate(keeper, "Foosball-Block-v0", episodes=30, seed=3)
    b = evaluate(keeper, "Foosball-Block-v0", episodes=30, seed=3)
    assert a == b
    assert a.successes == round(a.success_rate * 30) and a.success_rate >= 0.9
    zero = evaluate(lambda obs: np.zeros(1, np.float32), "Foosball-Block-v0", episodes=30, seed=3)
    assert zero.goals_against == 30 - zero.successes


def test_wilson_interval():
    low, high = wilson_interval(50, 100)
    assert low == pytest.approx(0.4038, abs=1e-3) and high == pytest.approx(0.5962, abs=1e-3)
    assert (
        wilson_interval(100, 100)[1] == pytest.approx(1.0) and wilson_interval(100, 100)[0] > 0.95
    )
    assert wilson_interval(0, 10)[0] == 0.0


def test_cli_evaluates_the_scripted_baseline_and_records_a_video(tmp_path, capsys):
    out, video = tmp_path / "s.json", tmp_path / "s.mp4"
    assert (
        main(
            [
                "eval",
                "--policy",
                "scripted",
                "Foosball-Block-v0",
                "--episodes",
                "20",
                "--json",
                str(out),
                "--video",
                str(video),
            ]
        )
        == 0
    )
    assert json.loads(out.read_text())["success_rate"] >= 0.9
    cv2 = pytest.importorskip("cv2")
    cap = cv2.VideoCapture(str(video))
    frames = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    ok, frame = cap.read()
    assert ok and frame.shape == (360, 640, 3) and frames > 10


def test_a_corrupt_model_file_gives_a_clear_error(tmp_path, capsys):
    bad = tmp_path / "model.zip"
    bad.write_bytes(b"this is not a zip file")
    with pytest.raises(SystemExit) as exit_info:
        main(["eval", str(bad), "--env", "Foosball-Block-v0"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "cannot read" in err and "Traceback" not in err
    with pytest.raises(ModelLoadError):
        load_policy(bad)


def test_pretraining_clones_the_scripted_keeper(tmp_path):
    from foosball_gym.training.sb3.pretrain import collect

    demos = collect("Foosball-Block-v0", {}, episodes=5, gamma=0.99)
    assert demos.observations.shape[1] == 6 and len(demos.actions) == len(demos.returns)
    assert demos.success_rate >= 0.6
    run = tmp_path / "bc"
    assert (
        main(
            [
                "train",
                "Foosball-Block-v0",
                "--timesteps",
                "512",
                "--eval-freq",
                "512",
                "--pretrain-episodes",
                "100",
                "--log-std-init",
                "-2",
                "--learning-rate",
                "1e-5",
                "--out",
                str(run),
                *SMALL,
            ]
        )
        == 0
    )
    record = json.loads((run / "pretrain.json").read_text())
    assert record["episodes"] == 100 and record["action_mse"] < 0.05
    # Barely trained by PPO, the clone already blocks like the scripted keeper.
    clone = load_policy(run).policy
    result = evaluate(clone, "Foosball-Block-v0", episodes=40, seed=500)
    zero = evaluate(lambda obs: np.zeros(1, np.float32), "Foosball-Block-v0", episodes=40, seed=500)
    assert result.success_rate >= zero.success_rate + 0.25


def start_training(argv: list[str], cwd) -> subprocess.Popen:
    """``foosball train`` in its own process group, as a terminal runs it."""
    env = {**os.environ, "PYTHONPATH": str(Path(foosball_gym.__file__).resolve().parents[1])}
    return subprocess.Popen(
        [sys.executable, "-m", "foosball_gym.cli", "train", *argv],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )


def interrupt_once_stepping(proc: subprocess.Popen, run: Path, tb_runs: int) -> tuple[str, str]:
    """Ctrl-C to the whole process group once PPO logged its first update of this start."""
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and proc.poll() is None:
        logs = sorted((run / "tb").glob("run_*/events.out.tfevents.*"))
        # A log file exists from the start of learning; it grows with each update's figures.
        if len(logs) >= tb_runs and logs[-1].stat().st_size > 200:
            break
        time.sleep(0.2)
    assert proc.poll() is None, proc.communicate()
    os.killpg(proc.pid, signal.SIGINT)
    return proc.communicate(timeout=120)


def test_ctrl_c_writes_a_checkpoint_and_resume_continues_from_it(tmp_path):
    run = tmp_path / "run"
    argv = ["--n-envs", "2", "--vec-env", "subproc", "--n-steps", "64", "--batch-size", "64"]
    argv += ["--eval-freq", "1000000", "--no-progress"]
    proc = start_training(
        ["Foosball-Block-v0", "--timesteps", "1000000", *argv, "--out", str(run)], tmp_path
    )
    out, err = interrupt_once_stepping(proc, run, tb_runs=1)
    # The default checkpoint interval (50 000 steps) is far off: this one is the interrupt's.
    assert proc.returncode == 130, err
    assert "stopped by SIGINT" in out and "--resume" in out and "Traceback" not in err
    first = json.loads((run / "checkpoints" / "latest.json").read_text())["timesteps"]
    assert 0 < first < 50_000 and not (run / "model.zip").exists()

    proc = start_training(["--resume", str(run), "--no-progress"], tmp_path)
    out, err = interrupt_once_stepping(proc, run, tb_runs=2)
    assert proc.returncode == 130, err
    second = json.loads((run / "checkpoints" / "latest.json").read_text())["timesteps"]
    assert second > first


def test_a_start_that_fails_leaves_no_run_behind(tmp_path, capsys):
    run = tmp_path / "run"
    argv = ["train", "Foosball-Block-v0", "--out", str(run), "--no-progress"]
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, "--selfplay-threshold", "1.5"])
    assert exit_info.value.code == 2
    assert "the win_rate rule's threshold must lie in (0, 1], got 1.5" in capsys.readouterr().err
    assert not (run / "config.json").exists()


def test_a_directory_with_a_configuration_but_no_checkpoint_can_start_again(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    # What a start stopped before its first checkpoint leaves.
    TrainConfig("Foosball-Block-v0", timesteps=128).save(run / "config.json")
    (run / "eval.csv").write_text("stale\n")
    small = ["--timesteps", "128", "--n-envs", "1", "--n-steps", "64", "--batch-size", "64"]
    small += ["--eval-freq", "128", "--eval-episodes", "1", "--no-progress"]
    assert main(["train", "Foosball-Block-v0", *small, "--out", str(run)]) == 0
    assert [int(r["timesteps"]) for r in read_curve(run / "eval.csv")] == [128]
    shutil.rmtree(run / "checkpoints")
    (run / "model.zip").unlink()
    assert main(["train", "--resume", str(run), "--no-progress"]) == 0
    assert "starting the run over" in capsys.readouterr().out
    assert (run / "model.zip").exists()


def test_the_defaults_take_pytorchs_fused_adam_and_the_papers_settings_keep_sb3s():
    # Adam's epsilon decides how far the first updates move a cloned policy: with PyTorch's
    # 1e-8 in place of SB3's 1e-5, the README's main job (its settings file) fell from 100 % to
    # 74-78 % after 10,000 steps.
    from foosball_gym.training.config_file import load_train_config
    from foosball_gym.training.sb3.model import build_model
    from foosball_gym.training.sb3.vec_env import make_env

    for config, eps, fused in [
        (TrainConfig("Foosball-Block-v0", n_envs=1), 1e-8, True),
        (load_train_config("builtin:paper-ppo", "Foosball-Block-v0", {"n_envs": 1}), 1e-5, False),
        (load_train_config("builtin:Foosball-Block-v0", overrides={"n_envs": 1}), 1e-5, False),
    ]:
        config.check()
        venv = make_env(config)
        try:
            defaults = build_model(config, venv, None).policy.optimizer.defaults
        finally:
            venv.close()
        assert (defaults["eps"], bool(defaults["fused"])) == (eps, fused)


def test_the_entropy_weight_reaches_ppo_and_a_bad_one_is_refused(capsys):
    from foosball_gym.training.sb3.model import build_model
    from foosball_gym.training.sb3.vec_env import make_env

    config = TrainConfig("Foosball-Block-v0", n_envs=1, ent_coef=0.01)
    config.check()
    venv = make_env(config)
    try:
        assert build_model(config, venv, None).ent_coef == 0.01
    finally:
        venv.close()
    for bad, message in [
        ({"ent_coef": -0.1}, "0 or more"),
        ({"algo": "sac", "ent_coef": 0.1}, "PPO"),
    ]:
        with pytest.raises(ValueError, match=message):
            TrainConfig("Foosball-Block-v0", **bad).check()
    with pytest.raises(SystemExit):
        main(["train", "Foosball-Block-v0", "--ent-coef", "x"])
    assert "--ent-coef" in capsys.readouterr().err
