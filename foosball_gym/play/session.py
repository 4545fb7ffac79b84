"""Session logs: every pass of the loop as a JSON line, and replaying a log offline.

A log holds what the camera measured, the drives' state and what the policy decided, so a
session can be played back through the same estimator and policy to see, or check, what the
table did and why.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from dataclasses import asdict
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from foosball_gym import user_json
from foosball_gym.play.loop import LoopRecord


class SessionLog:
    """Writes one JSON line per :class:`LoopRecord`; a header line says what was played."""

    def __init__(self, path: str | Path, header: dict[str, Any]) -> None:
        self.path = Path(path)
        self._file: TextIO = self.path.open("w")
        self._file.write(json.dumps({"header": header}) + "\n")

    def __call__(self, record: LoopRecord) -> None:
        self._file.write(json.dumps(asdict(record)) + "\n")

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()


def read_session(path: str | Path) -> tuple[dict[str, Any], Iterator[dict[str, Any]]]:
    """The header and the records of a session log."""
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    if not lines:
        raise ValueError(f"{path} is empty, not a session log")
    first = user_json.loads(lines[0])
    header = first.get("header") if isinstance(first, dict) else None
    if header is None:
        raise ValueError(f"{path} does not start with a session header")
    if not isinstance(header, dict):
        raise ValueError(f"{path}: its header is {type(header).__name__}, not an object")
    return header, (_record(line, number) for number, line in enumerate(lines[1:], start=2))


def _record(line: str, number: int) -> dict[str, Any]:
    record = user_json.loads(line)
    if not isinstance(record, dict):
        raise ValueError(f"line {number} is {type(record).__name__}, not a loop record")
    return record


def replay(
    path: str | Path,
    estimator: Any,
    policy: Callable[[np.ndarray], Any],
    own_joints: Callable[[dict[str, list[float]]], tuple[list[float], list[float]]],
) -> list[tuple[list[float], list[float], list[float], list[float]]]:
    """Feed a log's measurements through an estimator and a policy again.

    Args:
        path: the session log.
        estimator: a fresh estimator configured as in the session.
        policy: the policy.
        own_joints: turns a record's ``own_state`` into the builder's (positions, velocities).

    Returns:
        Per record: (logged observation, replayed observation, logged action, replayed action).
    """
    out = []
    _, records = read_session(path)
    for rec in records:
        if rec.get("new_ball"):
            estimator.new_ball()
        ball = tuple(rec["ball_measured"]) if rec["ball_measured"] is not None else None
        estimator.update(rec["frame_time"], ball, rec["opponent_slides"])
        pos, vel = own_joints(rec["own_state"])
        obs = estimator.observation(pos, vel)
        action = [float(a) for a in np.ravel(policy(obs))]
        out.append((rec["observation"], [float(v) for v in obs], rec["action"], action))
    return out
