"""Putting the real-table stack together, for a real table or the simulated one.

:func:`play` runs a policy on a table for a number of episodes (the simulated table serves a ball
per episode) or for a while (the real table, where people serve). Both go through the same
:class:`~foosball_gym.real_table.play.loop.PlayLoop`: camera, detector, Kalman filter, observation
builder, policy, safety layer, CAN.
"""

from __future__ import annotations

import contextlib
import gc
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

from foosball_gym.estimation import BallFilter, TableStateEstimator
from foosball_gym.policy_io.task import TaskInterface
from foosball_gym.real_table.hardware.config import TableConfig
from foosball_gym.real_table.hardware.drives import TableDrives
from foosball_gym.real_table.play.human import KEY_HINTS, HumanOpponent, check_view, human_rod
from foosball_gym.real_table.play.loop import STAGES, LoopRecord, PlayLoop, StatusLine
from foosball_gym.real_table.play.session import SessionLog
from foosball_gym.real_table.vision import (
    BallDetector,
    CameraCalibration,
    ColourBallDetector,
    OnnxBallDetector,
    OpenCVSource,
    RodTracker,
    calibrate_from_frame,
    calibrate_intrinsics,
)
from foosball_gym.table import rod

if TYPE_CHECKING:
    from foosball_gym.registration import CheckedOptions


@dataclass
class PlayReport:
    """What a session did: episodes and their outcome, and where the loop's time went."""

    episodes: int = 0
    successes: int = 0
    goals_for: int = 0
    goals_against: int = 0
    steps: int = 0
    stage_ms: dict[str, list[float]] = field(default_factory=lambda: {s: [] for s in STAGES})
    ball_error_mm: list[float] = field(default_factory=list)
    #: Time from one loop to the next (ms), and the loops that overran their period.
    period_ms: list[float] = field(default_factory=list)
    late: int = 0
    #: Loops whose frame came too late to use (the simulated table in real time).
    frames_missed: int = 0
    _last_t: float | None = None

    def add(self, record: LoopRecord) -> None:
        self.steps += 1
        self.late += record.late
        self.frames_missed += record.frame_missed
        if self._last_t is not None:
            self.period_ms.append(1e3 * (record.t - self._last_t))
        self._last_t = record.t
        for name, ms in record.stage_ms.items():
            self.stage_ms[name].append(ms)

    def timing_summary(self) -> str:
        """The loop's period and how many loops were late."""
        if not self.period_ms:
            return "loop period: no loops timed"
        periods = np.array(self.period_ms)
        share = 100 * self.late / max(self.steps, 1)
        return (
            f"loop period median {np.median(periods):.2f} ms, p99 "
            f"{np.percentile(periods, 99):.2f} ms; late {self.late} of {self.steps} loops "
            f"({share:.2f} %); frames too late to use {self.frames_missed}"
        )

    def timing_table(self) -> str:
        rows = []
        total = np.zeros(max(len(v) for v in self.stage_ms.values()) or 1)
        for name in STAGES:
            values = np.array(self.stage_ms[name]) if self.stage_ms[name] else np.zeros(1)
            total[: len(values)] += values
            rows.append(f"{name:9s} {np.median(values):7.2f} {np.percentile(values, 99):7.2f}")
        rows.append(f"{'total':9s} {np.median(total):7.2f} {np.percentile(total, 99):7.2f}")
        return "stage     median ms  p99 ms\n" + "\n".join(rows)

    @property
    def success_rate(self) -> float:
        return self.successes / self.episodes if self.episodes else 0.0


@contextlib.contextmanager
def collector_paused_for_old_objects() -> Any:
    """Keep the garbage collector from walking everything the session set up, while it runs.

    A full collection walks every object the interpreter tracks: with the simulator, the
    drives and the model loaded that took 45 ms on this project's 2-core machine, and it
    came at random loops, so a table on the wall clock went a watchdog period without a
    command. Frozen, the objects made before the loop are left out of every collection; the
    loop's own garbage is still collected, in the young generations as it comes.
    """
    gc.collect()
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def build_perception(
    config: TableConfig, interface: TaskInterface, latency_s: float | None
) -> tuple[BallDetector, CameraCalibration, TableStateEstimator, RodTracker | None]:
    """Detector, calibration, estimator and rod tracker (None without an opponent) from a
    table configuration: the perception arguments of :class:`PlayLoop`, in its order."""
    vision, camera, estimation = config.vision, config.camera, config.estimation
    if not camera.get("calibration"):
        raise ValueError(
            "the table configuration has no camera calibration; run "
            "`foosball calibrate --table CONFIG` first"
        )
    calibration = CameraCalibration.from_dict(camera["calibration"])
    if vision.get("detector", "colour") == "onnx":
        detector: BallDetector = OnnxBallDetector(vision["onnx_model"], **vision.get("onnx", {}))
    else:
        detector = ColourBallDetector(**vision.get("ball", {}))
    # The camera follows the opponent's rods, and still obstacles where a task has them.
    builder = interface.builder
    tracked = [rod(name) for name in builder.tracked_rods]
    tracker = RodTracker(calibration, tracked, **vision.get("rods", {})) if tracked else None
    latency = latency_s if latency_s is not None else estimation.get("latency_s", 0.03)
    estimator = TableStateEstimator(
        builder,
        latency_s=latency,
        ball=BallFilter(**estimation.get("ball", {})),
        rod_measurement_std=estimation.get("rod_measurement_std", 0.003),
    )
    return detector, calibration, estimator, tracker


def calibrate_table(
    config: TableConfig,
    frame: np.ndarray,
    chessboard: list[np.ndarray] | None = None,
    pattern: tuple[int, int] = (9, 6),
    square: float = 0.025,
    home_side: str = "left",
) -> dict[str, Any]:
    """Calibrate the camera and store the result in ``config.camera["calibration"]``.

    Intrinsics come from chessboard views if given, else from the configuration's
    ``camera.K`` / ``camera.dist``; the pose from the field's corners in ``frame``.

    Returns:
        A summary: the camera's position and, with a chessboard, the reprojection error.
    """
    summary: dict[str, Any] = {}
    if chessboard:
        K, dist, rms = calibrate_intrinsics(chessboard, pattern, square)
        summary["chessboard_rms_px"] = round(rms, 3)
        config.camera["K"], config.camera["dist"] = K.tolist(), dist.tolist()
    elif "K" in config.camera:
        K = np.asarray(config.camera["K"], dtype=float)
        dist = np.asarray(config.camera.get("dist", [0.0] * 5), dtype=float)
    else:
        raise ValueError(
            "no intrinsics: give chessboard images, or camera.K in the table configuration"
        )
    calibration = calibrate_from_frame(frame, K, dist, home_side)
    config.camera["calibration"] = calibration.to_dict()
    summary["camera_position_m"] = [round(float(v), 4) for v in calibration.centre]
    return summary


def play_real(
    policy: Callable[[np.ndarray], Any],
    interface: TaskInterface,
    config: TableConfig,
    duration_s: float | None,
    log_path: str | None = None,
    latency_s: float | None = None,
    status: bool = True,
) -> PlayReport:
    """Play on a real table until ``duration_s`` passes or Ctrl-C; the drives are disabled on
    the way out, whatever happens."""
    perception = build_perception(config, interface, latency_s)
    camera = config.camera
    report = PlayReport()
    period = config.control_period
    # Whatever is opened is closed however the session ends, a log that cannot be written
    # included: a camera left open holds its device until the process ends.
    with contextlib.ExitStack() as opened:
        source = OpenCVSource(
            camera.get("source", 0), camera.get("width"), camera.get("height"), camera.get("fps")
        )
        opened.callback(source.close)
        on_record, log = _recorders(report, log_path, _header(interface, config), status)
        if log is not None:
            opened.callback(log.close)
        with TableDrives(config) as drives, collector_paused_for_old_objects():
            drives.bring_up()
            loop = PlayLoop(policy, interface, drives, source, *perception, on_record=on_record)
            loop.start()
            end = None if duration_s is None else time.monotonic() + duration_s
            next_tick = time.monotonic()
            while end is None or time.monotonic() < end:
                record = loop.decide()
                loop.send(record)
                next_tick += period
                time.sleep(max(0.0, next_tick - time.monotonic()))
                loop.receive(record)
    return report


def play_sim(
    policy: Callable[[np.ndarray], Any],
    env_id: str,
    env_kwargs: dict[str, Any],
    episodes: int,
    seed: int = 0,
    log_path: str | None = None,
    latency_s: float | None = 0.03,
    status: bool = False,
    camera_size: tuple[int, int] | None = None,
    realtime: bool = False,
    gui: bool = False,
    human: str | None = None,
    pace: bool = False,
    camera_latency_s: float | None = None,
    view: str = "top",
    serves: str = "task",
    camera_errors: bool = True,
    checked: CheckedOptions | None = None,
) -> PlayReport:
    """Play ``episodes`` served balls on the simulated table, through the whole stack.

    ``realtime`` runs the table on the wall clock (see
    :mod:`foosball_gym.real_table.virtual.simulated_table`); the default is lock-step. The camera's
    frames are 640 x 360 in lock-step and 320 x 180 in real time unless ``camera_size`` says.

    ``camera_latency_s`` is how long the simulated camera's frames take to reach the loop
    (see :class:`~foosball_gym.real_table.virtual.simulated_table.SimulatedTable`; by default the
    latency of the task's simulated camera, 30 ms unless ``camera_noise`` says).
    ``camera_errors`` False pictures the ball and the rods exactly where they are, instead of
    with the errors of the task's camera model.

    ``gui`` opens the PyBullet GUI on the table, with the serve and the score written in the window.
    ``human`` names the away rod (``"keeper"``, or in Foosball-FullGame-v0 also ``"defense"``,
    ``"midfield"``, ``"offense"``) a person drives from the window's keyboard
    (:mod:`foosball_gym.real_table.play.human`) against the policy, the other away rods played by
    the task's opponent; it opens the GUI. Neither changes the clock: ``pace`` keeps a lock-step
    table from running ahead of the wall clock, which ``foosball play --gui`` chooses.

    ``view`` is where the window looks from: ``"top"`` (straight down, the home goal on the
    left) or ``"away"`` (from behind the away goal, the person's side); the keys follow it.

    Closing the window ends the game after the serve in play.

    ``serves`` is ``"task"`` (the task's own balls) or ``"calibration"``: balls that show the
    table's physics to ``foosball sysid`` (:mod:`foosball_gym.real_table.sysid.excitation`), each
    played for up to 4 s.

    ``checked``: the task's options as ``check_env_options(env_id, env_kwargs)`` gives them,
    where the caller has resolved them already (``foosball play`` does, once).

    Raises:
        ValueError: ``human`` names no away rod of the task (or the task has no away side).
        WindowError: the GUI window could not be opened (no display); a RuntimeError.
    """
    from foosball_gym.real_table.virtual.simulated_table import SimulatedTable, virtual_table_config
    from foosball_gym.registration import check_env_options

    if checked is None:
        checked = check_env_options(env_id, env_kwargs)
    if camera_size is None:
        # A paced table renders in the loop's own time: the small frame keeps it near real time.
        camera_size = REALTIME_CAMERA if realtime or pace else LOCKSTEP_CAMERA
    interface = checked.interface
    rod = None if human is None else human_rod(env_id, interface.layout, human)
    check_view(view)
    gui = gui or rod is not None
    config = virtual_table_config(interface)
    table = SimulatedTable(
        env_id,
        env_kwargs,
        config,
        seed=seed,
        camera_size=camera_size,
        camera_latency_s=camera_latency_s,
        realtime=realtime,
        gui=gui,
        pace=pace,
        view=view,
        serves=serves,
        camera_errors=camera_errors,
        checked=checked,
    )
    # Everything the table started (its camera, its viewer, its drives' threads) ends however
    # the session does, a log that cannot be opened included: left running, they keep the
    # command from ever exiting.
    log: SessionLog | None = None
    try:
        if rod is not None:
            keys = table.keyboard_events
            dt = table.sim.control_dt
            table.set_opponent(
                HumanOpponent(keys, interface.layout, rod, dt, table.opponent, view=view)
            )
        calibration = CameraCalibration.from_camera_model(table.camera_model)
        config.camera["calibration"] = calibration.to_dict()
        perception = build_perception(config, interface, latency_s)
        source = _TableCamera(table)
        report = PlayReport()
        header = _header(interface, config, env_id, env_kwargs)
        on_record, log = _recorders(report, log_path, header, status)
        max_steps = table.serve_steps or gym.spec(env_id).max_episode_steps
        assert max_steps is not None  # every id is registered with its time limit
        # Supervision runs on the table's clock: simulated time in lock-step, where a slow
        # frame is no silence on the table, and the wall clock in real time.
        with (
            TableDrives(
                config,
                clock=table.clock,
                answer_timeout_s=None if realtime else LOCKSTEP_ANSWER_TIMEOUT_S,
            ) as drives,
            collector_paused_for_old_objects(),
        ):
            try:
                drives.bring_up()
                loop = PlayLoop(
                    policy,
                    interface,
                    drives,
                    source,
                    *perception,
                    clock=table.clock,
                    on_record=on_record,
                )
                table.step()  # the drives report their state once before the first decision
                loop.start()
                record = None
                for serve in range(1, episodes + 1):
                    ready = None
                    if serve > 1 and table.serves == "task":
                        ready = _ready_for_serve(table, loop)
                    table.serve()
                    # Without this the filter would take the new ball for the old one jumping,
                    # and spend the first frames of a fast shot unlearning that velocity.
                    # Its first frame comes at once, the next after the camera's latency.
                    loop.new_ball(first_frame_early_by=table.camera_latency)
                    if gui:
                        table.show_text(_score_lines(report, table, serve, episodes, rod, view))
                    if record is not None and realtime:
                        # The table's clock runs on while the camera shows the new ball: the rods
                        # keep their last targets, and the watchdog hears the loop is alive.
                        if ready is None:
                            loop.send(record)
                        else:
                            loop.command(ready)
                    for _ in range(max_steps):
                        # A step the table took while the loop was busy: its command was late.
                        late = table.late_steps
                        record = loop.decide()
                        true_x, true_y, _, _ = table.ball(at=record.frame_time)
                        loop.send(record)
                        truth = table.true_state()  # after the command: it must not wait
                        goal, out = table.step()
                        record.truth = {**truth, "goal": int(goal), "out": bool(out)}
                        record.late = table.late_steps > late
                        loop.receive(record)
                        if record.ball_measured is not None:
                            report.ball_error_mm.append(
                                1e3
                                * float(
                                    np.hypot(
                                        record.ball_measured[0] - true_x,
                                        record.ball_measured[1] - true_y,
                                    )
                                )
                            )
                        if goal and gui:
                            table.show_text(_score_lines(report, table, serve, episodes, rod, view))
                        closed = gui and not table.window_open
                        if goal or out or table.stagnated or closed:
                            break
                    report.episodes += 1
                    report.successes += table.success
                    report.goals_for += table.goals_for
                    report.goals_against += table.goals_against
                    if gui and not table.window_open:
                        break  # a person closed the window: the game ends with this serve
            finally:
                # However the loop ended, the table moves on while the drives brake and
                # switch off: a lock-step table waits for the loop no more.
                table.run_on()
    finally:
        if log is not None:
            log.close()
        table.close()
    return report


def _ready_for_serve(table: Any, loop: PlayLoop) -> dict[Any, float]:
    """Bring the rods to where the next serve's episode starts them, and to rest, before the
    ball comes: as an environment's reset places them, so that the table serves the ball of
    that episode (a rod left where the ball goes made the table draw another). Gives up after
    :data:`READY_STEPS` and serves anyway. Returns the rods' targets there."""
    targets = table.prepare_serve()
    for _ in range(READY_STEPS):
        loop.hold(targets)
        table.step()
        loop.settle()
        if table.rods_ready():
            break
    return targets


def _score_lines(
    report: PlayReport, table: Any, serve: int, episodes: int, human: str | None, view: str
) -> list[str]:
    """What the GUI window shows: the serve and the score, and who the person plays."""
    goals_for = report.goals_for + table.goals_for
    goals_against = report.goals_against + table.goals_against
    lines = [f"serve {serve} of {episodes}   goals for {goals_for}, against {goals_against}"]
    if human is not None:
        side = "right" if view == "top" else "near"
        lines.append(f"you: {human.replace('_', ' ')} ({side})   {KEY_HINTS[view]}")
    return lines


# The real-time camera renders in a process of its own, which 320 x 180 frames keep well
# within the control period (about 3 ms a frame for one rod, 5 ms for eight; 640 x 360 takes
# 12-15 ms).
LOCKSTEP_CAMERA = (640, 360)
REALTIME_CAMERA = (320, 180)
# The simulated drives answer a SYNC from a thread of their own. On a loaded machine that
# thread came more than a control period late, and 300-serve lock-step sessions stopped on a
# "fault" that simulated time never saw. A drive that does not answer at all still stops it.
LOCKSTEP_ANSWER_TIMEOUT_S = 0.5
# The most control steps the rods take to get to a serve's start: a keeper crosses its range
# and turns its feet down in well under a second.
READY_STEPS = 120


class _TableCamera:
    """The simulated table's camera as a frame source: frames stamped with the table time of
    the scene they show, which numbers them too (a still scene renders the same pixels, and
    is no frozen camera)."""

    def __init__(self, table: Any) -> None:
        self.table = table
        self.frame_number: float | None = None

    def read(self) -> tuple[float, np.ndarray | None]:
        t, frame = self.table.read()
        if frame is None:
            return t, None
        self.frame_number = t
        return t, np.ascontiguousarray(frame[:, :, ::-1])  # RGB to the BGR of OpenCV sources

    def close(self) -> None:
        pass


def _recorders(
    report: PlayReport, log_path: str | None, header: dict[str, Any], status: bool
) -> tuple[Callable[[LoopRecord], None], SessionLog | None]:
    """What every loop record goes to: the report, the session log, the status line."""
    hooks: list[Callable[[LoopRecord], None]] = [report.add]
    log = SessionLog(log_path, header) if log_path else None
    if log is not None:
        hooks.append(log)
    if status:
        hooks.append(StatusLine(sys.stderr.write))

    def record(entry: LoopRecord) -> None:
        for hook in hooks:
            hook(entry)

    return record, log


def _header(
    interface: TaskInterface,
    config: TableConfig,
    env_id: str | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> dict[str, Any]:
    with contextlib.suppress(Exception):
        config_dict = config.to_dict()
    return {
        "env_id": env_id,
        "env_kwargs": env_kwargs or {},
        "observation": list(interface.builder.names),
        "action": [f"{r}.{j}" for r, j in interface.action_joints],
        "table": config_dict,
        "started": time.time(),
    }
