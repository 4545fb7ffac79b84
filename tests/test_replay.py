"""Replays in a browser: play logs and evaluations as one self-contained HTML page, opened in a
real headless Chromium (screenshots checked against what the page must show)."""

from __future__ import annotations

import io
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from play_logs import header, record

from foosball_gym import table
from foosball_gym.cli import main
from foosball_gym.evaluation import evaluate
from foosball_gym.replay import (
    Episode,
    LogError,
    Recording,
    recording_from_session,
    render_html,
    write_html,
)
from foosball_gym.replay.page import POSITION_UNIT
from foosball_gym.replay.recording import figurine_footprint
from foosball_gym.urdf.generate import COLOURS

# What foosball play --log writes by default: 20 served balls.
SESSION_SERVES = 20
PAGE_LIMIT_BYTES = 2_000_000


def colour(name: str) -> np.ndarray:
    return np.round(255 * np.array(COLOURS[name][:3]))


def open_page(browser, path: Path, errors: list[str]):
    """``path`` in a fresh page, its console errors and uncaught exceptions into ``errors``."""
    page = browser.new_page(viewport={"width": 1100, "height": 900})
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on(
        "request",
        lambda r: (
            None
            if r.url.startswith(("file:", "data:", "blob:"))
            else errors.append(f"network: {r.url}")
        ),
    )
    page.goto(path.resolve().as_uri())
    page.wait_for_function("document.body.dataset.ready")
    assert page.evaluate("document.body.dataset.ready") == "true", page.inner_text("#error")
    return page


def screenshot(page) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB")).astype(int)


# The page draws the table's outer walls and goal pockets edge to edge, +x to the right (the
# away goal) and +y up, as the rgb_array frames show it.
HALF_X = table.POCKET_BACK_X + table.WALL_THICKNESS
HALF_Y = table.FIELD_HALF_WIDTH + table.WALL_THICKNESS


def to_pixel(page, x: float, y: float) -> tuple[float, float]:
    """Where the table's point (x, y) should be on the screen."""
    box = page.locator("#table").bounding_box()
    return (
        box["x"] + (x + HALF_X) / (2 * HALF_X) * box["width"],
        box["y"] + (HALF_Y - y) / (2 * HALF_Y) * box["height"],
    )


def pixel(shot: np.ndarray, page, x: float, y: float) -> np.ndarray:
    px, py = to_pixel(page, x, y)
    return shot[int(round(py)), int(round(px))]


def near(rgb: np.ndarray, want: np.ndarray, tolerance: int = 6) -> bool:
    return bool(np.abs(rgb - want).max() <= tolerance)


def drawn_around(shot, page, x: float, y: float, want: np.ndarray, radius: float) -> float:
    """The share of the pixels within ``radius`` (m) of (x, y) drawn in ``want``."""
    px, py = to_pixel(page, x, y)
    edge_x, _ = to_pixel(page, x + radius, y)
    r = max(1, int(edge_x - px))
    rows, cols = np.mgrid[-r : r + 1, -r : r + 1]
    inside = rows**2 + cols**2 <= r * r
    patch = shot[int(py) + rows[inside], int(px) + cols[inside]]
    return float((np.abs(patch - want).max(axis=1) <= 30).mean())


# ---------------------------------------------------------------- recordings from play logs


@pytest.fixture(scope="module")
def session_log(tmp_path_factory) -> tuple[Path, object]:
    """Two served balls of the scripted keeper on the simulated table, logged."""
    pytest.importorskip("canopen")
    import gymnasium as gym

    from foosball_gym.real_table.play.stack import play_sim

    env = gym.make("Foosball-Block-v0")
    keeper = env.unwrapped.scripted_policy()
    env.close()
    log = tmp_path_factory.mktemp("play") / "session.jsonl"
    report = play_sim(
        keeper, "Foosball-Block-v0", {}, episodes=2, seed=3, camera_size=(320, 180), log_path=log
    )
    return log, report


def test_a_simulated_session_replays_each_serve_with_the_truth_the_estimate_and_detections(
    session_log,
):
    log, report = session_log
    recording = recording_from_session(log)
    assert recording.rods == ("home_keeper",)
    assert [e.label for e in recording.episodes] == ["serve 1", "serve 2"]
    assert recording.frames == report.steps
    assert recording.tracks() == ("ball", "estimate", "measured")
    records = [json.loads(line) for line in log.read_text().splitlines()[1:]]
    first = recording.episodes[0]
    # Frame k is record k: the simulator's truth, the observation's ball, the detection.
    k = 30
    rec = records[k]
    assert first.tracks["ball"][k] == pytest.approx(rec["truth"]["ball"][:2])
    assert first.tracks["estimate"][k] == pytest.approx(rec["observation"][2:4])
    assert first.joints[k] == pytest.approx(rec["truth"]["joints"]["home_keeper"])
    # The estimate follows the truth to within centimetres, as lab 2 teaches.
    gap = np.hypot(*(first.tracks["estimate"] - first.tracks["ball"]).T)
    assert np.nanmedian(gap) < 0.02
    outcomes = [e.outcome for e in recording.episodes]
    assert outcomes.count("goal against") == report.episodes - report.successes


def test_a_real_tables_log_replays_without_a_truth_and_with_the_opponents_spin_unknown(
    tmp_path,
):
    names = [
        "home_keeper_slide_pos",
        "home_keeper_spin_pos",
        "home_keeper_slide_vel",
        "home_keeper_spin_vel",
        "away_keeper_slide_pos",
        "away_keeper_slide_vel",
        "ball_x",
        "ball_y",
        "ball_vx",
        "ball_vy",
    ]
    head = header(env_id=None, interface="socketcan", observation=names)
    lines = [json.dumps({"header": head})]
    for i in range(5):
        loop = record(i, None if i == 2 else (0.01 * i, 0.0))
        loop["opponent_slides"] = {"away_keeper": 0.02}
        loop["own_state"] = {"home_keeper.slide": [0.05, 0.0], "home_keeper.spin": [0.3, 0.0]}
        loop["observation"] = [0.05, 0.3, 0, 0, 0.02, 0, 0.01 * i, 0.001, 0, 0]
        loop["new_ball"] = False
        lines.append(json.dumps(loop))
    log = tmp_path / "real.jsonl"
    log.write_text("\n".join(lines) + "\n")
    recording = recording_from_session(log)
    assert recording.rods == ("home_keeper", "away_keeper")
    (episode,) = recording.episodes
    assert recording.tracks() == ("estimate", "measured")
    assert episode.joints[0].tolist()[:3] == [0.05, 0.02, 0.3]
    assert math.isnan(episode.joints[0][3])  # the away keeper's spin: not seen
    assert np.isnan(episode.tracks["measured"][2]).all()
    assert episode.outcome == ""


BALL = ["ball_x", "ball_y"]
HEAD = json.dumps({"header": header(observation=BALL)}) + "\n"
LOOP = record(0, (0.0, 0.0)) | {"observation": [0.0, 0.0]}


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("", "is empty"),
        ('{"episode": 1}\n', "does not start with a session header"),
        (HEAD, "holds no loops, only its header"),
        (HEAD + json.dumps(LOOP | {"own_state": {}, "targets": {}}) + "\n", "name no rods"),
        (HEAD + '{"t": 0, "own_state": {"home_keeper.slide": [0, 0]}}\n', "line 2 is not a loop"),
        ("not json\n", "does not start with a session header"),
        ('{"header": [1]}\n' + json.dumps(LOOP) + "\n", "does not start with a session header"),
        ('{"header": {"observation": ["ball_x"]}}\n', "does not describe the table"),
        (
            json.dumps({"header": header(observation=BALL) | {"observation": 5}}) + "\n",
            "observation is no list of names",
        ),
        (
            json.dumps({"header": header(observation=BALL, env_id=[1])}) + "\n",
            "which this foosball_gym does not know",
        ),
        (
            json.dumps({"header": header(observation=["ball_vx"])}) + "\n" + json.dumps(LOOP),
            "the header's observation has no ball_x, ball_y",
        ),
        (HEAD + "[1, 2]\n", "line 2 is not a loop record"),
        (HEAD + '{"t": ' + "9" * 400 + "}\n", "an integer of 400 digits"),
        ("[" * 100_000 + "]" * 100_000 + "\n", "nested too deep"),
        (HEAD + "[" * 100_000 + "]" * 100_000 + "\n", "nested too deep"),
    ],
)
def test_a_file_that_is_no_play_log_is_refused_in_one_line(tmp_path, capsys, content, message):
    log = tmp_path / "bad.jsonl"
    log.write_text(content)
    with pytest.raises(LogError, match=message):
        recording_from_session(log)
    with pytest.raises(SystemExit) as exit_info:
        main(["replay", str(log), "--html", str(tmp_path / "out.html")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and message in err, err
    assert not (tmp_path / "out.html").exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["missing.jsonl", "--html", "out.html"], "missing.jsonl: no such file"),
        (["log.jsonl", "--html", "out.png"], "suffix must be .html or .htm, not .png"),
        (["log.jsonl", "--html", "nowhere/out.html"], "there is no folder nowhere"),
    ],
)
def test_replay_refuses_bad_paths_before_reading(tmp_path, monkeypatch, capsys, argv, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "log.jsonl").write_text('{"header": {}}\n')
    with pytest.raises(SystemExit) as exit_info:
        main(["replay", *argv])
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err


# ---------------------------------------------------------------- the page


def synthetic_session(serves: int, frames: int, rods: tuple[str, ...], seed: int = 0) -> Recording:
    """The largest session of its length: every rod moving, the ball always on the move and
    every track noisy, so that no frame repeats the one before."""
    rng = np.random.default_rng(seed)
    recording = Recording(title="synthetic", rods=rods)
    n = len(rods)
    for s in range(serves):
        t = np.arange(frames) / table.CONTROL_HZ
        phase = rng.uniform(0, 2 * np.pi, 2 * n)
        joints = np.concatenate(
            [0.06 * np.sin(3 * t[:, None] + phase[:n]), 1.5 * np.sin(7 * t[:, None] + phase[n:])],
            axis=1,
        )
        ball = np.stack([0.55 * np.sin(2.1 * t + s), 0.3 * np.sin(3.3 * t)], axis=1)
        estimate = ball + rng.normal(0, 0.004, ball.shape)
        measured = ball + rng.normal(0, 0.002, ball.shape)
        measured[rng.random(frames) < 0.1] = np.nan
        recording.add(
            Episode(
                f"serve {s + 1}",
                t,
                joints,
                {"ball": ball, "estimate": estimate, "measured": measured},
                outcome="no goal",
            )
        )
    return recording


@pytest.mark.parametrize(
    ("env_id", "rods"),
    [
        ("Foosball-KeeperVsKeeper-v0", ("home_keeper", "away_keeper")),
        ("Foosball-FullGame-v0", tuple(rod.name for rod in table.RODS)),
    ],
)
def test_a_20_serve_sessions_page_stays_under_2_mb_at_its_longest(env_id, rods):
    import gymnasium as gym

    longest = gym.spec(env_id).max_episode_steps
    html = render_html(synthetic_session(SESSION_SERVES, longest, rods))
    assert len(html.encode()) < PAGE_LIMIT_BYTES


def test_the_page_needs_nothing_from_outside():
    page = render_html(synthetic_session(1, 20, ("home_keeper",)))
    assert not re.search(r"<(link|img|iframe)\b|\bsrc=|https?://|@import|url\(", page)
    assert page.count("<script") == 2  # the data and the drawing code, both inline


@pytest.fixture(scope="module")
def block_page(tmp_path_factory) -> tuple[Path, Recording]:
    """The scripted keeper's evaluation through the simulated camera, as a page."""
    pytest.importorskip("filterpy")
    import gymnasium as gym

    env = gym.make("Foosball-Block-v0")
    keeper = env.unwrapped.scripted_policy()
    env.close()
    path = tmp_path_factory.mktemp("replay") / "block.html"
    result = evaluate(
        keeper,
        "Foosball-Block-v0",
        {"estimated_state": True},
        episodes=3,
        seed=5,
        replay=path,
        policy_name="scripted",
    )
    return path, result


def test_eval_writes_every_episode_with_the_estimate_beside_the_truth(block_page):
    path, result = block_page
    data = json.loads(
        re.search(r'id="replay-data">(.*?)</script>', path.read_text(), re.S).group(1)
    )
    assert [e["label"] for e in data["episodes"]] == [
        f"episode {i + 1}, seed {5 + i}" for i in range(3)
    ]
    assert data["tracks"] == ["ball", "estimate"]
    # Each episode: its reset's frame, then one a step.
    assert data["frames"] == round(result.mean_length * 3) + 3
    assert data["title"] == "scripted on Foosball-Block-v0"


def test_the_browser_draws_the_table_rods_and_both_balls_where_the_recording_has_them(
    browser, block_page
):
    path, _ = block_page
    errors: list[str] = []
    page = open_page(browser, path, errors)
    try:
        page.evaluate("replay.seek(1, 40)")
        shot = screenshot(page)
        # The frame the page shows, as the browser unpacked it, is the one recorded.
        values = page.evaluate(
            "['t','home_keeper.slide','home_keeper.spin','ball.x','ball.y','estimate.x',"
            "'estimate.y'].map(n => replay.value(n))"
        )
        t, slide, spin, bx, by, ex, ey = values
        assert t == pytest.approx(40 / table.CONTROL_HZ, abs=1e-3)
        # The field, in the simulator's colour, and the walls around it.
        assert near(pixel(shot, page, 0.3, 0.25), colour("field"))
        assert near(pixel(shot, page, 0.0, table.FIELD_HALF_WIDTH + 0.01), colour("wall"))
        assert near(pixel(shot, page, 0.65, 0.0), colour("pocket"))
        # The keeper's figurine where its joints put it, in the home team's colour.
        ((fx, fy),) = figurine_footprint("home_keeper", slide, spin)
        assert near(pixel(shot, page, fx, fy), colour("home"), 10)
        # The true ball, orange, and the estimate's ring around where the filter had it.
        ball_radius = table.BALL_RADIUS
        assert drawn_around(shot, page, bx, by, colour("ball"), ball_radius) > 0.3
        assert drawn_around(shot, page, 0.3, -0.25, colour("ball"), ball_radius) == 0
        ring = drawn_around(shot, page, ex, ey, np.array([0x15, 0x65, 0xFF]), 1.2 * ball_radius)
        assert ring > 0.1
        # The status line says where we are.
        assert "episode 2, seed 6 (2 of 3)" in page.inner_text("#status")
        assert "frame 41 of" in page.inner_text("#status")
    finally:
        page.close()
    assert errors == []


def test_the_slider_play_pause_speed_and_episode_list_move_through_the_replay(browser, block_page):
    path, _ = block_page
    errors: list[str] = []
    page = open_page(browser, path, errors)
    try:
        before = screenshot(page)
        page.locator("#time").fill("60")
        assert page.evaluate("replay.frame") == 60
        assert "frame 61 of" in page.inner_text("#status")
        assert np.abs(screenshot(page) - before).max() > 100  # the ball moved on the screen
        page.keyboard.press("ArrowRight")
        assert page.evaluate("replay.frame") == 61
        page.select_option("#speed", "4")
        assert page.evaluate("replay.speed") == 4
        page.select_option("#episode", "2")
        assert page.evaluate("[replay.episode, replay.frame]") == [2, 0]
        page.click("#play")
        page.wait_for_function("replay.frame > 10")
        page.click("#play")  # pause
        assert not page.evaluate("replay.playing")
        paused_at = page.evaluate("replay.frame")
        page.wait_for_timeout(300)
        assert page.evaluate("replay.frame") == paused_at
        # Playing on from the last frame of an episode goes into the next one.
        page.select_option("#episode", "0")
        last = page.evaluate("document.getElementById('time').max")
        page.locator("#time").fill(last)
        page.click("#play")
        page.wait_for_function("replay.episode === 1")
    finally:
        page.close()
    assert errors == []


def test_a_play_sessions_page_opens_without_console_errors(browser, session_log, tmp_path):
    log, _ = session_log
    out = tmp_path / "session.html"
    assert main(["replay", str(log), "--html", str(out)]) == 0
    errors: list[str] = []
    page = open_page(browser, out, errors)
    try:
        page.evaluate("replay.seek(0, 20)")
        assert "serve 1 (1 of 2)" in page.inner_text("#status")
        legend = page.inner_text("#legend")
        assert "true ball" in legend and "estimate" in legend and "camera detection" in legend
        measured = page.evaluate("[replay.value('measured.x'), replay.value('measured.y')]")
        records = [json.loads(line) for line in log.read_text().splitlines()[1:]]
        assert measured == pytest.approx(records[20]["ball_measured"], abs=POSITION_UNIT)
    finally:
        page.close()
    assert errors == []


# Strings that once swallowed the page's own script ("<!--<script>"), or that would end it,
# open markup or break a line in JavaScript, where a log or a path can put them.
CRAFTED = "<!--<script> </script><script>window.injected = 1</script> &amp; \u2028\u2029 \"'"


def tiny_log(path: Path, env_id: str) -> Path:
    """A session log of 40 loops of one keeper, its env id ``env_id``."""
    lines = [json.dumps({"header": header(env_id=env_id, observation=BALL)})]
    for k in range(40):
        loop = record(k, (0.01 * k - 0.2, 0.05))
        loop["own_state"]["home_keeper.slide"] = [0.01 * k, 0.0]
        loop["observation"] = [0.01 * k - 0.2, 0.05]
        lines.append(json.dumps(loop))
    path.write_text("\n".join(lines) + "\n")
    return path


def assert_shown_as_data(browser, page_path: Path, title: str) -> None:
    """The page opens and plays, shows ``title`` as text, and runs nothing it carries."""
    errors: list[str] = []
    page = open_page(browser, page_path, errors)
    try:
        shown = page.evaluate(
            "[document.querySelector('h1'), document.querySelector('title')]"
            ".map((e) => e.textContent)"
        )
        assert shown == [title, title]
        assert page.evaluate("window.injected") is None
        page.evaluate("replay.seek(0, 5)")
        assert page.evaluate("replay.frame") == 5
    finally:
        page.close()
    assert errors == []


def test_a_crafted_env_id_in_a_log_is_refused_before_any_page(tmp_path, capsys):
    # The one reader of the format knows the ids: a crafted one never reaches a page.
    log = tiny_log(tmp_path / "session.jsonl", f"Foosball-{CRAFTED}")
    out = tmp_path / "page.html"
    with pytest.raises(SystemExit) as exit_info:
        main(["replay", str(log), "--html", str(out)])
    assert exit_info.value.code == 2 and not out.exists()
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "which this foosball_gym does not know" in err


def test_a_crafted_log_file_name_is_shown_as_text(browser, tmp_path):
    name = "<!--<script> &amp; \u2028.jsonl"
    log = tiny_log(tmp_path / name, "Foosball-Block-v0")
    out = tmp_path / "page.html"
    assert main(["replay", str(log), "--html", str(out)]) == 0
    assert_shown_as_data(browser, out, f"Foosball-Block-v0: {name}")


def test_a_crafted_model_path_in_an_evaluation_page_is_shown_as_text(browser, tmp_path):
    import shutil

    import foosball_gym

    run = tmp_path / "<!--<script> & </script>"
    shutil.copytree(Path(foosball_gym.__file__).parent / "builtin" / "block", run)
    out = tmp_path / "eval.html"
    argv = ["eval", str(run / "model.zip"), "--episodes", "1", "--replay", str(out)]
    assert main(argv) == 0
    data = json.loads(re.search(r'id="replay-data">(.*?)</script>', out.read_text(), re.S).group(1))
    assert "<!--<script> & </script>" in data["title"]
    assert_shown_as_data(browser, out, data["title"])


def test_a_long_matchs_track_shows_its_last_seconds_unless_the_whole_is_asked_for(
    browser, tmp_path
):
    recording = synthetic_session(1, 30 * table.CONTROL_HZ, ("home_keeper", "away_keeper"))
    out = write_html(recording, tmp_path / "match.html")
    errors: list[str] = []
    page = open_page(browser, out, errors)
    try:
        last = 30 * table.CONTROL_HZ - 1
        page.evaluate(f"replay.seek(0, {last})")
        # The last 2 s, not the 30 s tangle.
        assert last - page.evaluate("replay.trackFrom") == pytest.approx(
            2 * table.CONTROL_HZ, abs=1
        )
        assert not page.is_checked("#whole-track")
        page.check("#whole-track")
        assert page.evaluate("replay.trackFrom") == 0
    finally:
        page.close()
    assert errors == []


def test_a_long_title_wraps_on_a_phone_width_screen(browser, tmp_path):
    recording = synthetic_session(1, 60, ("home_keeper",))
    recording.title = "/home/student/runs/" + "keeper_vs_keeper_selfplay_" * 4 + "1/model.zip on x"
    out = write_html(recording, tmp_path / "phone.html")
    page = browser.new_page(viewport={"width": 390, "height": 844})
    try:
        page.goto(out.resolve().as_uri())
        page.wait_for_function("document.body.dataset.ready")
        assert page.evaluate("document.documentElement.scrollWidth") <= 390
        box = page.locator("h1").bounding_box()
        assert box["x"] >= 0 and box["x"] + box["width"] <= 390
        assert box["height"] > 40  # on several lines
    finally:
        page.close()


def test_the_replay_module_reads_logs_without_the_simulator(tmp_path):
    code = (
        "import sys; from foosball_gym.replay import recording_from_session, write_html;"
        "assert 'pybullet' not in sys.modules and 'foosball_gym.sim' not in sys.modules"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def test_a_page_written_for_an_empty_recording_is_refused(tmp_path):
    with pytest.raises(ValueError, match="no episodes"):
        write_html(Recording(title="empty", rods=("home_keeper",)), tmp_path / "x.html")


def test_a_notebook_shows_the_page_in_a_frame_of_its_own(browser, block_page):
    from foosball_gym.replay import NotebookReplay

    path, _ = block_page
    errors: list[str] = []
    page = browser.new_page(viewport={"width": 1000, "height": 900})
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        page.set_content(f"<h1>a notebook</h1>{NotebookReplay(path)._repr_html_()}")
        page.wait_for_function("document.querySelector('iframe').contentDocument === null")
        frame = next(f for f in page.frames if f != page.main_frame)
        frame.wait_for_function("document.body && document.body.dataset.ready")
        assert frame.evaluate("document.body.dataset.ready") == "true"
        assert "episode 1, seed 5 (1 of 3)" in frame.inner_text("#status")
    finally:
        page.close()
    assert errors == []
