"""Behaviour cloning from the scripted baseline, to start reinforcement learning from it.

Sparse goal rewards make PPO slow to find a kick that scores. Starting from a policy that
already plays like the scripted team (and a value function fitted to the returns it earns)
lets PPO spend its samples improving on it instead. The demonstrations are collected with a
little noise on the executed actions, labelled with the clean scripted action, so the clone
also learns to recover from small mistakes (as in DART).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.vec_env import VecNormalize

from foosball_gym.progress import Progress
from foosball_gym.training.config import TrainConfig
from foosball_gym.training.run_dir.files import PRETRAIN_FILE, atomic_write_text

if TYPE_CHECKING:
    from foosball_gym.envs.base import FoosballEnv


@dataclass
class Demonstrations:
    observations: np.ndarray  # (N, obs_dim), raw
    actions: np.ndarray  # (N, act_dim), the scripted policy's
    returns: np.ndarray  # (N,), discounted returns from each state
    success_rate: float


def collect(
    env_id: str,
    env_kwargs: dict[str, Any],
    episodes: int,
    gamma: float,
    noise: float = 0.1,
    seed: int = 0,
    progress: bool = False,
) -> Demonstrations:
    """Play ``episodes`` episodes with the task's scripted policy and record them
    (``progress``: show the episodes played on standard error)."""
    env = gym.make(env_id, **env_kwargs)
    policy = cast("FoosballEnv", env.unwrapped).scripted_policy()
    rng = np.random.default_rng(seed)
    obs_all, act_all = [], []
    ret_all: list[float] = []
    successes = 0
    count = Progress(episodes, "demonstrations", "episodes", enabled=progress)
    try:
        for i in range(episodes):
            obs, info = env.reset(seed=seed + i)
            rewards, done = [], False
            while not done:
                action = np.asarray(policy(obs), dtype=np.float32)
                obs_all.append(obs)
                act_all.append(action)
                executed = np.clip(action + rng.normal(0.0, noise, action.shape), -1, 1)
                obs, reward, terminated, truncated, info = env.step(executed.astype(np.float32))
                rewards.append(float(reward))
                done = terminated or truncated
            successes += bool(info["is_success"])
            g, episode_returns = 0.0, []
            for r in reversed(rewards):
                g = r + gamma * g
                episode_returns.append(g)
            ret_all.extend(reversed(episode_returns))
            count.update()
    finally:
        count.close()
        env.close()
    return Demonstrations(
        np.array(obs_all, np.float32),
        np.array(act_all, np.float32),
        np.array(ret_all, np.float32),
        successes / episodes,
    )


def clone(
    model: Any,
    demos: Demonstrations,
    epochs: int = 30,
    batch_size: int = 256,
    learning_rate: float = 1e-3,
    seed: int = 0,
    progress: bool = False,
) -> dict[str, float]:
    """Fit ``model``'s policy (action mean) and value function to the demonstrations
    (``progress``: show the epochs on standard error).

    The model's VecNormalize statistics, if any, are first set from the demonstrations, so
    the network sees the observations it was fitted on.

    Returns:
        The final mean squared errors of actions and (normalised) values.
    """
    norm = model.get_vec_normalize_env()
    obs = demos.observations
    if isinstance(norm, VecNormalize) and norm.norm_obs:
        norm.obs_rms.update(obs)
        # A Box's observations normalise to an array (SB3 also types the dict case).
        obs = cast(np.ndarray, norm.normalize_obs(obs))
    policy = model.policy
    device = policy.device
    obs_t = th.as_tensor(obs, dtype=th.float32, device=device)
    act_t = th.as_tensor(demos.actions, dtype=th.float32, device=device)
    scale = float(np.abs(demos.returns).max()) or 1.0
    ret_t = th.as_tensor(demos.returns / scale, dtype=th.float32, device=device)
    optimizer = th.optim.Adam(policy.parameters(), lr=learning_rate)
    gen = th.Generator().manual_seed(seed)
    policy.set_training_mode(True)
    action_loss = value_loss = th.tensor(0.0)
    count = Progress(epochs, "cloning", "epochs", enabled=progress)
    for _ in range(epochs):
        count.update()
        for idx in th.randperm(len(obs_t), generator=gen).split(batch_size):
            features = policy.extract_features(obs_t[idx])
            latent_pi, latent_vf = policy.mlp_extractor(features)
            mean = policy.action_net(latent_pi)
            values = policy.value_net(latent_vf).squeeze(-1)
            action_loss = th.mean((mean - act_t[idx]) ** 2)
            value_loss = th.mean((values - ret_t[idx]) ** 2)
            optimizer.zero_grad()
            (action_loss + value_loss).backward()
            optimizer.step()
    # The value head learnt returns divided by `scale`; its last layer takes the factor back.
    with th.no_grad():
        policy.value_net.weight.mul_(scale)
        policy.value_net.bias.mul_(scale)
    count.close()
    policy.set_training_mode(False)
    return {"action_mse": action_loss.item(), "value_mse": value_loss.item()}


def pretrain(model: Any, config: TrainConfig, out: Path, progress: bool = False) -> None:
    """Clone ``config.pretrain_episodes`` episodes of the scripted baseline into ``model``,
    and record how it went in the run's ``pretrain.json`` (``progress``: show the episodes
    and the epochs on standard error)."""
    start = time.perf_counter()
    demos = collect(
        config.env_id,
        config.env_kwargs,
        config.pretrain_episodes,
        config.gamma,
        seed=config.seed,
        progress=progress,
    )
    fit = clone(model, demos, seed=config.seed, progress=progress)
    record = {
        "episodes": config.pretrain_episodes,
        "samples": len(demos.actions),
        "scripted_success_rate": demos.success_rate,
        **fit,
        "seconds": round(time.perf_counter() - start, 2),
    }
    atomic_write_text(out / PRETRAIN_FILE, json.dumps(record, indent=2))
