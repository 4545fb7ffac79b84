"""System identification: the physical parameters of a table, fitted to what it logged.

``foosball sysid LOG.jsonl`` fits, to the session logs of ``foosball play --log``, the
physics the environments take as options: the ball's rolling resistance, restitution and
friction, the drives' gain and their command-to-motion latency, and the camera's latency where
the log's timestamps show it (docs/system-identification.md).

- :mod:`~foosball_gym.real_table.sysid.logs` reads and checks logs,
  :mod:`~foosball_gym.real_table.sysid.segments` cuts the ball's track into stretches no figurine
  touches, and :mod:`~foosball_gym.real_table.sysid.latency` reads the camera's latency from the
  frames' timestamps: none of them needs the simulator;
- :mod:`~foosball_gym.real_table.sysid.fit` fits the ball and the drives by replaying the logged
  stretches in the simulator (:mod:`foosball_gym.sim.replay`);
- :mod:`~foosball_gym.real_table.sysid.excitation` is the calibration serve pattern of the simulated
  table, which makes logs worth fitting.
"""

from foosball_gym.real_table.sysid.logs import LogError, PlayLog, read_logs

__all__ = ["LogError", "PlayLog", "read_logs"]
