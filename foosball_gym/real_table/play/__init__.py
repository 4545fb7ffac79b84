"""Running a policy on a table: the control loop, session logs, and the stack around them.

Needs the hardware extra (``pip install -e ".[hardware]"``); never the simulator,
except through :mod:`foosball_gym.real_table.virtual` for ``--table sim``.
"""
