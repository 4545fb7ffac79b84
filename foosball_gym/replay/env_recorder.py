"""Recording an environment's episodes as they are played, for a replay page.

:func:`foosball_gym.evaluation.evaluate` uses it for ``foosball eval --replay``; anything that
steps a :class:`~foosball_gym.envs.base.FoosballEnv` can. It reads what the environment
exposes (its rods' joints, the true ball, the observation) and never the simulator itself.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from foosball_gym.replay.recording import Episode, Recording


class EnvRecorder:
    """Frames of ``env``'s episodes: call :meth:`start` after each reset, :meth:`step` after
    each step and :meth:`end` when the episode is over.

    Where the environment observes through the simulated camera and Kalman filter
    (``estimated_state=True``) the estimate in its observation is recorded beside the truth.

    Args:
        env: the environment (wrapped or not).
        recording: the recording episodes are added to.
    """

    def __init__(self, env: Any, recording: Recording | None = None, title: str = "") -> None:
        self.env = env.unwrapped
        rods = tuple(self.env.layout.rods)
        self.recording = recording or Recording(title=title or self.env.spec.id, rods=rods)
        if tuple(self.recording.rods) != rods:
            raise ValueError(f"the recording's rods {self.recording.rods} are not {rods}")
        kwargs = getattr(self.env.spec, "kwargs", None) or {}
        self.estimated = bool(kwargs.get("estimated_state"))
        names = self.env.obs_builder.names
        self._ball_index = names.index("ball_x"), names.index("ball_y")
        self._frames: dict[str, list[Any]] = {}
        self._label = ""

    def start(self, label: str, observation: Any) -> None:
        self._frames = {k: [] for k in ("t", "joints", "ball", "estimate", "events")}
        self._label = label
        self._add(observation)

    def step(self, observation: Any, info: dict[str, Any]) -> None:
        self._add(observation)
        frame = len(self._frames["t"]) - 1
        goal = int(info.get("goal", 0))
        if goal:
            self._frames["events"].append((frame, "goal for" if goal > 0 else "goal against"))
        if info.get("out_of_table"):
            self._frames["events"].append((frame, "ball off the table"))

    def end(self, info: dict[str, Any]) -> None:
        """Close the episode, its outcome taken from the last step's ``info``."""
        frames = self._frames
        tracks = {"ball": frames["ball"]}
        if self.estimated:
            tracks["estimate"] = frames["estimate"]
        self.recording.add(
            Episode(
                label=self._label,
                t=frames["t"],
                joints=frames["joints"],
                tracks=tracks,
                outcome=outcome(info),
                events=frames["events"],
            )
        )

    def _add(self, observation: Any) -> None:
        env, frames = self.env, self._frames
        frames["t"].append(len(frames["t"]) * env.dt)
        positions, _ = env.rod_joint_values()
        frames["joints"].append([float(v) for v in positions])
        x, y = env.game.ball[:2]
        frames["ball"].append((float(x), float(y)))
        obs = np.ravel(observation)
        ix, iy = self._ball_index
        frames["estimate"].append((float(obs[ix]), float(obs[iy])))


def outcome(info: dict[str, Any]) -> str:
    """How an episode ended, from its last step's info, in a few words."""
    parts = []
    if "goals_for" in info:
        parts.append(f"{info['goals_for']}:{info['goals_against']}")
    elif info.get("goal"):
        parts.append("goal for" if info["goal"] > 0 else "goal against")
    if info.get("out_of_table"):
        parts.append("ball off the table")
    elif info.get("stagnated"):
        parts.append("ball lay still")
    parts.append("success" if info.get("is_success") else "failure")
    return ", ".join(parts)
