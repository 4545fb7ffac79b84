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

import numpy as np

from foosball_gym import table as T
from foosball_gym.camera import CameraModel
from foosball_gym.game import Game
from foosball_gym.hardware.config import BusConfig, JointConfig, TableConfig
from foosball_gym.interface.task import TaskInterface
from foosball_gym.physics_options import PHYSICS_DEFAULTS, check_physics
from foosball_gym.sim_table.drives import SimulatedDrives
from foosball_gym.simulator import TableSim
from foosball_gym.tasks import interface_of, make_task

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
        env_id, env_kwargs: the task the policy was trained on (its physics options apply).
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
        task, options = make_task(env_id, env_kwargs)
        physics = check_physics(*(options.get(k, d) for k, d in PHYSICS_DEFAULTS.items()))
        self.sim = TableSim(task.layout.rods, **dict(zip(PHYSICS_DEFAULTS, physics)))
        try:
            self.game = Game(task, interface_of(task, options), self.sim)
            self.rng = np.random.default_rng(seed)
            self.game.start(task.sample_start(self.rng))
            self.camera_model = CameraModel(*camera_size)
            self.drives = SimulatedDrives(config, self.sim)
        except BaseException:
            self.sim.close()
            raise
        self.time = 0.0

    @property
    def goals_for(self) -> int:
        return self.game.goals_for

    @property
    def goals_against(self) -> int:
        return self.game.goals_against

    def frame(self) -> np.ndarray:
        """The camera's view of the table now, RGB."""
        return self.sim.render(self.camera_model.width, self.camera_model.height)

    def serve(self) -> None:
        """A new ball, as the task starts its episodes; the rods stay where they are."""
        self.game.serve(self.rng)

    def step(self) -> tuple[int, bool]:
        """One control step: the drives take their targets, the opponent moves, physics runs.

        Returns:
            ``(goal, out_of_table)``: goal +1 (home scored), -1 (away scored) or 0.
        """
        if self.game.task.layout.opponent:
            self.drives.set_free_targets(self.game.opponent_targets())
        self.drives.apply()
        outcome = self.game.advance()
        self.time += self.sim.control_dt
        self.drives.publish()
        return outcome.goal, outcome.out_of_table

    @property
    def success(self) -> bool:
        """Whether the task is met by the goals since the last serve."""
        return self.game.success

    def ball(self) -> tuple[float, float, float, float]:
        """The true ball x, y, vx, vy (for comparing the estimate with)."""
        return self.game.ball

    def close(self) -> None:
        self.drives.close()
        self.sim.close()
