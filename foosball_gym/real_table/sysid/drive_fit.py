"""The drives' response, fitted to what they reported after each command.

Every loop logs each drive's position and velocity as the loop began and the target it sent;
the next loop logs where the drive got to. The simulated drives' law
(:mod:`foosball_gym.sim.drives`, replayed by :class:`~foosball_gym.sim.replay.DriveReplay`)
moves each logged state one control step on towards the targets in force, and the fit finds the
factor on the drives' gains and the latency from a command to the drive acting on it under which
that lands where the drive reported. The latency is searched in whole physics steps (the
drives' law acts once a physics step), each with its best gain; the gain is then fitted to every
step at the best latency.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from foosball_gym import table
from foosball_gym.real_table.sysid.estimate import cluster_covariance
from foosball_gym.real_table.sysid.logs import PlayLog
from foosball_gym.sim.replay import DriveReplay

#: The longest command-to-motion latency searched (s).
MAX_LATENCY_S = 0.05
#: The drive gain factor's bounds, as the environments' drive_gain_range allows.
GAIN_BOUNDS = (1e-3, 10.0)
# Residuals in mm of travel (what a mm is in each joint's unit): of the rod along its slide, of
# a foot about the spin axis.
_SCALE = {"slide": 1e-3, "spin": 1e-3 / table.FIGURINE_FOOT_BELOW_AXIS}
# The latency is searched on at most this many steps, evenly drawn.
_PROFILE_SAMPLES = 3000
# A loop's command is counted for the next if the loops were within this share of a period of
# the control rate apart.
_PERIOD_SLACK = 0.25
# Residuals are grouped for the uncertainty by this much of a log's time (s).
_CLUSTER_S = 1.0


@dataclass
class DriveSamples:
    """Control steps of the drives, each from a logged state towards logged targets.

    Attributes:
        joints: the joints, ``(rod, "slide" | "spin")``.
        joint: per step, its joint's index.
        position, velocity: the joint's state at the step's start.
        after: where the next loop found it.
        targets: the targets sent from ``history`` loops before the step's to the step's own,
            (steps, history + 1).
        cluster: per step, a label of the second of its log it falls in.
    """

    joints: list[tuple[str, str]]
    joint: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    after: np.ndarray
    targets: np.ndarray
    cluster: np.ndarray

    def __len__(self) -> int:
        return len(self.joint)

    def take(self, rows: np.ndarray) -> DriveSamples:
        return DriveSamples(
            self.joints,
            self.joint[rows],
            self.position[rows],
            self.velocity[rows],
            self.after[rows],
            self.targets[rows],
            self.cluster[rows],
        )


@dataclass
class DriveFit:
    """What the drives' fit found.

    Attributes:
        gain, gain_std: the factor on the drives' gains, and its uncertainty.
        latency_s, latency_std: the command-to-motion latency (s), and its uncertainty (at
            least half a physics step: the resolution of the search).
        rms_before_mm, rms_after_mm: the RMS distance (mm of rod or foot travel) between where
            the drives' law and the drives themselves put each joint a step later, under the
            simulator's drives (gain factor 1, no latency) and under the fitted ones.
        steps: the control steps fitted.
        profile: each latency searched (s) with the cost of its best gain.
    """

    gain: float
    gain_std: float
    latency_s: float
    latency_std: float
    rms_before_mm: float
    rms_after_mm: float
    steps: int
    profile: list[tuple[float, float]] = field(repr=False)


def drive_samples(logs: list[PlayLog], history: int) -> DriveSamples | None:
    """Every control step of the logs' drives that shows their response (the drive moved, or
    was told to), with the ``history`` targets before; None if there is none."""
    joints: list[tuple[str, str]] = []
    parts: dict[str, list[np.ndarray]] = {
        k: [] for k in ("joint", "position", "velocity", "after", "targets", "cluster")
    }
    for number, log in enumerate(logs):
        period = 1.0 / log.control_hz
        gaps = np.diff(log.t)
        steady = np.abs(gaps - period) <= _PERIOD_SLACK * period
        n = log.loops
        for column, name in enumerate(log.joints):
            rod, kind = name.split(".")
            if (rod, kind) not in joints:
                joints.append((rod, kind))
            pos, vel = log.position[:, column], log.velocity[:, column]
            sent = log.targets[:, column]
            rows = []
            for k in range(history, n - 1):
                window = slice(k - history, k + 1)
                if not (
                    steady[k - history : k + 1].all()
                    and np.isfinite(sent[window]).all()
                    and math.isfinite(pos[k] + vel[k] + pos[k + 1])
                    and not log.late[window].any()
                ):
                    continue
                moving = (
                    abs(vel[k]) > 1e-6
                    or abs(pos[k + 1] - pos[k]) > 1e-6
                    or np.abs(sent[window] - pos[k]).max() > 1e-6
                )
                if moving:
                    rows.append(k)
            if not rows:
                continue
            rows_a = np.array(rows)
            parts["joint"].append(np.full(len(rows_a), joints.index((rod, kind))))
            parts["position"].append(pos[rows_a])
            parts["velocity"].append(vel[rows_a])
            parts["after"].append(pos[rows_a + 1])
            parts["targets"].append(
                np.stack([sent[rows_a - history + h] for h in range(history + 1)], 1)
            )
            parts["cluster"].append(number * 1_000_000 + np.floor(log.t[rows_a] / _CLUSTER_S))
    if not parts["joint"]:
        return None
    return DriveSamples(joints, *(np.concatenate(parts[k]) for k in list(parts)))


def fit_drives(samples: DriveSamples, physics_hz: int, control_hz: int) -> DriveFit:
    """The gain factor and latency of the drives (see the module's docstring)."""
    replay = DriveReplay(samples.joints, physics_hz, control_hz)
    substeps, history = replay.substeps, samples.targets.shape[1] - 1
    most = min(round(MAX_LATENCY_S * physics_hz), history * substeps)
    scale = np.array([_SCALE[samples.joints[j][1]] for j in samples.joint])

    def residuals(gain: float, delay: int, part: DriveSamples, part_scale: np.ndarray):
        # The target in force at each physics step of the control step: sent ``delay`` physics
        # steps before, so from an earlier loop for the first ``delay`` of them.
        column = history + np.floor((np.arange(substeps) - delay) / substeps).astype(int)
        position, _ = replay.step(
            part.joint, part.position, part.velocity, part.targets[:, column], gain
        )
        return (position - part.after) / part_scale

    before = residuals(1.0, 0, samples, scale)
    rows = np.unique(
        np.linspace(0, len(samples) - 1, min(len(samples), _PROFILE_SAMPLES)).astype(int)
    )
    sub, sub_scale = samples.take(rows), scale[rows]
    first = least_squares(lambda g: residuals(g[0], 0, sub, sub_scale), [1.0], bounds=GAIN_BOUNDS)
    spread = 1.4826 * float(np.median(np.abs(first.fun)))
    f_scale = max(2.5 * spread, 1e-3)
    profile = []
    for delay in range(most + 1):
        result = least_squares(
            lambda g, d=delay: residuals(g[0], d, sub, sub_scale),
            [first.x[0]],
            bounds=GAIN_BOUNDS,
            loss="soft_l1",
            f_scale=f_scale,
        )
        profile.append((delay, float(result.cost), float(result.x[0])))
    best = min(profile, key=lambda p: p[1])
    delay = best[0]
    final = least_squares(
        lambda g: residuals(g[0], delay, samples, scale),
        [best[2]],
        bounds=GAIN_BOUNDS,
        loss="soft_l1",
        f_scale=f_scale,
    )
    gain_std = float(np.sqrt(cluster_covariance(final, samples.cluster, f_scale)[0, 0]))
    # The latencies whose cost is within one unit of chi-square of the best's.
    variance = 2 * best[1] / max(len(rows) - 2, 1)
    near = [d for d, cost, _ in profile if 2 * (cost - best[1]) / max(variance, 1e-300) <= 1.0]
    step = 1.0 / physics_hz
    latency_std = max(0.5 * step, 0.5 * (max(near) - min(near)) * step)
    return DriveFit(
        gain=float(final.x[0]),
        gain_std=gain_std,
        latency_s=delay * step,
        latency_std=latency_std,
        rms_before_mm=float(np.sqrt(np.mean(before**2))),
        rms_after_mm=float(np.sqrt(np.mean(final.fun**2))),
        steps=len(samples),
        profile=[(d * step, cost) for d, cost, _ in profile],
    )


def history_for(physics_hz: int, control_hz: int) -> int:
    """How many loops' targets before a step's own the latency search needs."""
    return math.ceil(MAX_LATENCY_S * physics_hz / (physics_hz // control_hz))
