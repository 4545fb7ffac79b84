"""A simulated real table: a task's simulation behind simulated CAN drives and a camera.

``foosball play MODEL --table sim`` runs the complete real-table stack against it: the camera
renders the PyBullet scene, the drives are CiA 402 nodes on python-can's virtual bus, and the
away side (if the task has one) is played by the task's opponent, as a human would play it.
Time is simulated: one :meth:`SimulatedTable.step` is one control step, in lockstep with the loop.
"""

from __future__ import annotations

import itertools
import os
from typing import Any

import gymnasium as gym
import numpy as np

from foosball_gym import table as T
from foosball_gym.camera import CameraModel
from foosball_gym.hardware.config import BusConfig, JointConfig, TableConfig
from foosball_gym.interface.task import TaskInterface
from foosball_gym.sim_table.drives import SimulatedDrives

# Calibration of the simulated drives: arbitrary but drive-like, and the revolute drive turned
# round, so that a sign error anywhere between policy and rod shows.
SLIDE_INCREMENTS_PER_M = 90_000.0
SPIN_INCREMENTS_PER_RAD = 3600 / (2 * np.pi)
SIM_HEARTBEAT_TIMEOUT_S = 1.0
_channels = itertools.count()


def sim_table_config(interface: TaskInterface, mode: str = "csp") -> TableConfig:
    """A table configuration with one drive per joint of the task's controlled rods, on a
    virtual CAN channel of its own."""
    joints = []
    node = 1
    for rod in interface.layout.controlled:
        for kind, scale, direction in (
            ("slide", SLIDE_INCREMENTS_PER_M, 1),
            ("spin", SPIN_INCREMENTS_PER_RAD, -1),
        ):
            joints.append(
                JointConfig(
                    rod=rod,
                    joint=kind,
                    node_id=node,
                    increments_per_unit=scale,
                    direction=direction,
                )
            )
            node += 1
    channel = f"foosball-sim-{os.getpid()}-{next(_channels)}"
    # The simulated drives beat their heartbeats from threads of this very process, which
    # rendering the camera's frames can hold up for tens of milliseconds on a busy machine.
    return TableConfig(
        joints=joints,
        bus=BusConfig(interface="virtual", channel=channel),
        control_hz=float(T.CONTROL_HZ),
        mode=mode,
        heartbeat_timeout_s=SIM_HEARTBEAT_TIMEOUT_S,
    )


class SimulatedTable:
    """The simulated table for a task.

    Args:
        env_id, env_kwargs: the task the policy was trained on.
        config: the table configuration the master uses (see :func:`sim_table_config`); its
            bus must be a ``virtual`` one.
        seed: seeds the serves (and the opponent's randomness, if any).
        camera_size: (width, height) of the rendered camera frames.
    """

    def __init__(
        self,
        env_id: str,
        env_kwargs: dict[str, Any] | None,
        config: TableConfig,
        seed: int = 0,
        camera_size: tuple[int, int] = (640, 360),
    ) -> None:
        self.env = gym.make(env_id, **(env_kwargs or {})).unwrapped
        self.env.reset(seed=seed)
        self.sim = self.env.sim
        self.camera_model = CameraModel(*camera_size)
        self.drives = SimulatedDrives(config, self.sim)
        self.time = 0.0
        self.goals_for = self.goals_against = 0

    def frame(self) -> np.ndarray:
        """The camera's view of the table now, RGB."""
        return self.sim.render(self.camera_model.width, self.camera_model.height)

    def serve(self) -> None:
        """A new ball, as the task starts its episodes; the rods stay where they are."""
        self.env.serve()
        self.goals_for = self.goals_against = 0

    def step(self) -> tuple[int, bool]:
        """One control step: the drives take their targets, the opponent moves, physics runs.

        Returns:
            ``(goal, out_of_table)`` as :meth:`TableSim.step` reports them.
        """
        if self.env.layout.opponent:
            self.drives.set_free_targets(self.env.opponent_targets())
        self.drives.apply()
        goal, out = self.sim.step()
        self.env.refresh()
        self.time += self.sim.control_dt
        self.drives.publish()
        if goal == T.HOME_SCORED:
            self.goals_for += 1
        elif goal == T.AWAY_SCORED:
            self.goals_against += 1
        return goal, out

    @property
    def success(self) -> bool:
        """Whether the task is met by the goals since the last serve."""
        return self.env.success(self.goals_for, self.goals_against)

    def ball(self) -> tuple[float, float, float, float]:
        """The true ball x, y, vx, vy (for comparing the estimate with)."""
        return self.sim.ball_xy()

    def close(self) -> None:
        self.drives.close()
        self.env.close()
