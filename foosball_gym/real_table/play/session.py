"""Session logs: every pass of the loop as a JSON line (the format and its reader are
:mod:`foosball_gym.session_log`), and replaying a log offline.

A log holds what the camera measured, the drives' state and what the policy decided, so a
session can be played back through the same estimator and policy to see, or check, what the
table did and why.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from foosball_gym.real_table.play.loop import LoopRecord
from foosball_gym.session_log import SessionLogWriter, read_session_log


class SessionLog:
    """Writes one line per :class:`LoopRecord` in the format of :mod:`foosball_gym.session_log`;
    a header line says what was played."""

    def __init__(self, path: str | Path, header: dict[str, Any]) -> None:
        self._writer = SessionLogWriter(path, header)
        self.path = self._writer.path

    def __call__(self, record: LoopRecord) -> None:
        self._writer.write(asdict(record))

    def close(self) -> None:
        self._writer.close()


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
    for rec in read_session_log(path).records:
        if rec.get("new_ball"):
            estimator.new_ball()
        ball = tuple(rec["ball_measured"]) if rec["ball_measured"] is not None else None
        estimator.update(rec["frame_time"], ball, rec["opponent_slides"])
        pos, vel = own_joints(rec["own_state"])
        obs = estimator.observation(pos, vel)
        action = [float(a) for a in np.ravel(policy(obs))]
        out.append((rec["observation"], [float(v) for v in obs], rec["action"], action))
    return out
