"""Shared fixtures: a virtual display for the PyBullet GUI, a headless browser, fresh
environments."""

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


# Chromium as the system installs it (Debian: the chromium package; .ci/run installs it). The
# flags keep it from reaching for the network: a test page must need none.
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
BROWSER_FLAGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


@pytest.fixture(scope="session")
def browser():
    """A headless Chromium driven through Playwright (each page gets a fresh profile)."""
    executable = next((path for path in map(shutil.which, BROWSERS) if path), None)
    if executable is None:
        pytest.skip("needs Chromium from the system's packages (Debian: apt-get install chromium)")
    sync_api = pytest.importorskip(
        "playwright.sync_api",
        reason='drives the browser through Playwright: pip install -e ".[test]"',
    )
    with sync_api.sync_playwright() as playwright:
        launched = playwright.chromium.launch(executable_path=executable, args=BROWSER_FLAGS)
        try:
            yield launched
        finally:
            launched.close()


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
