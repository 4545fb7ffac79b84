"""The real-table control loop: frame → detection → filter → observation → policy → safety → CAN.

Every stage is timed, so the status line and the session log say where a loop's time goes.
The loop runs the same against the real table and the simulated one; only the clock and the
step of the simulation differ (see :mod:`foosball_gym.real_table.play.stack`).
"""

from __future__ import annotations

import contextlib
import math
import time
import zlib
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from foosball_gym.policy_io.task import Joint, TaskInterface
from foosball_gym.real_table.hardware.safety import WatchdogTripped

STAGES = ("frame", "detect", "estimate", "policy", "command", "read")


@dataclass
class LoopRecord:
    """What one pass of the loop saw, decided and sent, and how long each stage took."""

    t: float
    frame_time: float | None
    detection_px: tuple[float, float] | None
    ball_measured: tuple[float, float] | None
    opponent_slides: dict[str, float | None]
    own_state: dict[str, tuple[float, float]]
    observation: list[float]
    action: list[float]
    targets: dict[str, float]
    stage_ms: dict[str, float] = field(default_factory=dict)
    #: The loop overran its period: its command reached the table a control step late.
    late: bool = False
    #: The first loop after a new ball was put in play: the estimate started afresh.
    new_ball: bool = False
    #: The frame of ``frame_time`` came too late to use: the filters predicted through it.
    #: (A frame of None with the last frame's time is no new frame due yet, as after a serve.)
    frame_missed: bool = False
    #: What only a simulated table knows: the true ball (``ball``: x, y, z) and rods
    #: (``joints``: name -> [slide, spin]) as the loop decided, and what its step brought
    #: (``goal``: +1, -1 or 0; ``out``: the ball left the table). None on a real table.
    truth: dict[str, Any] | None = None

    @property
    def loop_ms(self) -> float:
        return sum(self.stage_ms.values())


def _key(joint: Joint) -> str:
    return f"{joint[0]}.{joint[1]}"


class PlayLoop:
    """One policy playing through the real-table stack.

    Args:
        policy: a callable from an observation to an action in [-1, 1].
        interface: the task's observation builder and action mapping.
        drives: the table's drives (``TableDrives``), already brought up.
        source: the camera (``read() -> (t, frame) | None``, None at its end); a frame of
            None is one taken at ``t`` that came too late to use, a missed detection. Only a
            new picture feeds the drives' state watchdog: a camera that stops delivering them
            stops the table within ``watchdog_s`` and one control period. A picture is new
            when its time is later than the last one's and, where the source counts its
            frames (a ``frame_number`` attribute, the number of the frame ``read`` gave), its
            number changed; else where its pixels differ from the last picture's. A frozen
            camera that hands out its last picture under fresh time stamps is a fault.
        detector: the ball detector (``detect(frame) -> Detection | None``).
        calibration: pixel → table-plane back-projection (``pixel_to_table``).
        estimator: the Kalman filters (``update``, ``observation``).
        rod_tracker: ``frame -> {rod: slide | None}`` for the opponent's rods (None when the
            task has no opponent).
        clock: seconds, monotonic; the simulated table passes its simulated time. The
            drives' command guard measures on it too (``drives.use_clock``), so a lock-step
            table, which waits for the loop, is not stopped for a slow loop.
        on_record: called with every :class:`LoopRecord` (session log, status line).
    """

    def __init__(
        self,
        policy: Callable[[np.ndarray], Any],
        interface: TaskInterface,
        drives: Any,
        source: Any,
        detector: Any,
        calibration: Any,
        estimator: Any,
        rod_tracker: Callable[[np.ndarray], Mapping[str, float | None]] | None = None,
        clock: Callable[[], float] = time.monotonic,
        on_record: Callable[[LoopRecord], None] | None = None,
    ) -> None:
        self.policy = policy
        self.interface = interface
        self.drives = drives
        self.source = source
        self.detector = detector
        self.calibration = calibration
        self.estimator = estimator
        self.rod_tracker = rod_tracker
        self.clock = clock
        self.on_record = on_record
        use_clock = getattr(drives, "use_clock", None)
        if use_clock is not None:
            use_clock(clock)
        rods = interface.builder.rods_in_play
        self._n = len(rods)
        self._slot = {(rod, "slide"): i for i, rod in enumerate(rods)}
        self._slot.update({(rod, "spin"): self._n + i for i, rod in enumerate(rods)})
        self._state: Mapping[Joint, tuple[float, float]] = {}
        self._new_ball = False
        self._last_frame_time: float | None = None
        # The time of the last frame that came with a picture: what the state estimate is as
        # fresh as.
        self._last_seen: float | None = None
        self._last_number: object = None
        self._last_fingerprint: int | None = None
        # Pictures given again since the last new one: what a watchdog stop is put down to.
        self._repeats = 0
        self._first_frame_early_by = 0.0

    def start(self, state: Mapping[Joint, tuple[float, float]] | None = None) -> None:
        """Take the drives' state to begin from (``bring_up`` gives positions only)."""
        self._state = dict(state) if state is not None else self.drives.read()

    def own_joints(self) -> tuple[list[float], list[float]]:
        """The drives' joint values in the observation builder's layout (others 0)."""
        pos = [0.0] * (2 * self._n)
        vel = [0.0] * (2 * self._n)
        for joint, (p, v) in self._state.items():
            slot = self._slot.get(joint)
            if slot is not None:
                pos[slot], vel[slot] = p, v
        return pos, vel

    def new_ball(self, first_frame_early_by: float = 0.0) -> None:
        """A new ball is in play somewhere else (the simulated table served one): the next
        frame starts the ball's estimate afresh, as an environment's reset does.

        Args:
            first_frame_early_by: how much sooner than the camera's latency the first frame of
                the new ball comes (s): the simulated table shows it at once, as an
                environment's reset does, and the next one only after the latency. The state
                watchdog counts that first frame as come when it would have, so the wait for
                the second is no silence of the camera.
        """
        self.estimator.new_ball()
        self._new_ball = True
        self._first_frame_early_by = max(0.0, float(first_frame_early_by))

    def hold(self, targets: Mapping[Joint, float]) -> None:
        """One control step that sends ``targets`` (m or rad) through the safety layer
        instead of the policy's: the rods brought to where the next serve starts them. The
        camera's new pictures feed the watchdog as in :meth:`decide`; nothing is detected,
        estimated or recorded (the next ball starts its estimate afresh). Follow it with the
        table's step and :meth:`settle`."""
        frame_time, _ = self._take_frame()
        self._last_frame_time = frame_time
        self.command(targets)

    def command(self, targets: Mapping[Joint, float]) -> None:
        """Send ``targets`` (m or rad) through the safety layer, not the policy's."""
        with self._frozen_named():
            self.drives.command(targets, self.clock())

    def settle(self) -> None:
        """The drives' state after a :meth:`hold` step, and the watchdog and fault checks."""
        self._state = self.drives.read()
        self._check()

    def _check(self) -> None:
        with self._frozen_named():
            self.drives.check(self.clock())

    @contextlib.contextmanager
    def _frozen_named(self) -> Iterator[None]:
        """A state watchdog's stop (from a command or a check) says the camera froze, where
        it gave its last picture again."""
        try:
            yield
        except WatchdogTripped as err:
            if err.what != "state estimate" or not self._repeats or err.why:
                raise
            why = f"the camera gave its last picture again, {self._repeats} times"
            raise WatchdogTripped(err.what, err.age, err.timeout, why) from None

    def _perceive(
        self, times: dict[str, float]
    ) -> tuple[float, Any, tuple[float, float] | None, tuple[float, float] | None, dict]:
        """A frame through the detector into the filters: the frame's time and picture, the
        detected pixel and table point, the opponent's rods; ``times`` gets the stages' ends."""
        frame_time, frame = self._take_frame()
        times["frame"] = time.perf_counter()
        detection = self.detector.detect(frame) if frame is not None else None
        pixel, ball = None, None
        if detection is not None:
            pixel = (float(detection.u), float(detection.v))
            x, y = self.calibration.pixel_to_table(np.array(pixel))
            ball = (float(x), float(y))
        slides = {}
        if self.rod_tracker is not None and frame is not None:
            slides = dict(self.rod_tracker(frame))
        times["detect"] = time.perf_counter()
        self.estimator.update(frame_time, ball, slides)
        return frame_time, frame, pixel, ball, slides

    def _take_frame(self) -> tuple[float, Any]:
        """The camera's next frame (its time, and the picture or None); a new picture feeds
        the drives' state watchdog."""
        got = self.source.read()
        if got is None:
            raise EOFError("the camera has no more frames")
        frame_time, frame = got
        if frame is not None and self._new_picture(frame_time, frame):
            # Only a new picture is news for the state estimate: a camera that delivers none
            # (frozen, or read() giving the last frame again) trips the watchdog, however
            # busily the loop goes on predicting.
            self._last_seen = frame_time
            self._repeats = 0
            self.drives.feed_state(self.clock() + self._first_frame_early_by)
            self._first_frame_early_by = 0.0
        return frame_time, frame

    def _new_picture(self, frame_time: float, frame: Any) -> bool:
        """Whether ``frame`` is a picture the camera has not given before."""
        if self._last_seen is not None and frame_time <= self._last_seen:
            return False
        number = getattr(self.source, "frame_number", None)
        if number is not None:
            new = number != self._last_number
            self._last_number = number
        else:
            # A stalled USB camera or capture driver hands out its last picture again, stamped
            # with the time it was read. A sensor's noise changes some pixel in every real
            # picture, so one identical to the last, byte for byte, is that picture again.
            fingerprint = zlib.crc32(np.ascontiguousarray(frame).data)
            new = fingerprint != self._last_fingerprint
            self._last_fingerprint = fingerprint
        self._repeats += not new
        return new

    def decide(self) -> LoopRecord:
        """Everything before the targets go out: camera to action."""
        times: dict[str, float] = {}
        start = time.perf_counter()
        frame_time, frame, pixel, ball, slides = self._perceive(times)
        pos, vel = self.own_joints()
        obs = self.estimator.observation(pos, vel)
        times["estimate"] = time.perf_counter()
        action = [float(a) for a in np.ravel(self.policy(obs))]
        if not all(math.isfinite(a) for a in action):
            raise ValueError(f"the policy returned a non-finite action {action}")
        times["policy"] = time.perf_counter()
        stage_ms, last = {}, start
        for name in ("frame", "detect", "estimate", "policy"):
            stage_ms[name] = 1e3 * (times[name] - last)
            last = times[name]
        record = LoopRecord(
            t=self.clock(),
            frame_time=frame_time,
            detection_px=pixel,
            ball_measured=ball,
            opponent_slides=slides,
            own_state={_key(j): s for j, s in self._state.items()},
            observation=[float(v) for v in obs],
            action=action,
            targets={},
            stage_ms=stage_ms,
            new_ball=self._new_ball,
            # None for the time of the last frame is no new frame due, not a late one.
            frame_missed=frame is None and frame_time != self._last_frame_time,
        )
        self._last_frame_time = frame_time
        self._new_ball = False
        return record

    def send(self, record: LoopRecord) -> None:
        """Targets through the safety layer to the drives."""
        start = time.perf_counter()
        action = self.interface.table_action(record.action, record.observation)
        targets = self.interface.action_to_targets(action)
        with self._frozen_named():
            sent = self.drives.command(targets, record.t)
        record.targets = {_key(j): float(v) for j, v in sent.items()}
        record.stage_ms["command"] = 1e3 * (time.perf_counter() - start)

    def receive(self, record: LoopRecord) -> None:
        """The drives' state after the step; the watchdog and fault checks."""
        start = time.perf_counter()
        self._state = self.drives.read()
        self._check()
        record.stage_ms["read"] = 1e3 * (time.perf_counter() - start)
        if self.on_record is not None:
            self.on_record(record)


class StatusLine:
    """A one-line live status: loop rate, latency, ball estimate, faults."""

    def __init__(self, write: Callable[[str], Any], every: int = 15) -> None:
        self.write = write
        self.every = every
        self._count = 0
        self._last_t: float | None = None
        self._rate = 0.0
        self._late = 0

    def __call__(self, record: LoopRecord) -> None:
        self._late += record.late
        if self._last_t is not None and record.t > self._last_t:
            self._rate = 0.9 * self._rate + 0.1 / (record.t - self._last_t)
        self._last_t = record.t
        self._count += 1
        if self._count % self.every:
            return
        ball = record.ball_measured
        seen = f"ball ({ball[0]:+.3f}, {ball[1]:+.3f}) m" if ball else "ball not seen"
        self.write(
            f"\r{self._rate:5.1f} Hz | loop {record.loop_ms:5.1f} ms | late {self._late} | "
            f"{seen} | "
            f"action {' '.join(f'{a:+.2f}' for a in record.action)} | faults: none   "
        )
