"""Replays a student can scrub through: a logged play session or an evaluation's episodes as
one self-contained HTML page (``foosball replay``, ``foosball eval --replay``).

Reading logs and writing pages needs neither the simulator nor a browser: the page draws the
table itself, on a canvas, from the frames packed inside it.
"""

from foosball_gym.replay.env_recorder import EnvRecorder
from foosball_gym.replay.page import NotebookReplay, check_page_path, render_html, write_html
from foosball_gym.replay.recording import TRACKS, Episode, Recording
from foosball_gym.replay.session_log import LogError, recording_from_session

__all__ = [
    "TRACKS",
    "check_page_path",
    "EnvRecorder",
    "Episode",
    "LogError",
    "NotebookReplay",
    "Recording",
    "recording_from_session",
    "render_html",
    "write_html",
]
