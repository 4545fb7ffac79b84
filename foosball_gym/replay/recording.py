"""What a replay shows: the rods and the ball of a table, frame by frame, in episodes.

A :class:`Recording` is plain data: built from a ``foosball play --log`` session
(:mod:`~foosball_gym.replay.session_log`) or while an evaluation runs
(:class:`~foosball_gym.replay.env_recorder.EnvRecorder`), and written as a page by
:func:`~foosball_gym.replay.page.write_html`. Nothing here imports the simulator.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from foosball_gym import table

#: The ball tracks a frame may carry: the simulator's truth, the estimate the policy saw (the
#: Kalman filter's, predicted ahead), and the camera's detection.
TRACKS = ("ball", "estimate", "measured")


@dataclass
class Episode:
    """One episode (an evaluation's) or one served ball (a play session's).

    Attributes:
        label: how the page names it ("episode 3, seed 2", "serve 5").
        t: the time of each frame (s), from the recording's start or the episode's.
        joints: (frames, 2 * rods): the slides then the spins of the recording's rods, NaN
            where a joint was not known (an opponent rod's spin on a real table).
        tracks: for each of :data:`TRACKS` that was logged, (frames, 2): x, y of the ball,
            NaN where there was none (a frame without a detection).
        outcome: one line on how it ended ("goal against", "blocked"); empty if unknown.
        events: (frame, text) of what happened during it, such as goals.
    """

    label: str
    t: Any
    joints: Any
    tracks: dict[str, Any] = field(default_factory=dict)
    outcome: str = ""
    events: list[tuple[int, str]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, dtype=float).reshape(-1)
        n = len(self.t)
        self.joints = np.asarray(self.joints, dtype=float).reshape(n, -1)
        for name, track in list(self.tracks.items()):
            if name not in TRACKS:
                raise ValueError(f"unknown ball track {name!r}; allowed: {', '.join(TRACKS)}")
            self.tracks[name] = np.asarray(track, dtype=float).reshape(n, 2)
        for frame, _ in self.events:
            if not 0 <= frame < n:
                raise ValueError(f"event at frame {frame} of an episode of {n} frames")

    @property
    def frames(self) -> int:
        return len(self.t)


@dataclass
class Recording:
    """Episodes of a table with the rods ``rods`` (names of :data:`foosball_gym.table.RODS`).

    Attributes:
        title: the page's heading ("builtin:block on Foosball-Block-v0").
        rods: the rods in play, whose joints each frame holds.
        episodes: in the order played.
        notes: lines the page shows under the title (the source, the seeds).
    """

    title: str
    rods: Sequence[str]
    episodes: list[Episode] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.rods = tuple(self.rods)
        for name in self.rods:
            table.rod(name)  # raises for a name that is no rod

    def add(self, episode: Episode) -> None:
        width = 2 * len(self.rods)
        if episode.joints.shape[1] != width:
            raise ValueError(
                f"an episode of {self.title!r} has {episode.joints.shape[1]} joint values a "
                f"frame; its {len(self.rods)} rods have {width}"
            )
        self.episodes.append(episode)

    @property
    def frames(self) -> int:
        return sum(e.frames for e in self.episodes)

    def tracks(self) -> tuple[str, ...]:
        """The ball tracks any episode holds, in the order of :data:`TRACKS`."""
        held = {name for e in self.episodes for name in e.tracks}
        return tuple(name for name in TRACKS if name in held)


def table_geometry() -> dict[str, object]:
    """The table as the page draws it (m), from :mod:`foosball_gym.table`: what the
    simulator builds, so the page and the rgb_array frames agree."""
    return {
        "field_half_length": table.FIELD_HALF_LENGTH,
        "field_half_width": table.FIELD_HALF_WIDTH,
        "wall": table.WALL_THICKNESS,
        "end_wall": table.END_WALL_THICKNESS,
        "goal_half_width": table.GOAL_HALF_WIDTH,
        "goal_line_x": table.GOAL_LINE_X,
        "pocket_back_x": table.POCKET_BACK_X,
        "rod_radius": table.ROD_RADIUS,
        "ball_radius": table.BALL_RADIUS,
        "figurine_size": list(table.FIGURINE_SIZE[:2]),
        # How far a figurine's centre, foot and head lie from the rod's axis: its top view
        # stretches along x as the rod turns.
        "figurine_centre_below_axis": table.FIGURINE_CENTRE_BELOW_AXIS,
        "figurine_foot_below_axis": table.FIGURINE_FOOT_BELOW_AXIS,
        "figurine_head_above_axis": table.FIGURINE_HEAD_ABOVE_AXIS,
    }


def rod_geometry(names: Sequence[str]) -> list[dict[str, object]]:
    """Each rod of ``names`` as the page draws it."""
    out = []
    for name in names:
        rod = table.rod(name)
        out.append(
            {
                "name": name,
                "team": rod.team,
                "x": rod.x,
                "direction": rod.direction,
                "offsets": list(rod.figurine_offsets),
            }
        )
    return out


def figurine_footprint(name: str, slide: float, spin: float) -> list[tuple[float, float]]:
    """Each figurine's centre (x, y) seen from above: where the page draws it (a test
    checks the page against this)."""
    rod = table.rod(name)
    x, _ = rod.figurine_swing(spin)
    return [(x, y) for y in rod.figurine_y(slide)]


def rods_in_table_order(names: Iterable[str]) -> tuple[str, ...]:
    """``names`` sorted as :data:`foosball_gym.table.RODS` lists them, each once."""
    names = set(names)
    rank = {rod.name: k for k, rod in enumerate(table.RODS)}
    unknown = sorted(set(names) - set(rank))
    if unknown:
        raise ValueError(f"no such rods: {', '.join(unknown)}")
    return tuple(sorted(names, key=rank.__getitem__))


def nan_pair(value: Sequence[float] | None) -> tuple[float, float]:
    """An (x, y) pair, or NaNs for none."""
    if value is None:
        return math.nan, math.nan
    return float(value[0]), float(value[1])
