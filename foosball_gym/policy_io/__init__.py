"""What a task's policy sees and commands, with no simulator and no environment behind it.

The Gymnasium environments, the simulated table, the state estimator and the real table's play
loop all build observations and read actions through this package, so it imports none of them.
"""

from foosball_gym.policy_io.observations import ObservationBuilder, ObservationOptions
from foosball_gym.policy_io.task import Joint, Layout, TaskInterface

__all__ = ["Joint", "Layout", "ObservationBuilder", "ObservationOptions", "TaskInterface"]
