"""A ``foosball play --log`` session as a :class:`~foosball_gym.replay.recording.Recording`.

Every line of the log is a frame. A simulated table's log holds the truth (every rod and the
ball as the simulator had them, and the goals), which a real table's cannot; both hold the
camera's detection, the estimate the policy saw (in its observation) and the drives' state.
A real table's opponent rods are seen by their slides only, so their spin is drawn as unknown.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from foosball_gym.replay.recording import Episode, Recording, nan_pair, rods_in_table_order
from foosball_gym.session_log import SessionLogError, read_session_log


class LogError(SessionLogError):
    """A file that is not a play session's log, or one damaged past reading."""


def _rods(records: list[dict[str, Any]]) -> tuple[str, ...]:
    names: set[str] = set()
    for rec in records:
        names |= {key.split(".")[0] for key in rec.get("own_state") or {}}
        names |= set(rec.get("opponent_slides") or {})
        truth = rec.get("truth") or {}
        names |= set(truth.get("joints") or {})
    return rods_in_table_order(names)


def _joints(rec: dict[str, Any], rods: tuple[str, ...]) -> list[float]:
    n = len(rods)
    out = [math.nan] * (2 * n)
    truth = (rec.get("truth") or {}).get("joints") or {}
    own = rec.get("own_state") or {}
    seen = rec.get("opponent_slides") or {}
    for i, name in enumerate(rods):
        if name in truth:
            out[i], out[n + i] = float(truth[name][0]), float(truth[name][1])
            continue
        for k, joint in ((i, "slide"), (n + i, "spin")):
            state = own.get(f"{name}.{joint}")
            if state is not None:
                out[k] = float(state[0])
        if math.isnan(out[i]) and seen.get(name) is not None:
            out[i] = float(seen[name])
    return out


def _outcome(goals: list[int], out: bool) -> str:
    scored = [("goal for" if g > 0 else "goal against") for g in goals if g]
    if scored:
        return ", ".join(scored)
    return "ball off the table" if out else "no goal"


def recording_from_session(path: str | Path) -> Recording:
    """The frames of a play session's log, a served ball to an episode.

    Raises:
        LogError: the file is no session log (the message says what is wrong and where).
        OSError: it cannot be read.
    """
    path = Path(path)
    try:
        read = read_session_log(path)
    except SessionLogError as err:
        raise LogError(str(err)) from None
    header, records = read.header, read.records
    names = header["observation"]
    try:
        ix, iy = names.index("ball_x"), names.index("ball_y")
    except ValueError:
        raise LogError(f"{path}: the header's observation has no ball_x, ball_y") from None
    env_id = header.get("env_id") or "a real table"
    try:
        rods = _rods(records)
    except (AttributeError, TypeError, ValueError, OverflowError) as err:
        raise LogError(f"{path}: unreadable rods in the records ({err})") from None
    if not rods:
        raise LogError(f"{path}: its records name no rods")
    simulated = any(rec.get("truth") for rec in records)
    recording = Recording(
        title=f"{env_id}: {path.name}",
        rods=rods,
        notes=[
            (
                "a simulated table's session: the true ball beside the estimate the policy saw"
                if simulated
                else "a real table's session: the camera's detections and the policy's estimate"
            ),
        ],
    )
    serve: dict[str, list[Any]] = {}
    count = 0
    out_of_table = False

    def close_serve() -> None:
        nonlocal serve, out_of_table
        if not serve.get("t"):
            return
        tracks = {"estimate": serve["estimate"], "measured": serve["measured"]}
        if simulated:
            tracks["ball"] = serve["ball"]
        label = f"serve {count}" if count else "session"
        recording.add(
            Episode(
                label=label,
                t=serve["t"],
                joints=serve["joints"],
                tracks=tracks,
                outcome=_outcome(serve["goals"], out_of_table) if simulated else "",
                events=serve["events"],
            )
        )
        serve, out_of_table = {}, False

    for number, rec in enumerate(records, start=2):
        try:
            if rec.get("new_ball"):
                close_serve()
                count += 1
            if not serve:
                serve = {k: [] for k in ("t", "joints", "ball", "estimate", "measured", "events")}
                serve["goals"] = []
            frame = len(serve["t"])
            serve["t"].append(float(rec["t"]))
            serve["joints"].append(_joints(rec, rods))
            obs = rec["observation"]
            serve["estimate"].append((float(obs[ix]), float(obs[iy])))
            serve["measured"].append(nan_pair(rec.get("ball_measured")))
            truth = rec.get("truth") or {}
            serve["ball"].append(nan_pair(truth.get("ball")))
            goal = int(truth.get("goal") or 0)
            if goal:
                serve["goals"].append(goal)
                serve["events"].append((frame, "goal for" if goal > 0 else "goal against"))
            if truth.get("out"):
                out_of_table = True
                serve["events"].append((frame, "ball off the table"))
        except (KeyError, IndexError, TypeError, ValueError, AttributeError, OverflowError) as err:
            raise LogError(f"{path}: line {number} is not a loop record ({err!r})") from None
    close_serve()
    t0 = recording.episodes[0].t[0]
    if np.isfinite(t0):
        recording.notes.append(
            f"{len(records)} loops in {len(recording.episodes)} "
            f"{'serves' if count else 'part'} over {recording.episodes[-1].t[-1] - t0:.1f} s"
        )
    return recording
