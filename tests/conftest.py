"""Shared fixtures: a virtual display for the PyBullet GUI, fresh environments."""

from __future__ import annotations

import os
import shutil
import subprocess
import time

import gymnasium as gym
import pytest

import foosball_gym  # noqa: F401  (registers the ids)


@pytest.fixture(scope="session")
def display() -> str:
    """A display for render_mode='human': the user's, or a private Xvfb started here."""
    if os.environ.get("DISPLAY"):
        yield os.environ["DISPLAY"]
        return
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        pytest.skip("render_mode='human' needs a display: install Xvfb (Debian: xvfb)")
    number = f":{90 + os.getpid() % 500}"
    proc = subprocess.Popen(
        [xvfb, number, "-screen", "0", "1280x720x24", "-nolisten", "tcp"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    socket = f"/tmp/.X11-unix/X{number[1:]}"
    for _ in range(100):
        if os.path.exists(socket):
            break
        time.sleep(0.05)
    os.environ["DISPLAY"] = number
    try:
        yield number
    finally:
        del os.environ["DISPLAY"]
        proc.terminate()
        proc.wait(timeout=10)


@pytest.fixture
def make_env():
    """gym.make that closes what it made at the end of the test."""
    made = []

    def make(env_id: str, **kwargs):
        env = gym.make(env_id, **kwargs)
        made.append(env)
        return env

    yield make
    for env in made:
        env.close()
