"""Replaying what a table logged, under physical parameters of one's choosing: the simulator's
side of system identification (:mod:`foosball_gym.real_table.sysid`).

- :class:`BallReplay` rolls a ball on the bare table (no rods: the segments replayed are those
  where no figurine could reach the ball) from a state, and says where it is at given times.
- :class:`DriveReplay` moves drives one control step on from logged states towards logged
  targets, by the law the simulated drives follow (:mod:`foosball_gym.sim.drives`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from foosball_gym import table
from foosball_gym.sim.drives import RodDrives
from foosball_gym.sim.table_sim import SLIDE_GAIN, SPIN_GAIN, TableSim, drive_limits, rolling_spin
from foosball_gym.sim.worlds import ERP_RATE


class BallReplay:
    """A ball on the table without rods, stepped at the table's control rate.

    Args:
        physics_hz, control_hz, contact_travel: the simulator's options (see :class:`TableSim`);
            those of the table that made the log reproduce it step for step.
    """

    def __init__(
        self,
        physics_hz: int = table.PHYSICS_HZ,
        control_hz: int = table.CONTROL_HZ,
        contact_travel: float = table.CONTACT_TRAVEL,
    ) -> None:
        self.sim = TableSim(
            (), physics_hz=physics_hz, control_hz=control_hz, contact_travel=contact_travel
        )
        self.dt = self.sim.control_dt

    def track(
        self,
        state: Sequence[float] | np.ndarray,
        times: np.ndarray,
        *,
        rolling_resistance: float,
        restitution: float,
        friction: float,
    ) -> np.ndarray:
        """Where the ball is at ``times`` (s after the start, sorted, >= 0): (len(times), 2).

        Args:
            state: the ball at time 0: x, y (m), vx, vy (m/s) and the velocity (ux, uy) whose
                rolling spin it has (m/s): ``(ux, uy) == (vx, vy)`` is a ball rolling without
                slipping, ``(0, 0)`` one sliding without spin.
            times: when to say where it is; between control steps positions are interpolated.
            rolling_resistance, restitution, friction: the ball's parameters (see
                :meth:`TableSim.set_ball_dynamics`).
        """
        times = np.asarray(times, dtype=float)
        duration = float(times[-1]) if len(times) else 0.0
        grid, path = self.path(
            state,
            duration,
            rolling_resistance=rolling_resistance,
            restitution=restitution,
            friction=friction,
        )
        return np.stack([np.interp(times, grid, path[:, 0]), np.interp(times, grid, path[:, 1])], 1)

    def path(
        self,
        state: Sequence[float] | np.ndarray,
        duration: float,
        *,
        rolling_resistance: float,
        restitution: float,
        friction: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The ball's x, y, vx, vy at every control step from ``state`` (see :meth:`track`) for
        ``duration`` seconds: (times, (steps + 1, 4))."""
        x, y, vx, vy, ux, uy = (float(v) for v in state)
        sim = self.sim
        sim.set_ball_dynamics(
            rolling_resistance=rolling_resistance, restitution=restitution, friction=friction
        )
        sim.place_ball((x, y), (vx, vy), spin=rolling_spin(ux, uy))
        steps = max(0, int(np.ceil(duration / self.dt - 1e-9)))
        path = np.empty((steps + 1, 4))
        path[0] = x, y, vx, vy
        for k in range(1, steps + 1):
            sim.step()
            path[k] = sim.ball_xy()
        return np.arange(steps + 1) * self.dt, path

    def close(self) -> None:
        self.sim.close()


class DriveReplay:
    """Drives moved one control step at a time, each from a logged state: many steps at once.

    Args:
        joints: the joints replayed, as ``(rod, "slide" | "spin")``.
        physics_hz, control_hz: the simulator's rates: a control step is
            ``physics_hz // control_hz`` steps of the drives' law.
    """

    def __init__(
        self,
        joints: Sequence[tuple[str, str]],
        physics_hz: int = table.PHYSICS_HZ,
        control_hz: int = table.CONTROL_HZ,
    ) -> None:
        self.joints = [(table.rod(rod).name, kind) for rod, kind in joints]
        for _, kind in self.joints:
            if kind not in ("slide", "spin"):
                raise ValueError(f"a joint is 'slide' or 'spin', got {kind!r}")
        rods = sorted({rod for rod, _ in self.joints})
        limits = drive_limits([table.rod(r) for r in rods])
        n = len(rods)
        self._limits = {
            (rod, kind): {
                key: values[i + (n if kind == "spin" else 0)] for key, values in limits.items()
            }
            for i, rod in enumerate(rods)
            for kind in ("slide", "spin")
        }
        self.substeps = physics_hz // control_hz
        self.dt = 1.0 / physics_hz

    def base_gain(self, joint: int) -> float:
        """The simulated drive's own position gain (1/s) for ``self.joints[joint]``."""
        return SLIDE_GAIN if self.joints[joint][1] == "slide" else SPIN_GAIN

    def step(
        self,
        joint: np.ndarray,
        position: np.ndarray,
        velocity: np.ndarray,
        targets: np.ndarray,
        gain_factor: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """One control step of every sample: each starts at its logged position and velocity
        and follows its targets, one a physics step.

        Args:
            joint: per sample, its joint's index in ``self.joints``.
            position, velocity: per sample, the joint's state at the start.
            targets: (samples, substeps): the position target in force at each physics step.
            gain_factor: a factor on the drives' position gains.

        Returns:
            Every sample's position and velocity after the control step.
        """
        joint = np.asarray(joint, dtype=int)
        keys = [self.joints[j] for j in joint]
        per_sample = {
            key: [self._limits[k][key] for k in keys]
            for key in ("mass", "gravity", "max_force", "max_speed", "lower", "upper")
        }
        gains = [gain_factor * self.base_gain(j) for j in joint]
        drives = RodDrives(**per_sample, gains=gains, erp_rate=ERP_RATE)
        drives.pos[:] = [float(v) for v in position]
        drives.vel[:] = [float(v) for v in velocity]
        everyone = range(len(joint))
        targets = np.asarray(targets, dtype=float)
        for s in range(targets.shape[1]):
            drives.command("position", targets[:, s].tolist())
            drives.advance(everyone, self.dt)
        return np.array(drives.pos), np.array(drives.vel)
