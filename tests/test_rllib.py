"""The rllib backend: self-play on Ray RLlib, its run directory, its policy for `foosball eval`."""

from __future__ import annotations

import argparse
import json
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("ray")
pytest.importorskip("pettingzoo")
torch = pytest.importorskip("torch")

from foosball_gym.cli import main  # noqa: E402
from foosball_gym.cli.distributed import add_rllib_arguments  # noqa: E402
from foosball_gym.evaluation import evaluate  # noqa: E402
from foosball_gym.training.config import TrainConfig  # noqa: E402
from foosball_gym.training.loading.rllib_policy import load_rllib_policy  # noqa: E402
from foosball_gym.training.rllib.export import export_policy  # noqa: E402
from foosball_gym.training.rllib.opponent_pool import OpponentPool  # noqa: E402
from foosball_gym.training.rllib.ray_config import check_rllib_config  # noqa: E402
from foosball_gym.training.rllib.trainer import train_rllib  # noqa: E402
from foosball_gym.training.run_dir.files import POLICY_FILE, POLICY_INFO_FILE  # noqa: E402

ENV = "Foosball-KeeperVsKeeper-v0"


def tiny_config(**overrides) -> TrainConfig:
    """A budget a 2-core machine trains in seconds: a 16-unit network, 512-step updates."""
    values = dict(
        timesteps=3000,
        n_envs=2,
        n_steps=256,
        batch_size=128,
        n_epochs=2,
        net_arch=(16,),
        eval_freq=100_000,
        eval_episodes=2,
        checkpoint_freq=1000,
        # Every 4 games the opponent is replaced, so a short run replaces it several times.
        # Games end a still ball as a draw (self-play's default plays on to 1800 steps), so
        # that enough of them finish.
        env_kwargs={"stagnation_steps": 20},
        selfplay_window=4,
        selfplay_rule="net_score",
        selfplay_threshold=-1.0,
        selfplay_pool=2,
    )
    values.update(overrides)
    return TrainConfig(ENV, **values)


def module_state(obs: int = 10, hidden: int = 8, act: int = 2) -> dict[str, np.ndarray]:
    """The state of an RLlib PPO module's actor, as RLlib names it, with random weights."""
    rng = np.random.default_rng(0)
    return {
        "encoder.actor_encoder.net.mlp.0.weight": rng.normal(size=(hidden, obs)),
        "encoder.actor_encoder.net.mlp.0.bias": rng.normal(size=hidden),
        "encoder.critic_encoder.net.mlp.0.weight": rng.normal(size=(hidden, obs)),
        "encoder.critic_encoder.net.mlp.0.bias": rng.normal(size=hidden),
        "pi.net.mlp.0.weight": rng.normal(size=(2 * act, hidden)),
        "pi.net.mlp.0.bias": rng.normal(size=2 * act),
        "vf.net.mlp.0.weight": rng.normal(size=(1, hidden)),
        "vf.net.mlp.0.bias": rng.normal(size=1),
    }


def test_exported_policy_acts_as_the_modules_clipped_gaussian_mean(tmp_path):
    state = module_state()
    export_policy(state, tmp_path, env_id=ENV, env_kwargs={})
    policy = load_rllib_policy(tmp_path)
    obs = np.random.default_rng(1).normal(size=(5, 10)).astype(np.float32)
    hidden = np.tanh(
        obs @ state["encoder.actor_encoder.net.mlp.0.weight"].T
        + state["encoder.actor_encoder.net.mlp.0.bias"]
    )
    out = hidden @ state["pi.net.mlp.0.weight"].T + state["pi.net.mlp.0.bias"]
    expected = np.clip(out[:, :2], -1, 1)  # the means; the log std follow
    np.testing.assert_allclose(policy(obs), expected, atol=1e-5)
    np.testing.assert_allclose(policy(obs[0]), expected[0], atol=1e-5)
    assert policy.observation_size == 10 and policy.env_id == ENV


def test_exported_policy_is_tensors_only(tmp_path):
    export_policy(module_state(), tmp_path, env_id=ENV, env_kwargs={"max_cycles": 9})
    data = torch.load(tmp_path / POLICY_FILE, weights_only=True)
    assert all(isinstance(v, torch.Tensor) for v in data.values())
    info = json.loads((tmp_path / POLICY_INFO_FILE).read_text())
    assert info["hidden_sizes"] == [8] and info["activation"] == "tanh"
    assert info["env_kwargs"] == {"max_cycles": 9}


def test_policy_file_that_disagrees_with_its_description_is_refused(tmp_path):
    export_policy(module_state(), tmp_path, env_id=ENV, env_kwargs={})
    info = json.loads((tmp_path / POLICY_INFO_FILE).read_text())
    info["hidden_sizes"] = [9]
    (tmp_path / POLICY_INFO_FILE).write_text(json.dumps(info))
    with pytest.raises(ValueError, match="layer 0"):
        load_rllib_policy(tmp_path)
    with pytest.raises(ValueError, match="holds no RLlib policy"):
        load_rllib_policy(tmp_path / "missing")


def test_policy_file_with_a_mean_but_no_spread_is_refused_as_it_loads(tmp_path):
    """Normalising needs both statistics: a description that gives one is refused as it loads,
    not at the policy's first action."""
    export_policy(module_state(), tmp_path, env_id=ENV, env_kwargs={})
    info = json.loads((tmp_path / POLICY_INFO_FILE).read_text())
    info["obs_mean"] = [0.0] * 10
    (tmp_path / POLICY_INFO_FILE).write_text(json.dumps(info))
    with pytest.raises(ValueError, match="obs_mean and obs_std"):
        load_rllib_policy(tmp_path)


def test_opponent_is_replaced_by_the_rule_both_backends_share(tmp_path):
    def pool(rule):
        config = TrainConfig(ENV, selfplay_window=4, selfplay_rule=rule, selfplay_threshold=0.2)
        return OpponentPool(config, tmp_path)

    sp = pool("net_score")
    assert sp.judge([1, 1, 1]) is None  # not a full window yet
    sp = pool("net_score")
    assert sp.judge([1, -1, 0, 0]) is None  # net score 0
    assert sp.judge([1]) is None  # the last four: -1, 0, 0, 1
    score, elo = sp.judge([1, 1, 1])  # 0, 0, 1, 1
    assert score == pytest.approx(0.5) and elo > 0
    # The game after the one that earned the snapshot was played against the old pool.
    assert sp.games == 6 and len(sp.rule.results) == 0
    # The paper's rule, the default: one win in four is enough, draws or not.
    sp = pool("win_rate")
    score, _ = sp.judge([0, 0, 1, 0])
    assert score == pytest.approx(0.25)
    assert TrainConfig(ENV).selfplay_rule == "win_rate"


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"algo": "sac"}, "trains PPO only"),
        ({"self_play": False}, "by self-play"),
        ({"pretrain_episodes": 10}, "does not pretrain"),
        ({"video_every": 1000}, "writes no clips"),
        ({"selfplay_scripted_share": 0.2}, "plays snapshots only"),
        ({"selfplay_sampled": True}, "act on their policy's mean"),
        ({"teacher_steps": 1000}, "no scripted teacher"),
        ({"selfplay_gate": 40}, "no gate"),
        ({"use_sde": True}, "explores with a Gaussian of its own"),
        ({"env_kwargs": {"residual": 0.5}}, "bare corrections"),
    ],
)
def test_what_the_rllib_backend_cannot_train_is_refused(overrides, message):
    with pytest.raises(ValueError, match=message):
        check_rllib_config(TrainConfig(ENV, **overrides), num_workers=1)


def test_the_rllib_backend_refuses_to_hold_rods():
    config = TrainConfig("Foosball-FullGame-v0", rods_held_share=0.5)
    with pytest.raises(ValueError, match="drives every rod in every game"):
        check_rllib_config(config, num_workers=1)


def test_rllib_options_parse():
    parser = argparse.ArgumentParser()
    add_rllib_arguments(parser)
    args = parser.parse_args(["--backend", "rllib", "--num-workers", "0", "--address", "auto"])
    assert (args.backend, args.num_workers, args.address) == ("rllib", 0, "auto")
    with pytest.raises(SystemExit):
        parser.parse_args(["--num-workers", "-1"])


# Sampling in the trainer's own process (0) is what a laptop runs; two env runners, what a
# cluster does, costs a minute more for their processes.
@pytest.mark.parametrize("workers", [0, pytest.param(2, marks=pytest.mark.slow)])
# RLlib registers its multi-agent env again when a second algorithm is built in one process.
@pytest.mark.filterwarnings("ignore:.*Overriding environment rllib-multi-agent-env-v0")
def test_a_run_trains_evaluates_and_resumes(tmp_path, workers):
    out = tmp_path / "run"
    result = train_rllib(tiny_config(), out, num_workers=workers, verbose=0)
    assert result.timesteps >= 3000
    config = json.loads((out / "config.json").read_text())
    assert config["backend"] == "rllib" and config["num_workers"] == workers
    # What this backend does not do is recorded as not done.
    assert not (config["normalize"] or config["normalize_reward"] or config["fused_adam"])
    assert (out / "checkpoints" / "latest.json").exists()
    history = json.loads((out / "selfplay" / "history.json").read_text())
    assert [h["generation"] for h in history][:2] == [0, 1]
    assert result.generation == history[-1]["generation"] >= 1
    rows = (out / "eval.csv").read_text().splitlines()
    assert rows[0].startswith("timesteps,") and len(rows) >= 2

    policy = load_rllib_policy(out)
    res = evaluate(policy, policy.env_id, policy.env_kwargs, episodes=3, seed=0)
    assert res.episodes == 3 and 0.0 <= res.success_rate <= 1.0
    action = policy(np.zeros(policy.observation_size, np.float32))
    assert action.shape == (2,) and np.all(np.abs(action) <= 1)
    # foosball eval takes the run directory as it is: no export, no trust flag.
    assert main(["eval", str(out), "--episodes", "3", "--seed", "0"]) == 0
    # foosball league rates its generations, read from the snapshots RLlib's modules left.
    assert main(["league", str(out), "--games", "2", "--generations", "2"]) == 0
    league = json.loads((out / "league.json").read_text())
    assert [p["name"] for p in league["players"]][-2:] == ["final", "scripted"]

    # Resuming continues the count, the pool and the curve from the last checkpoint.
    config["timesteps"] = result.timesteps + 1000
    (out / "config.json").write_text(json.dumps(config))
    again = train_rllib(TrainConfig(ENV), out, num_workers=min(workers, 1), resume=True, verbose=0)
    assert again.timesteps >= config["timesteps"]
    assert again.games > result.games
    assert len((out / "eval.csv").read_text().splitlines()) == len(rows) + 1


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
@pytest.mark.skipif(
    shutil.which("ray") is None and not (Path(sys.executable).parent / "ray").exists(),
    reason="the ray command is not installed",
)
def test_training_joins_a_ray_head_started_apart_by_its_address(tmp_path):
    """A cluster as a user starts one: `ray start --head`, then `foosball train --address`."""
    ray_cli = shutil.which("ray") or str(Path(sys.executable).parent / "ray")
    port = _free_port()
    env = {**os.environ, "RAY_AUTH_MODE": "disabled"}  # the address is what is tested
    # --block keeps the head in the foreground, so it is stopped through this process alone.
    head = subprocess.Popen(
        [ray_cli, "start", "--head", f"--port={port}", "--num-cpus", "2"]
        + ["--include-dashboard=false", "--block"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
    )
    run = tmp_path / "run"
    try:
        time.sleep(5)
        assert head.poll() is None, "the Ray head did not start"
        train = subprocess.run(
            [sys.executable, "-m", "foosball_gym.cli", "train", ENV, "--backend", "rllib"]
            + ["--num-workers", "2", "--address", f"127.0.0.1:{port}", "--out", str(run)]
            + ["--timesteps", "1000", "--n-steps", "64", "--n-envs", "4", "--batch-size", "64"]
            + ["--no-progress"],
            capture_output=True,
            text=True,
            env=env,
            timeout=600,
        )
        assert train.returncode == 0, train.stderr[-3000:]
        assert load_rllib_policy(run).observation_size == 10
    finally:
        head.terminate()
        head.wait(timeout=60)
        # The head leaves its address behind; a later plain ray.init() would try to join it.
        current = Path("/tmp/ray/ray_current_cluster")
        if current.exists() and current.read_text().strip().endswith(f":{port}"):
            current.unlink()


def test_an_unreachable_address_fails_fast_naming_it(tmp_path, capsys):
    port = _free_port()  # nothing listens there
    started = time.monotonic()
    with pytest.raises(SystemExit) as exit_info:
        main(
            ["train", ENV, "--backend", "rllib", "--address", f"127.0.0.1:{port}"]
            + ["--out", str(tmp_path / "run"), "--timesteps", "1000", "--no-progress"]
        )
    assert exit_info.value.code == 2
    assert f"127.0.0.1:{port}" in capsys.readouterr().err
    assert time.monotonic() - started < 30
