"""The environments from other tools: Gymnasium's RecordVideo."""

from __future__ import annotations

from importlib.util import find_spec

import gymnasium as gym
import numpy as np
import pytest

needs_train = pytest.mark.skipif(
    any(find_spec(m) is None for m in ("stable_baselines3", "torch", "cv2")),
    reason='needs the train extra: pip install "foosball_gym[train]"',
)
BLOCK = "Foosball-Block-v0"


# ------------------------------------------------------------------ Gymnasium's RecordVideo


@needs_train
def test_record_video_writes_an_mp4_of_one_episode(tmp_path):
    """gymnasium.wrappers.RecordVideo writes through moviepy, which the train extra brings."""
    import cv2

    env = gym.wrappers.RecordVideo(
        gym.make(BLOCK, render_mode="rgb_array", render_width=64, render_height=36),
        str(tmp_path / "videos"),
        episode_trigger=lambda episode: episode == 0,
        disable_logger=True,
    )
    env.reset(seed=0)
    steps, done = 0, False
    while not done:
        _, _, terminated, truncated, _ = env.step(np.zeros(1, np.float32))
        steps, done = steps + 1, terminated or truncated
    env.close()
    (video,) = (tmp_path / "videos").glob("*.mp4")
    capture = cv2.VideoCapture(str(video))
    size = (capture.get(cv2.CAP_PROP_FRAME_WIDTH), capture.get(cv2.CAP_PROP_FRAME_HEIGHT))
    frames = 0
    while capture.read()[0]:
        frames += 1
    capture.release()
    # RecordVideo keeps the frame of the reset and one a step; moviepy 2 writes all but the
    # last of them.
    assert steps <= frames <= steps + 1 and size == (64, 36)
