"""State estimation for the real table: Kalman filters (filterpy) on what the camera sees.

Never imports the simulator.
"""

from foosball_gym.estimation.kalman import BallFilter, RodFilter, bounce
from foosball_gym.estimation.state import TableStateEstimator

__all__ = ["BallFilter", "RodFilter", "TableStateEstimator", "bounce"]
