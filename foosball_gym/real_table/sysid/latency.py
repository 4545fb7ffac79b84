"""The camera's latency, read from the frames' timestamps in session logs.

Each loop record holds the loop's time ``t`` and the time of the frame it used, ``frame_time``:
their difference is how old the picture was when the loop acted on it. The simulated table
stamps a frame with the moment it shows, so there the difference is the camera's whole latency.
A camera read through OpenCV stamps its frames when they arrive: exposure, readout and transfer
are over by then, and what the log shows is only the loop's own delay. Which of the two a log
holds is told by its table: :attr:`CameraLatency.from_exposure`. Nothing here needs the
simulator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from foosball_gym.real_table.sysid.logs import PlayLog


@dataclass(frozen=True)
class CameraLatency:
    """How old the frames were when the loops used them.

    Attributes:
        mean_s, std_s: the mean age (s) and its spread over the frames.
        frames: how many frames it was read from.
        from_exposure: whether the frames were stamped with the moment they show (the
            simulated table), so that the age is the camera's whole latency; otherwise they
            were stamped on arrival and the time before arrival is not in the logs.
    """

    mean_s: float
    std_s: float
    frames: int
    from_exposure: bool


def camera_latency(logs: list[PlayLog]) -> CameraLatency | None:
    """The age of the frames the loops of ``logs`` used (None where no loop used a new one).

    A serve's first frame is left out: the simulated table shows it at once, as an
    environment's reset does.
    """
    ages = []
    for log in logs:
        frame_time = log.frame_time
        previous = np.concatenate([[-np.inf], frame_time[:-1]])
        new = np.isfinite(frame_time) & (frame_time > previous + 1e-9) & ~log.new_ball
        ages.append(log.t[new] - frame_time[new])
    age = np.concatenate(ages) if ages else np.empty(0)
    if not len(age):
        return None
    return CameraLatency(
        mean_s=float(np.mean(age)),
        std_s=float(np.std(age)),
        frames=len(age),
        from_exposure=all(log.simulated for log in logs),
    )
