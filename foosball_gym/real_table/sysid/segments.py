"""The stretches of a logged ball track that only the table shapes, and the wall bounces
between them.

Where no figurine is near, the ball rolls, slides and bounces off the walls, and nothing else.
The track there is cut at every wall bounce into stretches the ball spends on the cloth alone:
the simulator replays each from a starting state, smoothly in the physics, and how the replays
differ from the camera's measurements says how the table's rolling and sliding differ. A bounce
between two such stretches says how much of its speed into the wall the ball keeps. Nothing
here needs the simulator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from foosball_gym import table
from foosball_gym.real_table.sysid.excitation import free_bands
from foosball_gym.real_table.sysid.logs import PlayLog

#: A stretch needs at least this many measurements, over at least this long (s).
MIN_FRAMES = 8
MIN_DURATION_S = 0.12
#: Longer stretches are cut into pieces of at most this long (s), each replayed from a state of
#: its own: a long replay drifts with the smallest error in its start.
MAX_DURATION_S = 1.5
#: Frames further apart than this (s) end a stretch: what happened between is not known.
MAX_GAP_S = 0.2
#: A ball that comes clear of the rods (not served there) is left alone this long (s) first: a
#: figurine's kick throws it up off the cloth and spins it in ways a replay cannot start from.
SETTLE_S = 0.25
#: A ball that moved less than this (m) over a stretch shows nothing of the table.
MIN_TRAVEL = 0.02
#: A frame nearest a wall among those around it, with the ball within this of touching the
#: wall (m), is a bounce.
BOUNCE_WALL_DISTANCE = 0.02
# Frames before a bounce left out of the stretches (the ball is at the wall), and how long
# after it (s): a ball that rolled into a wall climbs it and lands a few frames later.
_BOUNCE_MARGIN = 1
_AFTER_BOUNCE_S = 0.1
# The ball near a goal mouth may go in: the pockets of a real table are not the simulator's.
_MOUTH_X = table.FIELD_HALF_LENGTH - 0.04
_MOUTH_Y = table.GOAL_HALF_WIDTH + table.BALL_RADIUS
#: The walls a bounce can be off: an end wall (normal along x) or a side wall (along y).
WALLS = ("end", "side")


@dataclass(frozen=True)
class BallSegment:
    """A stretch of the ball's track with no figurine near and no wall bounce.

    Attributes:
        log: the index of its log.
        serve: the serve it belongs to.
        t0: the time of its first frame (s, on the log's clock).
        times: its frames' times after ``t0`` (s), the first 0.
        xy: the ball the camera measured in them, (frames, 2).
        follows: the index (among the stretches returned together) of the stretch the ball
            came from through one wall bounce, straight before this one; None if none was kept
            (or the bounce was into a corner).
        wall: the wall of the bounce this stretch begins at, one of :data:`WALLS` or
            ``"corner"``; None where it begins elsewhere.
    """

    log: int
    serve: int
    t0: float
    times: np.ndarray
    xy: np.ndarray
    follows: int | None = None
    wall: str | None = None

    @property
    def duration(self) -> float:
        return float(self.times[-1])


def ball_segments(logs: list[PlayLog]) -> list[BallSegment]:
    """Every stretch of the logs' ball tracks that the simulator can replay without rods or
    walls, linked through the bounces between them."""
    out: list[BallSegment] = []
    for index, log in enumerate(logs):
        bands = free_bands(log.rods)
        for serve, times, xy in _frames_by_serve(log):
            for start, stop in _free_runs(times, xy, bands):
                if start > 0:
                    # Not a serve's first frame: the ball just came off a figurine (or a hand).
                    start = int(np.searchsorted(times, times[start] + SETTLE_S))
                if start < stop:
                    out += _pieces(index, serve, times[start:stop], xy[start:stop], len(out))
    return out


def _frames_by_serve(log: PlayLog) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """Each serve's new frames with the ball seen in them: (serve, times, xy), in time order."""
    serves = log.serve
    seen = np.isfinite(log.ball[:, 0]) & np.isfinite(log.frame_time)
    out = []
    for serve in np.unique(serves):
        rows = np.flatnonzero(seen & (serves == serve))
        if not len(rows):
            continue
        order = np.argsort(log.frame_time[rows], kind="stable")
        times, xy = log.frame_time[rows][order], log.ball[rows][order]
        # A frame used twice is one measurement.
        keep = np.concatenate([[True], np.diff(times) > 1e-9])
        out.append((int(serve), times[keep], xy[keep]))
    return out


def _free_runs(
    times: np.ndarray, xy: np.ndarray, bands: list[tuple[float, float]]
) -> list[tuple[int, int]]:
    """Runs of consecutive frames no figurine can reach, close enough in time, in one stretch
    of the field (a fast ball can cross a rod's reach between two frames)."""
    x, y = xy[:, 0], xy[:, 1]
    band = np.full(len(times), -1)
    for k, (low, high) in enumerate(bands):
        band[(x >= low) & (x <= high)] = k
    free = (band >= 0) & ~((np.abs(x) > _MOUTH_X) & (np.abs(y) < _MOUTH_Y))
    joined = free[:-1] & free[1:] & (band[:-1] == band[1:]) & (np.diff(times) <= MAX_GAP_S)
    runs, start = [], 0
    for i in range(1, len(times) + 1):
        if i == len(times) or not joined[i - 1]:
            if free[start]:
                runs.append((start, i))
            start = i
    return runs


def bounces(xy: np.ndarray, half_window: int = 3) -> list[tuple[int, str | None]]:
    """The frames at which the ball meets a wall: nearest a wall (within
    :data:`BOUNCE_WALL_DISTANCE` of touching it) among the frames around; each with its wall,
    None for a corner (both walls at once)."""
    hits: dict[int, set[str]] = {}
    for column, limit, wall in ((0, table.BALL_LIMIT_X, "end"), (1, table.BALL_LIMIT_Y, "side")):
        reach = np.abs(xy[:, column])
        for i in (int(k) for k in np.flatnonzero(reach > limit - BOUNCE_WALL_DISTANCE)):
            around = reach[max(0, i - half_window) : i + half_window + 1]
            if reach[i] >= around.max():
                hits.setdefault(i, set()).add(wall)
    out: list[tuple[int, str | None]] = []
    for i in sorted(hits):
        if out and i - out[-1][0] <= 2 * half_window:
            # One ball into a corner meets both walls within a few frames: one bounce.
            out[-1] = (out[-1][0], None)
            continue
        walls = hits[i]
        out.append((i, next(iter(walls)) if len(walls) == 1 else None))
    return out


def _pieces(
    log: int, serve: int, times: np.ndarray, xy: np.ndarray, first: int
) -> list[BallSegment]:
    """A run cut at its bounces and into pieces of at most :data:`MAX_DURATION_S`, a ball
    lying still at its end left out; ``first`` is the index the first piece will have."""
    still = _still_from(times, xy)
    times, xy = times[:still], xy[:still]
    hits = bounces(xy)
    # Each stretch between bounces: (start, stop, the wall of the bounce before it).
    stretches: list[tuple[int, int, str | None]] = []
    start, wall = 0, None
    for frame, hit_wall in hits:
        stretches.append((start, frame - _BOUNCE_MARGIN, wall))
        start = int(np.searchsorted(times, times[frame] + _AFTER_BOUNCE_S, side="right"))
        wall = hit_wall or "corner"
    stretches.append((start, len(times), wall))
    out: list[BallSegment] = []
    previous: int | None = None  # the piece that ended at the last bounce, if it was kept
    for start, stop, wall in stretches:
        pieces = []
        while start < stop:
            end = min(stop, int(np.searchsorted(times, times[start] + MAX_DURATION_S, "right")))
            pieces.append((start, end))
            start = end
        ends_at_bounce = None
        for k, (a, b) in enumerate(pieces):
            if not _replayable(times[a:b], xy[a:b]):
                continue
            out.append(
                BallSegment(
                    log,
                    serve,
                    float(times[a]),
                    times[a:b] - times[a],
                    xy[a:b],
                    follows=previous if k == 0 and wall in WALLS else None,
                    wall=wall if k == 0 else None,
                )
            )
            if k == len(pieces) - 1:
                ends_at_bounce = first + len(out) - 1
        previous = ends_at_bounce
    return out


def _replayable(times: np.ndarray, xy: np.ndarray) -> bool:
    if len(times) < MIN_FRAMES or times[-1] - times[0] < MIN_DURATION_S:
        return False
    return float(np.max(np.hypot(*(xy - xy[0]).T))) >= MIN_TRAVEL


def _still_from(times: np.ndarray, xy: np.ndarray, window: float = 0.25) -> int:
    """Where the frames of a ball lying still at the end begin (within 3 mm of where it comes
    to rest, for at least ``window`` seconds), the first of them kept: a ball at rest shows
    nothing, and Bullet's rest is not a real table's. The number of frames where it does not
    come to rest."""
    moved = np.flatnonzero(np.hypot(*(xy - xy[-1]).T) > 0.003)
    first = int(moved[-1]) + 1 if len(moved) else 0
    if times[-1] - times[first] >= window:
        return first + 1
    return len(times)


def within_budget(segments: list[BallSegment], seconds: float) -> list[BallSegment]:
    """The stretches a fit replays whole (those not beginning at a bounce), at most ``seconds``
    of them, drawn evenly over the logs; each with the stretch after its bounce, which a fit
    replays only into (the others after a bounce have nothing to carry the ball in from)."""
    heads = [i for i, s in enumerate(segments) if s.wall is None]
    total = sum(segments[i].duration for i in heads)
    share = min(1.0, seconds / total) if total > 0 else 1.0
    chosen = {i for k, i in enumerate(heads) if math.floor((k + 1) * share) > math.floor(k * share)}
    chosen |= {i for i, s in enumerate(segments) if s.follows in chosen}
    index = {old: new for new, old in enumerate(sorted(chosen))}
    return [
        BallSegment(
            s.log,
            s.serve,
            s.t0,
            s.times,
            s.xy,
            follows=index[s.follows] if s.follows is not None else None,
            wall=s.wall,
        )
        for s in (segments[i] for i in sorted(chosen))
    ]
