"""The session log of ``foosball play --log``: its format, its one writer and its one checked
reader.

A log is a header line, ``{"header": {...}}``: what was played (``env_id`` where the table is the
simulated one, ``env_kwargs``, the names of the ``observation``) and on which table (its
configuration: the drives' joints and the bus). Then one JSON object per pass of the loop, a
:class:`~foosball_gym.real_table.play.loop.LoopRecord` as a mapping. ``foosball play`` writes it
with :class:`SessionLogWriter`; replay pages, system identification and the tests read it with
:func:`read_session_log`, which refuses a file that is no such log in one line naming the file and
the line. Nothing here needs the simulator or the play stack.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from foosball_gym import table, user_json

HEADER = "header"
# What every loop record holds that a reader reads, whatever else it holds.
RECORD_KEYS = ("t", "frame_time", "ball_measured", "own_state", "observation", "targets")


class SessionLogError(ValueError):
    """A file that is no session log, or one damaged past reading; the message names the file
    and says why, in one line."""


class SessionLogWriter:
    """Writes a session log: the header at once, then one line per :meth:`write`."""

    def __init__(self, path: str | Path, header: Mapping[str, Any]) -> None:
        self.path = Path(path)
        self._file: TextIO = self.path.open("w", encoding="utf-8")
        self._file.write(json.dumps({HEADER: dict(header)}) + "\n")

    def write(self, record: Mapping[str, Any]) -> None:
        self._file.write(json.dumps(dict(record)) + "\n")

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()


@dataclass(frozen=True)
class SessionLogFile:
    """A session log as read: its header and its loop records, checked."""

    path: str
    header: dict[str, Any]
    records: list[dict[str, Any]]


def read_session_log(path: str | Path) -> SessionLogFile:
    """Read and check a session log.

    Raises:
        SessionLogError: the file is missing, empty, not text, cut off, not a session log, from
            a table this package does not know, or a line is not a loop record.
    """
    name = str(path)
    file = Path(path)
    if not file.exists():
        raise SessionLogError(f"{name}: no such file")
    if not file.is_file():
        raise SessionLogError(f"{name} is not a file")
    try:
        text = file.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise SessionLogError(
            f"{name} is not a session log of foosball play --log: not text"
        ) from None
    except OSError as err:
        raise SessionLogError(f"{name} cannot be read: {err.strerror}") from None
    lines = text.splitlines()
    if not any(line.strip() for line in lines):
        raise SessionLogError(
            f"{name} is empty, not a session log (foosball play --log FILE writes one)"
        )
    cut_off = not text.endswith("\n")
    header = _header(name, lines[0], cut_off and len(lines) == 1)
    records = []
    for number, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        try:
            record = user_json.loads(line)
        except ValueError as err:
            if not isinstance(err, json.JSONDecodeError):
                raise SessionLogError(f"{name} line {number}: {err}") from None
            if cut_off and number == len(lines):
                raise SessionLogError(
                    f"{name} is truncated: its last line ({number}) was cut off while the "
                    "session wrote it; delete that line to read the rest"
                ) from None
            raise SessionLogError(f"{name} line {number} is not JSON: the log is damaged") from None
        records.append(_check_record(name, number, record))
    if not records:
        raise SessionLogError(f"{name} holds no loops, only its header: the session ended at once")
    return SessionLogFile(name, header, records)


def _header(name: str, line: str, cut_off: bool) -> dict[str, Any]:
    not_a_log = f"{name} does not start with a session header: not a log of foosball play --log"
    try:
        first = user_json.loads(line)
    except ValueError as err:
        if not isinstance(err, json.JSONDecodeError):
            raise SessionLogError(f"{name} line 1: {err}") from None
        if cut_off:
            raise SessionLogError(f"{name} is truncated: it was cut off in its header") from None
        raise SessionLogError(not_a_log) from None
    header = first.get(HEADER) if isinstance(first, dict) else None
    if not isinstance(header, dict):
        raise SessionLogError(not_a_log)
    config = header.get("table")
    if not isinstance(config, dict) or not isinstance(config.get("joints"), list):
        raise SessionLogError(f"{name}: its header does not describe the table it was played on")
    for joint in config["joints"]:
        rod = joint.get("rod") if isinstance(joint, dict) else None
        if rod not in table.ROD_BY_NAME or joint.get("joint") not in ("slide", "spin"):
            raise SessionLogError(
                f"{name} is from another table: it has a drive on {rod!r}, which this table "
                f"has not (rods: {', '.join(table.ROD_BY_NAME)})"
            )
    env_id = header.get("env_id")
    if env_id is not None:
        from foosball_gym.registration import ENV_IDS

        if env_id not in ENV_IDS:
            raise SessionLogError(
                f"{name} was played on {env_id!r}, which this foosball_gym does not know "
                f"(another table, or another version); known: {', '.join(map(str, ENV_IDS))}"
            )
    if not isinstance(header.get("env_kwargs") or {}, dict):
        raise SessionLogError(f"{name}: its header's env_kwargs are not a mapping of options")
    names = header.get("observation")
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise SessionLogError(f"{name}: its header's observation is no list of names")
    return header


def _check_record(name: str, number: int, record: Any) -> dict[str, Any]:
    """A loop record whose fields the readers read are there and of their types."""
    where = f"{name} line {number}"
    if not isinstance(record, dict):
        raise SessionLogError(f"{where} is not a loop record of foosball play")
    missing = [key for key in RECORD_KEYS if key not in record]
    if missing:
        raise SessionLogError(
            f"{where} is not a loop record of foosball play: it has no {', '.join(missing)}"
        )
    if not _number(record["t"]) or not (
        record["frame_time"] is None or _number(record["frame_time"])
    ):
        raise SessionLogError(f"{where}: its t and frame_time must be numbers")
    ball = record["ball_measured"]
    if ball is not None and not (
        isinstance(ball, list) and len(ball) == 2 and all(_number(v) for v in ball)
    ):
        raise SessionLogError(
            f"{where}: its ball_measured must be null or two numbers, got {ball!r}"
        )
    state, targets = record["own_state"], record["targets"]
    if not isinstance(state, dict) or not all(
        isinstance(v, list) and len(v) == 2 and all(_number(x) for x in v) for v in state.values()
    ):
        raise SessionLogError(f"{where}: its own_state must map joints to [position, velocity]")
    if not isinstance(targets, dict) or not all(_number(v) for v in targets.values()):
        raise SessionLogError(f"{where}: its targets must map joints to numbers")
    observation = record["observation"]
    if not isinstance(observation, list) or not all(_number(v) for v in observation):
        raise SessionLogError(f"{where}: its observation must be a list of numbers")
    slides = record.get("opponent_slides") or {}
    if not isinstance(slides, dict) or not all(v is None or _number(v) for v in slides.values()):
        raise SessionLogError(f"{where}: its opponent_slides must map rods to numbers or null")
    truth = record.get("truth")
    if truth is not None and not isinstance(truth, dict):
        raise SessionLogError(f"{where}: its truth must be null or an object")
    return record


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
