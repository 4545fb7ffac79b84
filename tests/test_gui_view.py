"""What a student sees in the PyBullet window: screenshots of it on a virtual display, checked
against the table as the rgb_array frames draw it."""

from __future__ import annotations

import time

import numpy as np
import pytest

from foosball_gym import table

pytest.importorskip("Xlib.display", reason="screenshots go through python-xlib")

ALL_RODS = [rod.name for rod in table.RODS]
SETTLE_S = 1.5  # the window draws what it was sent


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


def grab(connection, window) -> np.ndarray:
    """The window's pixels as they are on the screen, (H, W, 3) RGB."""
    from Xlib import X

    screen = connection.screen()
    origin = screen.root.translate_coords(window, 0, 0)
    size = window.get_geometry()
    x0, y0 = max(origin.x, 0), max(origin.y, 0)
    x1 = min(origin.x + size.width, screen.width_in_pixels)
    y1 = min(origin.y + size.height, screen.height_in_pixels)
    shot = screen.root.get_image(x0, y0, x1 - x0, y1 - y0, X.ZPixmap, 0xFFFFFFFF)
    pixels = np.frombuffer(shot.data, np.uint8).reshape(y1 - y0, x1 - x0, 4)
    return pixels[:, :, [2, 1, 0]].astype(int)


def like(shot: np.ndarray, rgb, tolerance: int = 12) -> np.ndarray:
    return np.abs(shot - np.asarray(rgb)).max(axis=2) <= tolerance


def rgb_array_field_colour() -> np.ndarray:
    """The field's colour in the frames of render_mode='rgb_array'."""
    from foosball_gym.sim import View

    view = View([table.rod("home_keeper")], gui=False)
    try:
        frame = view.render(320, 180)
    finally:
        view.close()
    return frame[90, 200].astype(int)  # the middle of the field's right half


@pytest.fixture
def window(display):
    """A GUI window on the whole table, as ``foosball play --gui`` opens it, and a function
    that shows a scene and text and takes a screenshot."""
    from Xlib.display import Display

    from foosball_gym.real_table.virtual.viewer_process import ViewerProcess

    opened = []
    connection = Display(display)

    def open_window(view: str = "top"):
        viewer = ViewerProcess(ALL_RODS, view)
        opened.append(viewer)
        return viewer

    def shoot(viewer, lines=(), ball=(0.3, -0.15, table.BALL_RADIUS)) -> np.ndarray:
        viewer.show([0.0] * (2 * len(ALL_RODS)), ball)
        viewer.show_text(list(lines))
        time.sleep(SETTLE_S)
        found = find_window(connection.screen().root)
        assert found is not None
        return grab(connection, found)

    yield open_window, shoot
    connection.close()
    for viewer in opened:
        viewer.close()


def test_the_window_shows_the_table_as_the_rgb_array_frames_do_framed_whole_with_clear_bands(
    window,
):
    from foosball_gym.sim.view import WINDOW_BACKGROUND

    open_window, shoot = window
    viewer = open_window()
    plain = shoot(viewer)
    height, width, _ = plain.shape
    # The field in the colour the CPU renderer draws it in (it was near-black here).
    field = like(plain, rgb_array_field_colour(), 12)
    assert (
        field[height // 2 - 40 : height // 2 + 40, width // 2 - 40 : width // 2 + 40].mean() > 0.5
    )
    assert field.mean() > 0.2
    walls = like(plain, np.round(255 * 0.89 * np.array(table.COLOURS["wall"][:3])), 25)
    assert walls.mean() > 0.05
    # The table fills the window's width and nothing of it leaves the window: beyond it,
    # only the background.
    background = like(plain, np.round(255 * np.array(WINDOW_BACKGROUND)), 6)
    rows = np.flatnonzero(~background.all(axis=1))
    cols = np.flatnonzero(~background.all(axis=0))
    top, bottom, left, right = rows[0], rows[-1], cols[0], cols[-1]
    assert left > 0 and right < width - 1 and top > 0.08 * height and bottom < 0.92 * height
    assert right - left > 0.9 * width
    # The whole table: both goals (the pockets' near-black) at the window's two sides.
    pockets = like(plain, np.round(255 * 0.89 * np.array(table.COLOURS["pocket"][:3])), 15)
    assert pockets[:, : width // 4].sum() > 500 and pockets[:, 3 * width // 4 :].sum() > 500
    # The ball, orange, right of the middle and below it (x = 0.3, y = -0.15).
    ys, xs = np.nonzero(like(plain, [227, 125, 0], 40))
    assert len(xs) > 20 and xs.mean() > width / 2 and ys.mean() > height / 2

    # The score goes into the band above the table, the key help into the one below: the
    # table's pixels are left as they were.
    shot = shoot(viewer, ["serve 1 of 3   goals for 0, against 0", "you: away keeper (right)"])
    changed = np.abs(shot - plain).max(axis=2) > 60
    assert changed[:top].sum() > 300 and changed[bottom + 1 :].sum() > 300
    assert changed[top : bottom + 1].sum() < 50
    shot = shoot(viewer, [])
    assert (np.abs(shot - plain).max(axis=2) > 60).sum() < 50


def test_the_window_looks_from_the_players_side_with_his_goal_nearest(window):
    open_window, shoot = window
    viewer = open_window("away")
    # The ball near the away goal, at y > 0: from behind the away goal the screen's right.
    shot = shoot(viewer, ["serve 1 of 3"], ball=(0.45, 0.12, table.BALL_RADIUS))
    height, width, _ = shot.shape
    field = like(shot, rgb_array_field_colour(), 12)
    rows = np.flatnonzero(field.any(axis=1))
    # Seen along the table: the near end is wider than the far one.
    near_row, far_row = rows[-5], rows[5]
    assert field[near_row].sum() > 1.3 * field[far_row].sum()
    # The person's goal (the away pocket) at the bottom of the window, the ball near it and
    # to the right of the middle.
    pockets = like(shot, np.round(255 * 0.89 * np.array(table.COLOURS["pocket"][:3])), 15)
    ys, _ = np.nonzero(pockets[:, width // 3 : 2 * width // 3])
    assert np.median(ys) > 0.7 * height
    ys, xs = np.nonzero(like(shot, [227, 125, 0], 40))
    assert len(xs) > 10 and xs.mean() > width / 2 and ys.mean() > height / 2


# ------------------------------------------------------------- the keys from the player's side

DT = 1.0 / table.CONTROL_HZ


def test_from_the_players_side_the_keys_follow_that_screen():
    from foosball_gym.real_table.play.human import KICK_ANGLE, LIFT_ANGLE, SLIDE_SPEED, KeyboardRod

    rod = KeyboardRod("away_keeper", DT, view="away")
    none = frozenset()
    # From behind the away goal the screen's right is world +y.
    for _ in range(3):
        rod.update(frozenset({"right"}), none)
    assert rod.rod.figurine_y(rod.slide)[0] == pytest.approx(3 * DT * SLIDE_SPEED)
    rod.update(frozenset({"a"}), none)
    assert rod.rod.figurine_y(rod.slide)[0] == pytest.approx(2 * DT * SLIDE_SPEED)
    # Up the screen is the policy's goal: up kicks there, down lifts towards the person.
    spin = rod.update(frozenset({"up"}), frozenset({"up"}))[1]
    assert spin == KICK_ANGLE and rod.rod.figurine_swing(spin)[0] < rod.rod.x
    for _ in range(30):
        rod.update(none, none)
    assert rod.update(frozenset({"s"}), none)[1] == -LIFT_ANGLE
    # Up and down no longer slide.
    before = rod.slide
    rod.update(frozenset({"w"}), none)
    assert rod.slide == before


def test_a_person_plays_from_the_top_or_their_own_side_only():
    from foosball_gym.real_table.play.human import KeyboardRod, key_map_text

    with pytest.raises(ValueError, match="top or away, not 'home'"):
        KeyboardRod("away_keeper", DT, view="home")
    assert "left / a" in key_map_text("away") and "up / w" in key_map_text("top")


def test_play_refuses_a_view_without_a_window(capsys):
    from foosball_gym.cli import main

    argv = ["play", "scripted", "--env", "Foosball-KeeperVsKeeper-v0", "--table", "sim"]
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, "--view", "away"])
    assert exit_info.value.code == 2
    assert "--view chooses where the GUI window looks from: give --gui or --human" in (
        capsys.readouterr().err
    )


def test_an_unknown_view_is_refused_with_the_allowed_ones():
    from foosball_gym.sim import View

    with pytest.raises(ValueError, match="no view 'side'; allowed: top, away, home"):
        View([table.rod("home_keeper")], gui=False, view="side")
