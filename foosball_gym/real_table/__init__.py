"""The real table: everything that stands between a policy and a physical table.

- :mod:`~foosball_gym.real_table.hardware`: the table's configuration, its CANopen drives and
  the safety layer in front of them;
- :mod:`~foosball_gym.real_table.vision`: frame sources, calibration, ball detection and the
  opponent's rods;
- :mod:`~foosball_gym.real_table.play`: the control loop that runs a policy on a table, its
  session logs and the stack assembled around them;
- :mod:`~foosball_gym.real_table.virtual`: a simulated table standing where the real one would
  (virtual CAN drives, a rendered camera, a window), for ``foosball play --table sim``;
- :mod:`~foosball_gym.real_table.sysid`: a table's physics fitted to the logs it played.

Hardware, vision and play never import the simulator; only ``virtual`` and ``sysid`` (which
replays logs in it) do. The state estimator and the observation builder the table shares with
the environments live below, in :mod:`foosball_gym.estimation` and
:mod:`foosball_gym.policy_io`. This package imports nothing itself: the environments' camera
model reaches :mod:`~foosball_gym.real_table.vision` without loading the rest.
"""
