"""Session logs of ``foosball play --log``, read and checked for system identification.

A log (:mod:`foosball_gym.session_log`, which reads and checks it) is a header line (what was
played, on which table) and one line per pass of the loop. What a fit needs of it is read into
arrays: the camera's ball measurements and the time of their frames, and each drive's state and
target.
A log that cannot be fitted (empty, cut off, not a session log, from another table than the
others, without a ball in sight) is refused with a :class:`LogError` that says why in one
line. Nothing here needs the simulator.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from foosball_gym import table
from foosball_gym.session_log import SessionLogError, read_session_log
from foosball_gym.sim.options import PHYSICS_DEFAULTS, RANDOMISATION_BOUNDS, check_physics

#: The environment options that make a simulated table's physics what it is: two simulated
#: tables with different values are different tables.
PHYSICS_OPTIONS = (*PHYSICS_DEFAULTS, *RANDOMISATION_BOUNDS)


class LogError(SessionLogError):
    """A log that cannot be fitted; the message names the file and says why, in one line."""


@dataclass
class PlayLog:
    """What a fit reads of one session log.

    Attributes:
        path: the file.
        header: the log's header as written.
        env_id, env_kwargs: the environment played (None on a real table's log, which does
            not name it) and its options.
        simulated: whether the table was the simulated one.
        physics_hz, control_hz, contact_travel: the simulator options of the table (a real
            table's log gets the defaults).
        rods: the rods in play, whose figurines could touch the ball.
        joints: the drives' joints, ``"rod.slide"`` or ``"rod.spin"``.
        t: each loop's time (s).
        frame_time: the time of the frame each loop used (s; NaN for none).
        ball: the ball the camera measured in that frame, (loops, 2), NaN where not seen.
        new_ball: the loops at which a new ball was put in play.
        late: the loops whose command reached the table a control step late.
        position, velocity: each drive's state as the loop began, (loops, joints), NaN where
            a loop did not read it.
        targets: the target each loop sent each drive, (loops, joints), NaN where it sent none.
    """

    path: str
    header: dict[str, Any]
    env_id: str | None
    env_kwargs: dict[str, Any]
    simulated: bool
    physics_hz: int
    control_hz: int
    contact_travel: float
    rods: tuple[str, ...]
    joints: tuple[str, ...]
    t: np.ndarray = field(repr=False)
    frame_time: np.ndarray = field(repr=False)
    ball: np.ndarray = field(repr=False)
    new_ball: np.ndarray = field(repr=False)
    late: np.ndarray = field(repr=False)
    position: np.ndarray = field(repr=False)
    velocity: np.ndarray = field(repr=False)
    targets: np.ndarray = field(repr=False)

    @property
    def loops(self) -> int:
        return len(self.t)

    @property
    def serve(self) -> np.ndarray:
        """Each loop's serve: 0 before the first new ball, then counting up."""
        return np.cumsum(self.new_ball)

    @property
    def physics(self) -> dict[str, Any]:
        """The physics options the log's environment gave its table (absent: the defaults)."""
        return {k: self.env_kwargs[k] for k in PHYSICS_OPTIONS if k in self.env_kwargs}

    def calibration(self) -> dict[str, tuple[Any, ...]]:
        """Each drive's calibration: node, increments per unit, direction, offset."""
        return {
            f"{j['rod']}.{j['joint']}": tuple(
                j.get(k) for k in ("node_id", "increments_per_unit", "direction", "offset")
            )
            for j in self.header["table"]["joints"]
        }


def read_logs(paths: Sequence[str | Path]) -> list[PlayLog]:
    """Read session logs of one table.

    Raises:
        LogError: a log cannot be fitted, or one is from another table than the first.
    """
    if not paths:
        raise LogError("no log given")
    logs = [read_log(path) for path in paths]
    for log in logs[1:]:
        check_same_table(logs[0], log)
    return logs


def read_log(path: str | Path) -> PlayLog:
    """Read one session log.

    Raises:
        LogError: naming the file and what is wrong with it.
    """
    try:
        read = read_session_log(path)
    except SessionLogError as err:
        raise LogError(str(err)) from None
    log = _arrays(read.path, read.header, read.records)
    seen = int(np.isfinite(log.ball[:, 0]).sum())
    if not seen:
        raise LogError(
            f"{read.path}: the camera saw no ball in any of its {log.loops} loops; nothing to fit"
        )
    return log


def check_same_table(first: PlayLog, other: PlayLog) -> None:
    """Raise a LogError where ``other`` was played on another table than ``first``: one fit
    is one table's parameters."""
    where = f"{other.path} is from another table than {first.path}"
    if first.simulated != other.simulated:
        kinds = ("the simulated table", "a real table")
        raise LogError(f"{where}: {kinds[not other.simulated]}, not {kinds[not first.simulated]}")
    if first.simulated:
        if first.physics != other.physics:
            keys = sorted(set(first.physics) | set(other.physics))
            differ = [k for k in keys if first.physics.get(k) != other.physics.get(k)]
            shown = ", ".join(
                f"{k} {_shown(other.physics.get(k))} there, {_shown(first.physics.get(k))} here"
                for k in differ
            )
            raise LogError(f"{where}: its simulated physics differ ({shown})")
        return
    mine, theirs = first.calibration(), other.calibration()
    for joint in sorted(set(mine) & set(theirs)):
        if mine[joint] != theirs[joint]:
            raise LogError(
                f"{where}: its drive {joint} has another node or calibration "
                f"(node, increments per unit, direction, offset: {theirs[joint]} there, "
                f"{mine[joint]} here)"
            )


def _shown(value: Any) -> str:
    return "the default" if value is None else repr(value)


def _arrays(name: str, header: dict[str, Any], records: list[dict[str, Any]]) -> PlayLog:
    env_id = header.get("env_id")
    env_kwargs = dict(header.get("env_kwargs") or {})
    config = header["table"]
    simulated = (config.get("bus") or {}).get("interface") == "virtual"
    try:
        physics_hz, control_hz, contact_travel, _ = check_physics(
            *(env_kwargs.get(k, d) for k, d in PHYSICS_DEFAULTS.items())
        )
    except ValueError as err:
        raise LogError(f"{name}: its environment's physics options are not valid: {err}") from None
    joints = tuple(f"{j['rod']}.{j['joint']}" for j in config["joints"])
    n, count = len(records), len(joints)
    t = np.array([r["t"] for r in records], dtype=float)
    frame_time = np.array(
        [math.nan if r["frame_time"] is None else r["frame_time"] for r in records], dtype=float
    )
    ball = np.full((n, 2), math.nan)
    position, velocity, targets = (np.full((n, count), math.nan) for _ in range(3))
    column = {joint: j for j, joint in enumerate(joints)}
    for i, record in enumerate(records):
        if record["ball_measured"] is not None:
            ball[i] = record["ball_measured"]
        for joint, (p, v) in record["own_state"].items():
            if joint in column:
                position[i, column[joint]], velocity[i, column[joint]] = p, v
        for joint, target in record["targets"].items():
            if joint in column:
                targets[i, column[joint]] = target
    return PlayLog(
        path=name,
        header=header,
        env_id=env_id,
        env_kwargs=env_kwargs,
        simulated=simulated,
        physics_hz=physics_hz,
        control_hz=control_hz,
        contact_travel=contact_travel,
        rods=_rods_in_play(name, header, env_id, env_kwargs, records),
        joints=joints,
        t=t,
        frame_time=frame_time,
        ball=ball,
        new_ball=np.array([bool(r.get("new_ball", False)) for r in records]),
        late=np.array([bool(r.get("late", False)) for r in records]),
        position=position,
        velocity=velocity,
        targets=targets,
    )


def _rods_in_play(
    name: str,
    header: dict[str, Any],
    env_id: str | None,
    env_kwargs: dict[str, Any],
    records: list[dict[str, Any]],
) -> tuple[str, ...]:
    """The rods whose figurines could touch the ball: the task's, where the log names it;
    else every rod the drives move, the camera follows or the observation holds."""
    if env_id is not None:
        from foosball_gym.registration import make_task

        try:
            return tuple(make_task(env_id, env_kwargs)[0].layout.rods)
        except (ValueError, TypeError) as err:
            raise LogError(f"{name}: its environment's options are not valid: {err}") from None
    rods = {j["rod"] for j in header["table"]["joints"]}
    for record in records:
        rods |= set(record.get("opponent_slides") or {}) & set(table.ROD_BY_NAME)
    for observed in header.get("observation") or ():
        rods |= {r for r in table.ROD_BY_NAME if str(observed).startswith(f"{r}_")}
    return tuple(r.name for r in table.RODS if r.name in rods)
