"""A :class:`~foosball_gym.replay.recording.Recording` as one self-contained HTML page.

The page needs no server and no network: the frames, the drawing code and the styles are all
inside it, and any current browser opens it from the disk. The table is drawn on a canvas from
above, as the rgb_array frames show it (the simulator's colours); a time slider, play/pause,
speed and the episodes' list move through it.

The frames travel packed: each value quantised (0.1 mm, 1 mrad, 1 ms), stored channel by
channel as the change from the frame before, deflated and base64-encoded. A still rod is then
a run of zeros, and a 20-serve session of 60 Hz frames is tens of kilobytes where plain JSON
numbers took megabytes. The browser inflates it with its own ``DecompressionStream``.
"""

from __future__ import annotations

import base64
import html
import json
import re
import zlib
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from foosball_gym import table
from foosball_gym.replay.recording import Recording, rod_geometry, table_geometry

#: Units of the packed values: positions in 0.1 mm, angles in mrad, times in ms.
POSITION_UNIT = 1e-4
ANGLE_UNIT = 1e-3
TIME_UNIT = 1e-3
PAGE_SUFFIXES = (".html", ".htm")
#: A packed value that stands for none (NaN: an undetected ball, an unknown joint).
MISSING = -(2**30)
# Beyond this a value is no position on a table (or an angle in two turns) but a runaway.
_LIMIT = 2**29


def _colours() -> dict[str, list[float]]:
    return {name: list(rgba[:3]) for name, rgba in table.COLOURS.items()}


def _quantise(values: np.ndarray, unit: float) -> np.ndarray:
    """``values / unit`` rounded, :data:`MISSING` where NaN or beyond any table."""
    out = np.full(values.shape, MISSING, dtype=np.int64)
    finite = np.isfinite(values)
    scaled = np.round(values[finite] / unit)
    out[finite] = np.where(np.abs(scaled) < _LIMIT, scaled, MISSING)
    return out


def pack(recording: Recording) -> tuple[dict[str, Any], str]:
    """The page's description of the channels, and their values packed (base64 text).

    Channels, in order: ``t``; each rod's slide, then each rod's spin; then x and y of each
    ball track the recording holds. Episodes lie one after the other in every channel.
    """
    tracks = recording.tracks()
    rods = recording.rods
    channels: list[tuple[str, float]] = [("t", TIME_UNIT)]
    channels += [(f"{name}.slide", POSITION_UNIT) for name in rods]
    channels += [(f"{name}.spin", ANGLE_UNIT) for name in rods]
    channels += [(f"{track}.{axis}", POSITION_UNIT) for track in tracks for axis in "xy"]
    columns = []
    for episode in recording.episodes:
        n = episode.frames
        cols = [episode.t[:, None], episode.joints]
        for track in tracks:
            cols.append(episode.tracks.get(track, np.full((n, 2), np.nan)))
        columns.append(np.concatenate(cols, axis=1) if n else np.zeros((0, len(channels))))
    values = np.concatenate(columns) if columns else np.zeros((0, len(channels)))
    quantised = np.stack(
        [_quantise(values[:, k], unit) for k, (_, unit) in enumerate(channels)], axis=1
    )
    # Channel by channel, each value as its change from the one before: int32 holds them all,
    # since no value's size reaches 2**30.
    deltas = np.diff(quantised.T, axis=1, prepend=0).astype("<i4")
    packed = zlib.compress(deltas.tobytes(), 9)
    meta = {
        "channels": [{"name": name, "unit": unit} for name, unit in channels],
        "frames": int(len(quantised)),
        "missing": MISSING,
    }
    return meta, base64.b64encode(packed).decode("ascii")


def page_data(recording: Recording) -> dict[str, Any]:
    """Everything the page's script reads, as one JSON-ready object."""
    meta, data = pack(recording)
    episodes, start = [], 0
    for episode in recording.episodes:
        episodes.append(
            {
                "label": episode.label,
                "start": start,
                "frames": episode.frames,
                "outcome": episode.outcome,
                "events": [[int(frame), text] for frame, text in episode.events],
            }
        )
        start += episode.frames
    return {
        "title": recording.title,
        "notes": list(recording.notes),
        "table": table_geometry(),
        "colours": _colours(),
        "rods": rod_geometry(recording.rods),
        "tracks": list(recording.tracks()),
        "episodes": episodes,
        **meta,
        "data": data,
    }


def _asset(name: str) -> str:
    return (resources.files("foosball_gym.replay") / "assets" / name).read_text()


# What a <script> element's text must not hold as written: "</script" ends it, and "<!--"
# followed by "<script" puts the parser where the element's own end tag no longer ends it (the
# page's script is swallowed, the page left blank). "&" and the line separators are escaped as
# well, so the text means the same read as HTML, JavaScript or JSON.
_SCRIPT_ESCAPES = {
    ord("<"): "\\u003c",
    ord(">"): "\\u003e",
    ord("&"): "\\u0026",
    0x2028: "\\u2028",
    0x2029: "\\u2029",
}


def _json_in_script(value: Any) -> str:
    """JSON that a ``<script>`` element holds as data, whatever strings it carries."""
    return json.dumps(value, separators=(",", ":")).translate(_SCRIPT_ESCAPES)


def render_html(recording: Recording) -> str:
    """The page's text."""
    if not recording.episodes:
        raise ValueError(f"{recording.title!r} has no episodes to replay")
    parts = {
        "title": html.escape(recording.title),
        "style": _asset("replay.css"),
        "data": _json_in_script(page_data(recording)),
        "script": _asset("replay.js"),
    }
    # In one pass: a title or a script holding "{{data}}" is left as it is.
    return re.sub(r"\{\{(\w+)\}\}", lambda m: parts[m.group(1)], _asset("replay.html"))


def check_page_path(path: str | Path) -> Path:
    """``path`` as a replay page's file name: it must end in .html or .htm.

    Raises:
        ValueError: another suffix, or none.
    """
    out = Path(path)
    if out.suffix.lower() not in PAGE_SUFFIXES:
        has = f"not {out.suffix}" if out.suffix else "and it has none"
        raise ValueError(f"{path}: a replay page's suffix must be .html or .htm, {has}")
    return out


def write_html(recording: Recording, path: str | Path) -> Path:
    """Write the replay page of ``recording`` to ``path`` (.html); returns the path.

    Raises:
        ValueError: the path does not end in .html or .htm, or the recording is empty.
    """
    out = check_page_path(path)
    out.write_text(render_html(recording), encoding="utf-8")
    return out


class NotebookReplay:
    """A replay page inside a notebook's output: ``display(NotebookReplay("run.html"))``.

    The page goes into an iframe of its own (``srcdoc``), so its script and styles keep to
    themselves; Jupyter shows it in a notebook it trusts (one run in this session).

    Args:
        path: a page that :func:`write_html` wrote.
        height: the frame's height in pixels.
    """

    def __init__(self, path: str | Path, height: int = 760) -> None:
        self.path = Path(path)
        self.height = int(height)

    def _repr_html_(self) -> str:
        page = html.escape(self.path.read_text(encoding="utf-8"), quote=True)
        return (
            f'<iframe srcdoc="{page}" sandbox="allow-scripts" '
            f'title="{html.escape(self.path.name, quote=True)}" '
            f'style="width: 100%; height: {self.height}px; border: 0"></iframe>'
        )
