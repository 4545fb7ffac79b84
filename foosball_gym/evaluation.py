"""Seeded evaluation of a policy: success rate with a confidence interval, goals, rewards.

Needs neither PyTorch nor Stable-Baselines3: a policy is any callable from an observation to
an action, so the scripted baselines are evaluated on the base install. Recording a video
needs OpenCV, from the ``train`` or the ``hardware`` extra.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from foosball_gym.catalog import check_env_id

Policy = Callable[[np.ndarray], Any]


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a success rate (sensible at 0 % and 100 % too)."""
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


@dataclass
class EvalResult:
    env_id: str
    env_kwargs: dict[str, Any]
    policy: str
    opponent: str | None
    episodes: int
    seed: int
    successes: int
    success_rate: float
    ci_low: float
    ci_high: float
    goals_for: int
    goals_against: int
    mean_reward: float
    std_reward: float
    mean_length: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def table(self) -> str:
        """The result as a small text table."""
        rows = [
            ("environment", self.env_id),
            ("policy", self.policy),
            *([("opponent", self.opponent)] if self.opponent else []),
            ("episodes", f"{self.episodes} (seeds {self.seed}..{self.seed + self.episodes - 1})"),
            (
                "success rate",
                f"{100 * self.success_rate:.1f} % "
                f"(95 % CI {100 * self.ci_low:.1f} - {100 * self.ci_high:.1f} %)",
            ),
            ("goals for / against", f"{self.goals_for} / {self.goals_against}"),
            ("mean reward", f"{self.mean_reward:.1f} ± {self.std_reward:.1f}"),
            ("mean episode length", f"{self.mean_length:.1f} steps"),
        ]
        width = max(len(k) for k, _ in rows)
        return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def evaluate(
    policy: Policy,
    env_id: str,
    env_kwargs: dict[str, Any] | None = None,
    episodes: int = 100,
    seed: int = 0,
    opponent: Policy | None = None,
    policy_name: str = "policy",
    opponent_name: str | None = None,
    video: str | Path | None = None,
) -> EvalResult:
    """Run ``episodes`` episodes seeded ``seed, seed + 1, ...`` and summarise them.

    Args:
        policy: a callable from one observation to one action.
        env_id, env_kwargs: the environment.
        opponent: for two-player envs, the away side's policy (None: the env's default).
        video: write the first episode, rendered, to this .mp4 file.

    Raises:
        ValueError: ``episodes`` is below 1, ``env_id`` is not registered, an option has a
            bad value (TypeError where the environment has no such option), or a policy that
            says the size of the observations it takes (``observation_size``) takes others.
    """
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    check_env_id(env_id)
    kwargs = dict(env_kwargs or {})
    if video is not None:
        kwargs.update(render_mode="rgb_array", render_width=640, render_height=360)
    env = gym.make(env_id, **kwargs)
    try:
        _check_fits(policy, policy_name, env_id, env)
        if opponent is not None:
            _check_fits(opponent, opponent_name or "opponent", env_id, env)
    except ValueError:
        env.close()
        raise
    if opponent is not None:
        env.unwrapped.set_opponent(opponent)
    rewards, lengths = [], []
    successes = goals_for = goals_against = 0
    writer = None
    try:
        for i in range(episodes):
            obs, info = env.reset(seed=seed + i)
            record = video is not None and i == 0
            if record:
                writer = _VideoWriter(video, env.metadata["render_fps"])
                writer.add(env.render())
            total, steps, done = 0.0, 0, False
            while not done:
                obs, reward, terminated, truncated, info = env.step(policy(obs))
                total += reward
                steps += 1
                done = terminated or truncated
                if record:
                    writer.add(env.render())
            if record:
                writer.close()
                writer = None
            rewards.append(total)
            lengths.append(steps)
            successes += bool(info["is_success"])
            if "goals_for" in info:
                goals_for += info["goals_for"]
                goals_against += info["goals_against"]
            else:
                goals_for += info["goal"] == 1
                goals_against += info["goal"] == -1
    finally:
        if writer is not None:
            writer.close()
        env.close()
    low, high = wilson_interval(successes, episodes)
    return EvalResult(
        env_id=env_id,
        env_kwargs=dict(env_kwargs or {}),
        policy=policy_name,
        opponent=opponent_name,
        episodes=episodes,
        seed=seed,
        successes=successes,
        success_rate=successes / episodes,
        ci_low=low,
        ci_high=high,
        goals_for=int(goals_for),
        goals_against=int(goals_against),
        mean_reward=float(np.mean(rewards)),
        std_reward=float(np.std(rewards)),
        mean_length=float(np.mean(lengths)),
    )


def _check_fits(policy: Policy, name: str, env_id: str, env: gym.Env) -> None:
    expected = getattr(policy, "observation_size", None)
    size = int(np.prod(env.observation_space.shape))
    if expected is not None and expected != size:
        trained = getattr(policy, "env_id", None)
        of = f" of {trained}" if trained else ""
        raise ValueError(
            f"{name} expects observations of size {expected}{of}, but {env_id} gives {size}: "
            f"give a model trained on {env_id}"
        )


class _VideoWriter:
    """Frames to an .mp4 file with OpenCV."""

    def __init__(self, path: str | Path, fps: float) -> None:
        try:
            import cv2
        except ImportError as err:
            raise ImportError(
                "recording video needs OpenCV, which the train and hardware extras install: "
                'pip install "foosball_gym[train]"'
            ) from err
        self._cv2 = cv2
        self.path = str(path)
        self.fps = fps
        self._writer = None

    def add(self, frame: np.ndarray) -> None:
        if self._writer is None:
            h, w = frame.shape[:2]
            fourcc = self._cv2.VideoWriter_fourcc(*"mp4v")
            self._writer = self._cv2.VideoWriter(self.path, fourcc, self.fps, (w, h))
            if not self._writer.isOpened():
                raise OSError(f"cannot write a video to {self.path}")
        self._writer.write(self._cv2.cvtColor(frame, self._cv2.COLOR_RGB2BGR))

    def close(self) -> None:
        if self._writer is not None:
            self._writer.release()
