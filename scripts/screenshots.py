"""Take the docs' pictures of what a student sees: the GUI window and a replay page.

    python scripts/screenshots.py [--out docs/images]

Writes ``gui-top.png`` and ``gui-away.png`` (the PyBullet window of ``foosball play --human``
from above and from the person's side, on a virtual display: needs Xvfb and python-xlib) and
``replay.png`` (a ``foosball eval --replay`` page in headless Chromium, paused in a missed
shot: needs Chromium and Playwright, the test extra's). Prints the pages' sizes.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import shutil
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import gymnasium as gym
import numpy as np

from foosball_gym import load_policy, table
from foosball_gym.evaluation import evaluate
from foosball_gym.real_table.play.human import KEY_HINTS

OUT = Path(__file__).resolve().parents[1] / "docs" / "images"
BROWSER_FLAGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


@contextlib.contextmanager
def virtual_display() -> Iterator[str]:
    """DISPLAY as it is, or a private Xvfb for the time being."""
    if os.environ.get("DISPLAY"):
        yield os.environ["DISPLAY"]
        return
    number = f":{200 + os.getpid() % 500}"
    xvfb = subprocess.Popen(
        ["Xvfb", number, "-screen", "0", "1280x720x24", "-nolisten", "tcp"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.environ["DISPLAY"] = number
    try:
        socket = Path(f"/tmp/.X11-unix/X{number[1:]}")
        for _ in range(200):
            if socket.exists():
                break
            time.sleep(0.05)
        yield number
    finally:
        del os.environ["DISPLAY"]
        xvfb.terminate()
        xvfb.wait(timeout=10)


def mid_game_scene() -> tuple[list[float], list[float]]:
    """The rods and the ball a second into a full game of the scripted teams."""
    env = gym.make("Foosball-FullGame-v0")
    policy = env.unwrapped.scripted_policy()
    obs, _ = env.reset(seed=4)
    for _ in range(60):
        obs, *_ = env.step(policy(obs))
    positions, ball = env.unwrapped.sim.scene()
    env.close()
    return list(positions), list(ball)


def window_shot(view: str, path: Path) -> None:
    from PIL import Image
    from Xlib import X
    from Xlib.display import Display

    from foosball_gym.real_table.virtual.viewer_process import ViewerProcess

    positions, ball = mid_game_scene()
    viewer = ViewerProcess([rod.name for rod in table.RODS], view)
    try:
        viewer.show(positions, ball)
        side = "right" if view == "top" else "near"
        viewer.show_text(
            [
                "serve 3 of 20   goals for 1, against 1",
                f"you: away keeper ({side})   {KEY_HINTS[view]}",
            ]
        )
        time.sleep(2.0)
        connection = Display()
        root = connection.screen().root
        window = find_window(root)
        geometry = window.get_geometry()
        origin = root.translate_coords(window, 0, 0)
        shot = root.get_image(
            origin.x, origin.y, geometry.width, geometry.height, X.ZPixmap, 0xFFFFFFFF
        )
        pixels = np.frombuffer(shot.data, np.uint8).reshape(geometry.height, geometry.width, 4)
        Image.fromarray(pixels[:, :, [2, 1, 0]].copy()).save(path)
        connection.close()
    finally:
        viewer.close()


def find_window(window):
    name = window.get_wm_name()
    if name and "Bullet Physics" in name:
        return window
    for child in window.query_tree().children:
        found = find_window(child)
        if found is not None:
            return found
    return None


def replay_shot(path: Path) -> None:
    from PIL import Image
    from playwright.sync_api import sync_playwright

    keeper = load_policy("builtin:block")
    late = {"estimated_state": True, "camera_noise": {"latency_s": 0.1}}
    with tempfile.TemporaryDirectory() as folder:
        page_path = Path(folder) / "late-camera.html"
        result = evaluate(
            keeper,
            "Foosball-Block-v0",
            late,
            episodes=20,
            seed=1000,
            replay=page_path,
            policy_name="builtin:block",
        )
        print(f"{page_path.name}: 20 episodes, {page_path.stat().st_size / 1e3:.0f} kB")
        print(result.table())
        browser_path = next(filter(None, map(shutil.which, ("chromium", "chromium-browser"))))
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=browser_path, args=BROWSER_FLAGS)
            page = browser.new_page(viewport={"width": 1000, "height": 820})
            page.goto(page_path.as_uri())
            page.wait_for_function("document.body.dataset.ready === 'true'")
            # The longest missed shot, a fifth of a second before the goal.
            episodes = page.evaluate(
                "JSON.parse(document.getElementById('replay-data').textContent).episodes"
            )
            missed = [(e["frames"], k) for k, e in enumerate(episodes) if "failure" in e["outcome"]]
            frames, k = max(missed)
            page.evaluate(f"replay.seek({k}, {max(0, frames - 13)})")
            picture = page.screenshot(full_page=True)
            browser.close()
    Image.open(io.BytesIO(picture)).convert("RGB").save(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    with virtual_display():
        for view in ("top", "away"):
            window_shot(view, args.out / f"gui-{view}.png")
    replay_shot(args.out / "replay.png")
    for name in ("gui-top.png", "gui-away.png", "replay.png"):
        print(f"wrote {args.out / name}")


if __name__ == "__main__":
    main()
