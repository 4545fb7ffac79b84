"""A person plays the away side from the keyboard of the GUI window: the keys, the errors, and a
game in the window with real key events."""

from __future__ import annotations

import json
import re
import sys
import threading
import time
from importlib.util import find_spec

import numpy as np
import pytest

from foosball_gym import table
from foosball_gym.cli import main
from foosball_gym.real_table.play.human import (
    KICK_ANGLE,
    KICK_TIME,
    LIFT_ANGLE,
    SLIDE_SPEED,
    HumanOpponent,
    KeyboardRod,
    human_rod,
    key_map_text,
)
from foosball_gym.registration import task_interface

needs_hardware = pytest.mark.skipif(
    any(find_spec(m) is None for m in ("can", "canopen", "cv2", "yaml")),
    reason='needs python-can, canopen, OpenCV and PyYAML: pip install -e ".[hardware]"',
)

DT = 1 / 60
NONE = frozenset()


def keys(*names: str) -> frozenset[str]:
    return frozenset(names)


def screen_y(rod: KeyboardRod) -> float:
    """Where the rod's first figurine is on the screen's up axis (world y)."""
    return rod.rod.figurine_y(rod.slide)[0]


# ---------------------------------------------------------------------------- keys to targets


def test_holding_up_and_down_slides_the_away_keeper_up_and_down_the_screen():
    rod = KeyboardRod("away_keeper", DT)
    for _ in range(3):
        rod.update(keys("up"), NONE)
    # A fixed speed while held: three steps of up move the figurine 3 * dt * speed up.
    assert screen_y(rod) == pytest.approx(3 * DT * SLIDE_SPEED)
    assert rod.slide < 0  # the away rod's frame is turned: up the screen is its negative side
    rod.update(NONE, NONE)
    assert screen_y(rod) == pytest.approx(3 * DT * SLIDE_SPEED)  # released: it stays
    for _ in range(60):
        rod.update(keys("s"), NONE)
    assert rod.slide == pytest.approx(table.rod("away_keeper").slide_limit)  # down to the stop
    assert screen_y(rod) < 0
    rod.update(keys("up", "down"), NONE)
    assert rod.slide == pytest.approx(table.rod("away_keeper").slide_limit)  # both: no move


def test_a_key_tapped_between_two_steps_moves_the_rod_for_one_step():
    rod = KeyboardRod("away_keeper", DT)
    rod.update(NONE, keys("w"))  # pressed and released before the step read the keys
    assert screen_y(rod) == pytest.approx(DT * SLIDE_SPEED)


def test_a_kick_swings_the_figurines_forward_and_back_once_per_press():
    rod = KeyboardRod("away_keeper", DT)
    spins = [rod.update(keys("space"), keys("space"))[1]]
    spins += [rod.update(keys("space"), NONE)[1] for _ in range(30)]  # held on: no new kick
    forward = round(KICK_TIME / DT)
    assert spins[:forward] == [KICK_ANGLE] * forward
    assert spins[forward:] == [0.0] * (len(spins) - forward)
    assert rod.update(keys("left"), keys("left"))[1] == KICK_ANGLE  # left kicks too
    # Forward is towards the goal the rod's team attacks: the home goal, on the left.
    x, _ = rod.rod.figurine_swing(KICK_ANGLE)
    assert x < rod.rod.x


def test_holding_right_lifts_the_figurines_towards_the_persons_goal():
    rod = KeyboardRod("away_keeper", DT)
    assert rod.update(keys("right"), keys("right"))[1] == -LIFT_ANGLE
    assert rod.update(keys("d"), NONE)[1] == -LIFT_ANGLE
    assert rod.update(NONE, NONE)[1] == 0.0
    x, _ = rod.rod.figurine_swing(-LIFT_ANGLE)
    assert x > rod.rod.x


def test_the_person_drives_one_rod_and_the_opponent_policy_the_others():
    layout = task_interface("Foosball-FullGame-v0").layout
    events = iter([(keys("up"), keys("up")), (keys("up"), keys("space"))])
    seen = []

    def team(obs):
        seen.append(obs)
        return np.full(8, 0.5)

    person = HumanOpponent(lambda: next(events), layout, "away_midfield", DT, others=team)
    action = person(np.zeros(36))
    limit = table.rod("away_midfield").slide_limit
    # Away rods in the action: keeper, defense, midfield, offense; each slide then spin.
    np.testing.assert_allclose(action, [0.5, 0.5, 0.5, 0.5, -DT / limit, 0.0, 0.5, 0.5])
    action = person(np.ones(36))
    assert action[4] == pytest.approx(-2 * DT / limit)
    assert action[5] == pytest.approx(KICK_ANGLE / table.SPIN_LIMIT)
    assert len(seen) == 2


def test_the_keeper_against_keeper_opponent_is_the_person_alone():
    layout = task_interface("Foosball-KeeperVsKeeper-v0").layout

    def no_one(obs):
        raise AssertionError("nobody else plays the away side")

    person = HumanOpponent(lambda: (keys("down"), NONE), layout, "away_keeper", DT, no_one)
    action = person(np.zeros(10))
    np.testing.assert_allclose(action, [DT / table.rod("away_keeper").slide_limit, 0.0])


def test_a_person_plays_an_away_rod_of_a_two_player_task_only():
    full = task_interface("Foosball-FullGame-v0").layout
    assert human_rod("Foosball-FullGame-v0", full) == "away_keeper"
    assert human_rod("Foosball-FullGame-v0", full, "offense") == "away_offense"
    assert human_rod("Foosball-FullGame-v0", full, "away_defense") == "away_defense"
    with pytest.raises(ValueError, match="allowed: keeper, defense, midfield, offense"):
        human_rod("Foosball-FullGame-v0", full, "striker")
    block = task_interface("Foosball-Block-v0").layout
    with pytest.raises(
        ValueError, match="Foosball-KeeperVsKeeper-v0, Foosball-FullGame-v0"
    ) as error:
        human_rod("Foosball-Block-v0", block)
    assert "Foosball-Block-v0 has no away side" in str(error.value)


def test_the_key_map_names_every_key():
    text = key_map_text()
    for key in ("up", "down", "left", "right", "space", "w", "s", "a", "d"):
        assert re.search(rf"\b{key}\b", text), key


# ---------------------------------------------------------------------------- the command


@needs_hardware
@pytest.mark.parametrize(
    "extra, message",
    [
        (
            ["--env", "Foosball-Block-v0", "--human"],
            "--human: Foosball-Block-v0 has no away side for a person to play; two-player "
            "environments: Foosball-KeeperVsKeeper-v0, Foosball-FullGame-v0",
        ),
        (
            ["--env", "Foosball-FullGame-v0", "--human-rod", "striker"],
            "--human-rod striker: Foosball-FullGame-v0 has no away rod 'striker' to play; "
            "allowed: keeper, defense, midfield, offense",
        ),
        (
            ["--env", "Foosball-KeeperVsKeeper-v0", "--human-rod", "defense"],
            "allowed: keeper",
        ),
    ],
)
def test_play_refuses_a_person_where_there_is_no_such_rod(extra, message, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["play", "scripted", "--table", "sim", *extra])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err


@needs_hardware
@pytest.mark.parametrize("option", ["--gui", "--human"])
def test_play_in_the_gui_without_a_display_is_a_one_line_error(option, capsys, monkeypatch):
    if not sys.platform.startswith("linux"):
        pytest.skip("the GUI needs DISPLAY on Linux only")
    monkeypatch.delenv("DISPLAY", raising=False)
    argv = ["play", "scripted", "--env", "Foosball-KeeperVsKeeper-v0", "--table", "sim"]
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, option])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{option} opens the PyBullet GUI, which needs a display" in err


@needs_hardware
def test_the_window_of_a_table_without_a_display_says_so(monkeypatch):
    from foosball_gym.real_table.virtual.viewer_process import ViewerProcess, WindowError

    monkeypatch.setenv("DISPLAY", ":7999")  # no X server there
    with pytest.raises(WindowError, match="could not open its window on the display ':7999'"):
        ViewerProcess(["home_keeper", "away_keeper"])


# ---------------------------------------------------------------------------- in the window


def find_window(window):
    """PyBullet's window among ``window`` and its descendants, or None."""
    name = window.get_wm_name()
    if name and "Bullet Physics" in name:
        return window
    for child in window.query_tree().children:
        found = find_window(child)
        if found is not None:
            return found
    return None


class XKeyboard:
    """Real key events for PyBullet's window, sent into the X server with XTEST."""

    def __init__(self, connection) -> None:
        from Xlib import XK, X
        from Xlib.ext import xtest

        self.conn, self._X, self._XK, self._xtest = connection, X, XK, xtest
        self.held: set[str] = set()

    def window(self, timeout: float = 60.0):
        """Wait for PyBullet's window and give it the keyboard."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = find_window(self.conn.screen().root)
            if found is not None:
                # Pointer inside and input focus on it, as a person's click would leave them.
                found.warp_pointer(200, 200)
                found.set_input_focus(self._X.RevertToParent, self._X.CurrentTime)
                self.conn.sync()
                return found
            time.sleep(0.05)
        raise AssertionError("PyBullet's window did not appear")

    def _send(self, event: int, key: str) -> None:
        code = self.conn.keysym_to_keycode(self._XK.string_to_keysym(key))
        self._xtest.fake_input(self.conn, event, code)
        self.conn.sync()

    def press(self, key: str) -> None:
        self._send(self._X.KeyPress, key)
        self.held.add(key)

    def release(self, key: str) -> None:
        self._send(self._X.KeyRelease, key)
        self.held.discard(key)

    def release_all(self) -> None:
        for key in list(self.held):
            self.release(key)


@pytest.fixture
def keyboard(display):
    xlib = pytest.importorskip(
        "Xlib.display", reason="the key events go through python-xlib: pip install python-xlib"
    )
    connection = xlib.Display(display)
    if not connection.has_extension("XTEST"):
        connection.close()
        pytest.skip(f"the X server {display} has no XTEST extension to send key events with")
    board = XKeyboard(connection)
    yield board
    board.release_all()
    connection.close()


class Steps:
    """The policy, counting its decisions and holding the game at gates: the keys change
    between known control steps, however late the window passes them on."""

    def __init__(self, policy, gates: list[int]) -> None:
        self.policy = policy
        self.count = 0
        self.finished = False
        self.gates = {step: threading.Event() for step in gates}
        self._changed = threading.Condition()

    def __call__(self, observation):
        with self._changed:
            self.count += 1
            self._changed.notify_all()
        gate = self.gates.get(self.count)
        if gate is not None:
            gate.wait(timeout=30)  # lock-step: the table waits for the loop
        return self.policy(observation)

    def wait(self, count: int, timeout: float = 60.0) -> bool:
        """Wait for the ``count``-th decision; False where the game ended first."""
        with self._changed:
            self._changed.wait_for(lambda: self.count >= count or self.finished, timeout)
            return self.count >= count

    def finish(self) -> None:
        with self._changed:
            self.finished = True
            self._changed.notify_all()
        for gate in self.gates.values():
            gate.set()


# Keys held over control steps [start, end): 15 steps move the target across the keeper's
# whole range (0.25 m) at 1 m/s; the drive and the camera follow within a few steps more.
SCRIPT = (("Up", 10, 40), ("Down", 50, 80))
# How long the game waits at a gate for the window to read a key that changed (s): its
# process gives way to the table's, and on a busy machine reads its keyboard late.
SETTLE_S = 0.5


def press_script(board: XKeyboard, steps: Steps, pressed: list) -> None:
    try:
        board.window()
        for key, start, end in SCRIPT:
            for step, change in ((start, board.press), (end, board.release)):
                if not steps.wait(step):
                    return
                change(key)
                pressed.append((key, steps.count))
                time.sleep(SETTLE_S)
                steps.gates[step].set()
    finally:
        board.release_all()


@needs_hardware
def test_a_person_plays_the_away_keeper_in_the_window_with_real_key_events(
    keyboard, tmp_path, monkeypatch, capsys
):
    """``foosball play --human``: X key events sent into PyBullet's window move the away
    keeper, as the policy's camera sees it, and the game runs to its end with the score.

    The table plays lock-step paced to the wall clock, as the CLI chooses for a person: on the
    wall clock itself (``--realtime``) PyBullet's window, whose loop never idles, left a
    machine of two cores shared with other work too slow to keep the loop's 50 ms watchdog fed.
    """
    from foosball_gym.real_table.play import stack

    real_play_sim = stack.play_sim
    chosen: dict = {}

    def lockstep_play_sim(policy, *args, **kwargs):
        chosen.update(kwargs)
        steps = Steps(policy, [step for _, *phase in SCRIPT for step in phase])
        script = threading.Thread(target=press_script, args=(keyboard, steps, pressed))
        script.start()
        try:
            return real_play_sim(steps, *args, **kwargs)
        finally:
            steps.finish()
            script.join(timeout=10)

    pressed: list = []
    monkeypatch.setattr(stack, "play_sim", lockstep_play_sim)
    log = tmp_path / "game.jsonl"
    argv = ["play", "scripted", "--env", "Foosball-KeeperVsKeeper-v0", "--table", "sim"]
    argv += ["--human", "--episodes", "3", "--env-kwarg", "stagnation_steps=60"]
    argv += ["--camera", "320x180", "--no-status", "--log", str(log)]
    assert main(argv) == 0

    assert chosen["human"] == "keeper" and chosen["gui"]
    assert chosen["pace"] and not chosen["realtime"]
    out = capsys.readouterr().out
    assert "You play the away keeper" in out and key_map_text() in out
    score = (
        r"3 episodes of Foosball-KeeperVsKeeper-v0: success [\d.]+ %, goals for \d+, against \d+"
    )
    assert re.search(score, out), out
    assert [key for key, _ in pressed] == ["Up", "Up", "Down", "Down"], pressed

    records = log.read_text().splitlines()[1:]  # after the header
    # None where the camera saw no rod, or no new frame was due (after a serve).
    slides = [json.loads(line)["opponent_slides"].get("away_keeper") for line in records]
    limit = table.rod("away_keeper").slide_limit
    (_, up_at), (_, up_end), (_, down_at), (_, down_end) = pressed
    assert len(slides) > down_end, len(slides)

    def seen(first: int, end: int) -> list[float]:  # the camera's slides, steps [first, end)
        return [s for s in slides[first - 1 : end - 1] if s is not None]

    # Untouched, the keeper stays in the middle; up takes it to the top of the screen (the
    # away rod's negative side), down to the bottom.
    assert max(map(abs, seen(1, up_at)), default=1) < 0.01, slides[:up_at]
    assert max(seen(up_end - 5, up_end), default=0) < -0.9 * limit, slides[up_at:up_end]
    assert min(seen(down_end - 5, down_end), default=0) > 0.9 * limit, slides[down_at:down_end]


def test_the_window_writes_the_score_above_the_table(display):
    pytest.importorskip("Xlib.display", reason="screenshots go through python-xlib")
    from Xlib import X
    from Xlib.display import Display

    from foosball_gym.real_table.virtual.viewer_process import ViewerProcess

    def dark_pixels(window) -> int:
        """Near-black pixels in the part of ``window`` on the screen."""
        screen = connection.screen()
        origin = screen.root.translate_coords(window, 0, 0)
        size = window.get_geometry()
        x0, y0 = max(origin.x, 0), max(origin.y, 0)
        x1 = min(origin.x + size.width, screen.width_in_pixels)
        y1 = min(origin.y + size.height, screen.height_in_pixels)
        shot = screen.root.get_image(x0, y0, x1 - x0, y1 - y0, X.ZPixmap, 0xFFFFFFFF)
        pixels = np.frombuffer(shot.data, np.uint8).reshape(y1 - y0, x1 - x0, 4)
        return int((pixels[:, :, :3].max(axis=2) < 60).sum())

    # The window in a process of its own, as `foosball play --gui` opens it: a PyBullet GUI
    # connected in the test's own process, after other windows, once hung there for good.
    sim = ViewerProcess(["home_keeper", "away_keeper"])
    connection = Display(display)
    try:
        window = find_window(connection.screen().root)
        assert window is not None
        time.sleep(1.0)  # the window draws its first frames
        before = dark_pixels(window)
        sim.show_text(["serve 1 of 3   goals for 0, against 0"])
        time.sleep(1.0)
        written = dark_pixels(window)
        sim.show_text([])
        time.sleep(1.0)
        cleared = dark_pixels(window)
    finally:
        connection.close()
        sim.close()
    # Black letters on the light background beyond the table's side wall.
    assert written > before + 200, (before, written)
    assert cleared < before + 50, (before, cleared)
