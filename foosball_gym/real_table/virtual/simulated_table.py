"""A simulated real table: a task's simulation behind simulated CAN drives and a camera.

``foosball play MODEL --table sim`` runs the complete real-table stack against it: the camera
renders the PyBullet scene, the drives are CiA 402 nodes on python-can's virtual bus, and the
away side (if the task has one) is played by the task's opponent, as a human would play it.
Two ways to keep time:

- **lock-step** (``realtime=False``): time is simulated; one :meth:`SimulatedTable.step` is
  one control step, taken when the loop asks. Deterministic, for tests.
- **paced lock-step** (``pace=True``): lock-step, but a step never runs ahead of the wall
  clock, so a person watching sees the game at real speed where the machine keeps up and
  slower where it does not; supervision stays on the table's clock, so a slow machine slows
  the game instead of stopping it.
- **real time** (``realtime=True``): a thread steps the table at the control rate of the wall
  clock, whatever the loop is doing, as a real table moves; the camera renders in a process of
  its own (:mod:`~foosball_gym.real_table.virtual.camera_process`). :meth:`SimulatedTable.step` then
  waits for the next control step, and a loop that comes after its step has passed is late:
  its command acts one step later. Late steps are counted.

With ``gui=True`` a PyBullet GUI window shows the table
(:mod:`~foosball_gym.real_table.virtual.viewer_process`): a person watches it (:meth:`show_text`
writes the score in it) or plays the away side from its keyboard (:meth:`keyboard_events`, read by
an opponent that :meth:`set_opponent` sets). A serve ends as the task's episodes do: at a goal, with
the ball off the table, or with the ball lying still for the task's ``stagnation_steps``.
"""

from __future__ import annotations

import collections
import dataclasses
import itertools
import logging
import math
import os
import threading
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from foosball_gym import table
from foosball_gym.camera import CameraModel, CameraNoise
from foosball_gym.game import Game
from foosball_gym.policy_io.task import Joint, TaskInterface
from foosball_gym.real_table.hardware.config import (
    MAX_HEARTBEAT_TIMEOUT_S,
    MAX_WATCHDOG_S,
    BusConfig,
    TableConfig,
    simulated_joint,
)
from foosball_gym.real_table.sysid.excitation import (
    CALIBRATION_SERVE_S,
    calibration_serve,
    check_serves,
)
from foosball_gym.real_table.virtual.camera_process import (
    KEPT_FRAMES,
    CameraGone,
    CameraProcess,
    FrameBuffer,
)
from foosball_gym.real_table.virtual.drives import SimulatedDrives
from foosball_gym.real_table.virtual.viewer_process import ViewerProcess
from foosball_gym.registration import check_env_options
from foosball_gym.sim import TableSim
from foosball_gym.tasks.base import Start

if TYPE_CHECKING:
    from foosball_gym.registration import CheckedOptions

# Calibration of the simulated drives: arbitrary but drive-like, and the revolute drive turned
# round, so that a sign error anywhere between policy and rod shows.
SLIDE_INCREMENTS_PER_M = 90_000.0
SPIN_INCREMENTS_PER_RAD = 3600 / (2 * np.pi)
# The share of a control period a real-time loop waits for a frame still being rendered (a
# 320 x 180 frame takes 3 ms for one rod, 5 ms for all eight): the rest is the loop's.
FRAME_PATIENCE = 0.6
# Where a frame in which the detector misses the ball puts it: under the playing surface.
HIDDEN_BALL_Z = -0.1
# A rod is ready for a serve within these of the place an episode starts it, and at rest: an
# encoder's few increments, well under what moves a shot.
READY_SLIDE_M = 0.001
READY_SPIN_RAD = 0.02
READY_SPEED = 0.02

_channels = itertools.count()
logger = logging.getLogger(__name__)


def virtual_table_config(interface: TaskInterface, mode: str = "csp") -> TableConfig:
    """A table configuration with one drive per joint of the task's controlled rods, on a
    virtual CAN channel of its own."""
    joints = []
    node = 1
    for rod in interface.layout.controlled:
        for kind, scale, direction in (
            ("slide", SLIDE_INCREMENTS_PER_M, 1),
            ("spin", SPIN_INCREMENTS_PER_RAD, -1),
        ):
            joints.append(simulated_joint(rod, kind, node, scale, direction))
            node += 1
    channel = f"foosball-sim-{os.getpid()}-{next(_channels)}"
    # The simulated drives beat their heartbeats from threads of this very process, which
    # rendering the camera's frames can hold up for tens of milliseconds on a busy machine:
    # the longest heartbeat time a table file may have (0.5 s), not a real table's 0.1 s.
    # Likewise the watchdog: the camera is a renderer that shares the machine, and drops a
    # frame whenever a render overruns the control period (a frame is news for the state
    # estimate; see PlayLoop), so the longest a table file may have (0.1 s), not 50 ms.
    return TableConfig(
        joints=joints,
        bus=BusConfig(interface="virtual", channel=channel),
        control_hz=float(table.CONTROL_HZ),
        mode=mode,
        watchdog_s=MAX_WATCHDOG_S,
        heartbeat_timeout_s=MAX_HEARTBEAT_TIMEOUT_S,
    )


class SimulatedTable:
    """The simulated table for a task.

    Args:
        env_id, env_kwargs: the task the policy was trained on (its physics options apply).
        config: the table configuration the master uses (see :func:`virtual_table_config`); its
            bus must be a ``virtual`` one.
        seed: seeds the serves: serve K is the ball (and the drawn physics) of the task's
            environment reset with seed ``seed + K``.
        camera_size: (width, height) of the rendered camera frames.
        camera_latency_s: how long after it is taken a frame reaches the loop (s): exposure,
            readout and transfer on a real camera. By default the latency of the task's
            simulated camera (``estimated_state``, its ``camera_noise``), so a policy meets
            the latency it was trained with; the first frame of a serve comes at once, as at
            an environment's reset.
        realtime: keep the wall clock's time (see the module's docstring) instead of lock-step.
        gui: show the table in a PyBullet GUI window (needs a display).
        pace: in lock-step, keep steps from running ahead of the wall clock.
        view: where the GUI window looks from (see :data:`foosball_gym.sim.view.VIEWS`).
        serves: ``"task"``, the task's own balls, or ``"calibration"``, balls that show the
            table's physics to ``foosball sysid`` (:mod:`foosball_gym.real_table.sysid.excitation`),
            each served for up to :attr:`serve_steps` steps.
        camera_errors: picture the ball and the opponent's rods with the errors of the task's
            camera model (``camera_noise``; see :meth:`seen_scene`), as the environment's
            simulated camera sees them; False pictures them exactly.
        checked: ``env_id``'s options as ``check_env_options(env_id, env_kwargs)`` gives them,
            where the caller has resolved them already.

    The environment's physics options apply as they do in the environment: ``rolling_resistance``
    and the simulator's rates, and the domain randomisation ranges (``ball_friction_range``,
    ``ball_restitution_range``, ``ball_mass_range``, ``drive_gain_range``,
    ``rolling_resistance_range``, and ``drive_speed_range`` and ``drive_accel_range`` for the
    drives the policy moves), drawn afresh at every serve; a range of one value, such as
    ``(0.4, 0.4)``, makes a table with that value.
    """

    def __init__(
        self,
        env_id: str,
        env_kwargs: dict[str, Any] | None,
        config: TableConfig,
        seed: int = 0,
        camera_size: tuple[int, int] = (640, 360),
        camera_latency_s: float | None = None,
        realtime: bool = False,
        gui: bool = False,
        pace: bool = False,
        view: str = "top",
        serves: str = "task",
        camera_errors: bool = True,
        checked: CheckedOptions | None = None,
    ) -> None:
        # Checked as the environment checks them, before anything is built (once, by the
        # caller, where it passes them).
        if checked is None:
            checked = check_env_options(env_id, env_kwargs)
        task = checked.task
        self.serves = check_serves(serves)
        self._randomisation = checked.randomisation
        physics_hz, control_hz, contact_travel, rolling_resistance = checked.physics
        self.sim = TableSim(
            task.layout.rods,
            physics_hz=physics_hz,
            control_hz=control_hz,
            contact_travel=contact_travel,
            rolling_resistance=rolling_resistance,
        )
        self._base_gains = (self.sim.slide_gain, self.sim.spin_gain)
        self.dynamics: dict[str, float] = {}
        self.realtime = bool(realtime)
        self.pace = bool(pace) and not self.realtime
        self._paced_from: float | None = None
        self._t0 = time.monotonic()
        self.time = 0.0
        self.steps = 0
        self.late_steps = 0
        # The camera errs as the task's camera model says a real one does: its picture shows
        # the ball and the opponent's rods where a detector would place them.
        self.camera_noise = CameraNoise.from_dict(checked.values.camera_noise)
        if not camera_errors:
            self.camera_noise = dataclasses.replace(
                self.camera_noise, position_std=0.0, rod_std=0.0, drop_rate=0.0
            )
        self._camera_rng = np.random.default_rng([seed, 2])
        if camera_latency_s is None:
            camera_latency_s = self.camera_noise.latency_s
        if not camera_latency_s >= 0:
            raise ValueError(f"camera_latency_s must be 0 or more, got {camera_latency_s!r}")
        self.camera_latency = float(camera_latency_s)
        self._camera: CameraProcess | None = None
        self._camera_lost: CameraGone | None = None
        # Enough frames for the latency to hold back: with fewer, none would ever be due.
        kept = KEPT_FRAMES + math.ceil(self.camera_latency / self.sim.control_dt)
        self._frames = FrameBuffer(kept)  # lock-step's frames, for their latency
        self._viewer: ViewerProcess | None = None
        self._thread: threading.Thread | None = None
        try:
            self.game = Game(
                task, checked.interface, self.sim, stagnation_steps=checked.stagnation_steps
            )
            rods = task.layout.rods
            self._opponent_slides = [rods.index(rod) for rod in task.layout.opponent]
            self._seed = seed
            if self.serves == "calibration":
                # Calibration balls match no environment's episodes: one stream of balls, and
                # the physics drawn from a stream apart, so that they serve the same balls.
                self.rng = np.random.default_rng(seed)
                self._dynamics_rng = np.random.default_rng([seed, 1])
            else:
                self.rng = self._dynamics_rng = self._serve_rng(0)
            self._draw_dynamics()
            self.game.start(task.sample_start(self.rng))
            self.camera_model = CameraModel(*camera_size)
            # The drives watch the master's heartbeat on the table's own clock.
            self.drives = SimulatedDrives(config, self.sim, clock=self.clock)
            if self.realtime:
                self._camera = CameraProcess(task.layout.rods, *camera_size, kept=kept)
            if gui:
                self._viewer = ViewerProcess(task.layout.rods, view)
                self._viewer.show(*self.sim.scene())
        except BaseException:
            self.close()
            raise
        self._lock = threading.RLock()
        self._ticked = threading.Condition(self._lock)
        self._events: list[tuple[int, bool, bool]] = []
        self._stagnated = False
        # The goals since the serve (for, against), and whether the ball is dead.
        self._score = [0, 0]
        self._dead = False
        self._waiting = False
        self._stop = threading.Event()
        # The true ball of the last few steps, for comparing delayed frames' estimates with.
        self._balls: collections.deque[tuple[float, tuple[float, float, float, float]]] = (
            collections.deque(maxlen=16)
        )
        self._balls.append((0.0, self.game.ball))
        self._serves = 0
        self._served_at = 0.0
        # The next serve's start, drawn by prepare_serve(), and the places it puts the rods
        # that no drive moves (the opponent's, still obstacles) while the loop brings its own.
        self._pending: Start | None = None
        self._ready_pose: list[float] = []
        self._free_ready: dict[Joint, float] | None = None
        self._t0 = time.monotonic()
        if self._camera is not None:
            self._camera.request((0, 0.0), *self.seen_scene())

    # ------------------------------------------------------------------ time

    def clock(self) -> float:
        """The table's time (s): simulated in lock-step; in real time the wall clock's from the
        moment the table starts (:meth:`start`), and its simulated time before, so that it never
        runs back (it did, by however long the drives took to switch on, where the wall clock
        counted from the table's making)."""
        if self.realtime and self._thread is not None:
            return time.monotonic() - self._t0
        return self.time

    def start(self) -> None:
        """Start the table's own clock (real time only; lock-step waits for :meth:`step`)."""
        if not self.realtime or self._thread is not None:
            return
        self._t0 = time.monotonic() - self.time
        self._thread = threading.Thread(target=self._run, name="simulated-table", daemon=True)
        self._thread.start()

    def run_on(self) -> None:
        """Let the table move on by itself at the control rate of the wall clock, as a real
        one does whatever its master does: a lock-step table, whose loop has ended, keeps
        stepping while the master switches the drives off, so that they brake on their ramps
        (which run in the table's steps) instead of being cut off mid-motion. Nothing more is
        served or scored."""
        if self._thread is not None:
            return
        self._t0 = time.monotonic() - self.time
        self._thread = threading.Thread(target=self._run, name="simulated-table", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        dt = self.sim.control_dt
        next_tick = self._t0 + self.time + dt
        while not self._stop.is_set():
            wait = next_tick - time.monotonic()
            if wait > 0 and self._stop.wait(wait):
                break
            with self._lock:
                if not self._waiting:
                    self.late_steps += 1
                try:
                    self._events.append(self._tick())
                except Exception:
                    # The loop's next step reports the stopped clock.
                    logger.exception("the simulated table stopped")
                    return
                self._waiting = False
                self._ticked.notify_all()
                stamp, scene = (self._serves, self.time), self.seen_scene()
            if self._camera is not None and self._camera_lost is None:
                try:
                    self._camera.request(stamp, *scene)
                except CameraGone as err:
                    # The table moves on (the drives brake in its steps); the loop's next
                    # read reports the camera gone.
                    self._camera_lost = err
            next_tick += dt
            # After a stall (a debugger, a suspended process) time is not made up in a burst.
            if time.monotonic() > next_tick + dt:
                next_tick = time.monotonic() + dt

    def _tick(self) -> tuple[int, bool, bool]:
        if self._free_ready is not None:
            self.drives.set_free_targets(self._free_ready)
        elif self.game.task.layout.opponent:
            self.drives.set_free_targets(self.game.opponent_targets())
        self.drives.apply()
        outcome = self.game.advance()
        self.time += self.sim.control_dt
        self.steps += 1
        self._balls.append((self.time, self.game.ball))
        self.drives.publish()
        if self._viewer is not None:
            self._viewer.show(*self.sim.scene())
        if self._dead:
            # Until the next serve the ball counts for nothing: one lying in a goal, which
            # the real-time clock may step over several times before the loop serves, scores
            # once.
            return 0, False, False
        self._dead = outcome.ended
        if outcome.goal:
            self._score[0 if outcome.goal == table.HOME_SCORED else 1] += 1
        return outcome.goal, outcome.out_of_table, outcome.stagnated

    # ------------------------------------------------------------------ the loop's side

    def seen_scene(self) -> tuple[list[float], list[float]]:
        """The table now as its camera pictures it (:meth:`TableSim.scene`'s joint positions
        and ball), with the errors of :attr:`camera_noise`: the ball off by ``position_std``,
        or missing (below the table) in a share ``drop_rate`` of the frames, and each
        opponent rod's slide off by ``rod_std``. A figurine's head covers the ball in the
        picture itself."""
        positions, ball = self.sim.scene()
        noise, rng = self.camera_noise, self._camera_rng
        if noise.drop_rate and rng.random() < noise.drop_rate:
            ball = [ball[0], ball[1], HIDDEN_BALL_Z]
        elif noise.position_std:
            dx, dy = rng.normal(0.0, noise.position_std, size=2)
            ball = [ball[0] + float(dx), ball[1] + float(dy), ball[2]]
        if noise.rod_std:
            for i in self._opponent_slides:
                positions[i] += float(rng.normal(0.0, noise.rod_std))
        return positions, ball

    def frame(self) -> np.ndarray:
        """The camera's view of the table now, RGB (lock-step)."""
        return self.sim.render(
            self.camera_model.width, self.camera_model.height, scene=self.seen_scene()
        )

    def read(self) -> tuple[float, np.ndarray | None]:
        """The newest camera frame whose latency has passed and the table time it shows, RGB;
        a frame of ``None`` where no new one is due (the time is then the last frame's), or
        the one due came too late to use.

        Lock-step renders a frame at every call. In real time the camera process renders one
        at every step of the table, and a frame still being rendered is waited for at most
        :data:`FRAME_PATIENCE` of a control period, leaving the loop time to decide and
        command within the period.
        """
        serve = (self._serves, self._served_at)
        given = (self._camera or self._frames).given
        # The first frame of a serve is seen at once, as an environment's reset shows it.
        due = (self._serves, self.time - self.camera_latency + 1e-9)
        upto = due if given is not None and given >= serve else (self._serves, math.inf)
        if self._camera is None:
            self._frames.add(((self._serves, self.time), self.frame()))
            (_, t), frame = self._frames.give(serve, upto) or (serve, None)
            return t, frame
        if self._camera_lost is not None:
            raise self._camera_lost
        # A frame from before the serve shows a ball that is no longer there.
        (_, t), frame = self._camera.latest(
            after=serve, upto=upto, patience=FRAME_PATIENCE * self.sim.control_dt
        )
        return t, frame

    def _keep_pace(self) -> None:
        now = time.monotonic()
        if self._paced_from is None:
            self._paced_from = now - self.time
        ahead = self._paced_from + self.time - now
        if ahead > 0:
            time.sleep(ahead)
        else:
            # Behind: the lost time is not made up by running fast afterwards.
            self._paced_from = now - self.time

    @property
    def serve_steps(self) -> int | None:
        """The most control steps a serve lasts: None for the task's own (its episode's
        limit), :data:`~foosball_gym.real_table.sysid.excitation.CALIBRATION_SERVE_S` of them for a
        calibration serve."""
        if self.serves == "calibration":
            return round(CALIBRATION_SERVE_S / self.sim.control_dt)
        return None

    def _draw_dynamics(self) -> None:
        """This serve's physical parameters, where the options randomise them (as an
        environment draws them at every reset)."""
        if not self._randomisation:
            return
        self.dynamics = self.sim.draw_dynamics(
            self._randomisation,
            self._dynamics_rng,
            self._base_gains,
            self.game.interface.action_joints,
        )

    def _serve_rng(self, serve: int) -> np.random.Generator:
        """The generator of the serve that follows ``serve`` served balls: seeded with
        ``seed + serve``, as an environment's episode is by ``reset(seed=seed + serve)``, so
        that the table serves the balls ``foosball eval --seed SEED`` serves, one for one (the
        rods stay where the last serve left them)."""
        return np.random.default_rng(self._seed + serve)

    def prepare_serve(self) -> dict[Joint, float]:
        """Draw the next task serve (its ball, its physics and where it starts the rods, as
        ``foosball eval --seed`` starts that episode) and give the places of the rods the
        drives move, which the loop brings them to before :meth:`serve`. Until then the table
        moves the other rods to theirs.

        Raises:
            ValueError: the table serves calibration balls, which start no episode.
        """
        if self.serves != "task":
            raise ValueError("only the task's serves start the rods where an episode does")
        with self._lock:
            self.rng = self._dynamics_rng = self._serve_rng(self._serves)
            self._draw_dynamics()
            self._pending = self.game.task.sample_start(self.rng)
            self._ready_pose = self.game.start_pose(self._pending)
            targets = self.game.start_targets(self._pending)
            driven = {drive.joint.key for drive in self.drives.drives.values()}
            self._free_ready = {j: v for j, v in targets.items() if j not in driven}
            return {j: v for j, v in targets.items() if j in driven}

    def rods_ready(self) -> bool:
        """Whether every rod is at rest where :meth:`prepare_serve` wants it: within
        :data:`READY_SLIDE_M` and :data:`READY_SPIN_RAD`, moving slower than
        :data:`READY_SPEED` (m/s or rad/s)."""
        with self._lock:
            positions, velocities = self.sim.joint_states()
            n = len(self.game.rods)  # slides first, then spins
            for i, target in enumerate(self._ready_pose):
                tolerance = READY_SLIDE_M if i < n else READY_SPIN_RAD
                if abs(positions[i] - target) > tolerance or abs(velocities[i]) > READY_SPEED:
                    return False
            return True

    def serve(self) -> None:
        """A new ball: the one :meth:`prepare_serve` drew, or else one as the task starts its
        episodes (or a calibration ball), the rods staying where they are."""
        with self._lock:
            if self._pending is not None:
                self.game.serve_start(self._pending)
                self._pending, self._free_ready, self._ready_pose = None, None, []
                self._served()
                return
            if self.serves == "task":
                self.rng = self._dynamics_rng = self._serve_rng(self._serves)
            self._draw_dynamics()
            if self.serves == "calibration":
                ball = calibration_serve(self.rng, self.game.task.layout.rods)
                self.game.put_ball(ball.position, ball.velocity, ball.rolling)
            else:
                self.game.serve(self.rng)
            self._served()

    def _served(self) -> None:
        with self._lock:
            # What the clock reported of the old ball since the last step is no news of this one.
            self._events.clear()
            self._stagnated = self._dead = False
            self._score = [0, 0]
            self._serves += 1
            self._served_at = self.time
            self._balls.append((self.time, self.game.ball))
            if self._camera is not None:
                # Queued: the loop waits for a picture of the new ball.
                self._camera.request((self._serves, self.time), *self.seen_scene(), queue=True)

    def step(self) -> tuple[int, bool]:
        """One control step: the drives take their targets, the opponent moves, physics runs.

        In real time, waits for the table's next step instead and reports what happened since
        the last call.

        Returns:
            ``(goal, out_of_table)``: goal +1 (home scored), -1 (away scored) or 0. A ball
            lying still too long ends the serve too: see :attr:`stagnated`.
        """
        if not self.realtime:
            goal, out, stagnated = self._tick()
            self._stagnated |= stagnated
            if self.pace:
                self._keep_pace()
            return goal, out
        if self._thread is None:
            self.start()
        with self._lock:
            self._waiting = True
            steps = self.steps
            if not self._ticked.wait_for(lambda: self.steps > steps, timeout=1.0):
                raise RuntimeError("the simulated table's clock stopped")
            events, self._events = self._events, []
        self._stagnated |= any(stagnated for _, _, stagnated in events)
        goal = next((g for g, _, _ in events if g), 0)
        return goal, any(out for _, out, _ in events)

    @property
    def stagnated(self) -> bool:
        """Whether the ball has lain still for the task's ``stagnation_steps`` since the last
        serve, as of the last :meth:`step`: the serve is over, as an episode ends there."""
        return self._stagnated

    # ------------------------------------------------------------------ the GUI

    @property
    def window_open(self) -> bool:
        """Whether the GUI window is there: opened with ``gui=True``, not closed since."""
        return self._viewer is not None and self._viewer.open

    def show_text(self, lines: list[str]) -> None:
        """Write ``lines`` in the GUI window, the first above the table and the others below
        it (nothing without the window)."""
        if self._viewer is not None:
            self._viewer.show_text(lines)

    def keyboard_events(self) -> tuple[frozenset[str], frozenset[str]]:
        """The keys held in the GUI window now and those pressed since the last call (see
        :meth:`TableSim.keyboard_events`); none without the window."""
        if self._viewer is None:
            return frozenset(), frozenset()
        return self._viewer.keyboard_events()

    @property
    def opponent(self) -> Any:
        """The away side's policy (``None`` in a task without one)."""
        return self.game.opponent

    def set_opponent(self, policy: Any) -> None:
        """Play the away side with ``policy``, a callable from the mirrored observation to
        an action (see :meth:`Game.set_opponent`); it is asked once a control step."""
        with self._lock:
            self.game.set_opponent(policy)

    @property
    def success(self) -> bool:
        """Whether the task is met by the goals since the last serve."""
        return self.game.task.success(*self._score)

    @property
    def goals_for(self) -> int:
        """Goals the home side scored since the last serve."""
        return self._score[0]

    @property
    def goals_against(self) -> int:
        """Goals the away side scored since the last serve."""
        return self._score[1]

    def ball(self, at: float | None = None) -> tuple[float, float, float, float]:
        """The true ball x, y, vx, vy now, or at the table time ``at`` of a recent step."""
        if at is None:
            return self.game.ball
        with self._lock:  # the real-time clock's thread appends meanwhile
            balls = list(self._balls)
        # Newest first: a serve leaves two entries at one time, and the new ball is the truth.
        return min(reversed(balls), key=lambda tb: abs(tb[0] - at))[1]

    def true_state(self) -> dict[str, Any]:
        """The rods and the ball as they are now, for a session log: ``ball`` (x, y, z) and
        ``joints`` (rod name -> [slide, spin]), in the joints' own frames."""
        with self._lock:
            positions, ball = self.sim.scene()
        n = len(self.sim.rods)
        joints = {
            rod.name: [float(positions[i]), float(positions[n + i])]
            for i, rod in enumerate(self.sim.rods)
        }
        return {"ball": [float(v) for v in ball], "joints": joints}

    def close(self) -> None:
        """Stop the clock, the camera and the drives; safe to call twice."""
        stop = getattr(self, "_stop", None)
        if stop is not None:
            stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2)
        if self._camera is not None:
            self._camera.close()
        if self._viewer is not None:
            self._viewer.close()
        if hasattr(self, "drives"):
            self.drives.close()
        self.sim.close()
