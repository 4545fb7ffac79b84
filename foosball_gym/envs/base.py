"""The Gymnasium environment every foosball task builds on.

A task says which rods the learner controls (and which of their joints), which rods an
opponent plays, which rods stand still as obstacles, how an episode starts and what counts as
success. This class does the rest: action scaling, driving the simulator, observations,
reward terms, info, the opponent, rendering and seeding.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from foosball_gym import table as T
from foosball_gym.envs.common import check_range
from foosball_gym.envs.estimated import CameraNoise, EstimatedState
from foosball_gym.envs.rewards import TERMS, RewardComputer, RewardWeights
from foosball_gym.interface.observations import (
    JOINT_SETS,
    ObservationBuilder,
    ObservationOptions,
    mirrored_builder,
)
from foosball_gym.interface.task import Layout, TaskInterface
from foosball_gym.physics_options import check_physics
from foosball_gym.policies.scripted import ScriptedTeam

Policy = Callable[[np.ndarray], Any]

RENDER_MODES = ("human", "rgb_array")
# A ball slower than this (m/s) counts as lying still for the stagnation rule.
STILL_SPEED = 0.05


@dataclass
class Start:
    """An episode's first state; joint lists follow ``Layout.rods``."""

    slide: list[float]
    spin: list[float]
    ball_position: tuple[float, float]
    ball_velocity: tuple[float, float]


def check_pair(name: str, value: Any) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"option {name!r} must be two numbers (x, y), got {value!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"option {name!r} must be finite, got {value!r}")
    return x, y


def check_ball_position(name: str, value: Any) -> tuple[float, float]:
    x, y = check_pair(name, value)
    if abs(x) > T.BALL_LIMIT_X or abs(y) > T.BALL_LIMIT_Y:
        raise ValueError(
            f"option {name!r} = ({x}, {y}) is off the field; the ball's centre must lie "
            f"within |x| <= {T.BALL_LIMIT_X:.5f}, |y| <= {T.BALL_LIMIT_Y:.5f} m"
        )
    return x, y


def _flag(name: str, value: object) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def clear_of_ball(rod: T.Rod, slide: float, ball: tuple[float, float]) -> float:
    """A slide value near ``slide`` at which no figurine of ``rod`` overlaps the ball.

    Tasks put the ball at rest close to a rod; starting with a figurine inside the ball would
    throw it across the table on the first step.
    """
    bx, by = ball
    reach_x = T.FIGURINE_SIZE[0] / 2 + T.BALL_RADIUS
    if abs(bx - rod.x) >= reach_x:
        return slide
    gap = T.FIGURINE_SIZE[1] / 2 + T.BALL_RADIUS + 0.002
    d = rod.direction
    for off in rod.figurine_offsets:
        fig_y = d * (slide + off)
        if abs(fig_y - by) < gap:
            # Move the figurine just beside the ball, on whichever side stays within the limits.
            for side in (np.sign(fig_y - by) or 1.0, -(np.sign(fig_y - by) or 1.0)):
                candidate = d * (by + side * gap) - off
                if abs(candidate) <= rod.slide_limit:
                    return clear_of_ball(rod, candidate, ball)
    return slide


class FoosballEnv(gym.Env[np.ndarray, np.ndarray]):
    """Base class of the foosball tasks; see the task classes for what each one is.

    Keyword arguments every task takes:

    Rewards (SPEC §3; every term is also in ``info["reward_<name>"]``):
        goal_reward: +weight for a goal scored, -weight for one conceded (1000).
        out_of_table_penalty: -weight when the ball leaves the table upwards (1000).
        ball_to_goal_weight: weight of the ball-to-opponent-goal potential (0: off).
        figurine_to_ball_weight: weight of the figurine-to-ball potential (0: off).
        action_regularisation_weight: weight of -mean((a_t - a_{t-1})^2) (0: off).
        shaping: ``"difference"`` (the authors' per-step difference of the potentials) or
            ``"potential"`` (gamma * phi(s') - phi(s), which keeps the optimal policy).
        gamma: discount of potential-based shaping (0.99).

    Observation:
        joint_velocities: include the rods' velocities (True).
        observe_figurines: figurine centres (x, y) instead of joint values (False).
        opponent_prismatic_only: observe only the opponent's prismatic joints, as the real
            table's camera does (tasks with an opponent only).

    Domain randomisation (each off by default; a (low, high) range turns it on, sampled
    uniformly at every reset):
        ball_friction_range: the ball's friction coefficient (spec: 0.1).
        ball_restitution_range: the restitution of every ball contact (spec: 0.5).
        ball_mass_range: the ball's mass in kg (spec: 0.022).
        drive_gain_range: a factor on the drives' position gains: how briskly they respond.
        rolling_resistance_range: how a rolling ball slows, in units of g (default 0.01).

    Robust training (off by default):
        estimated_state: observe the ball and the opponent's rods as the real table does:
            through a simulated camera and the real table's Kalman filter
            (:mod:`foosball_gym.envs.estimated`).
        camera_noise: the simulated camera's errors, keys of
            :class:`~foosball_gym.envs.estimated.CameraNoise` (fps, position_std, rod_std,
            drop_rate, hide_under_figurines, latency_s).

    Other:
        opponent: the away side's policy, a callable from the mirrored observation to an
            action (tasks with an opponent only; default: the scripted team).
        stagnation_steps: end the game as a draw when the ball has lain still for this many
            steps (0: never).
        render_mode: ``None``, ``"rgb_array"`` or ``"human"`` (the PyBullet GUI).
        render_width, render_height: size of ``"rgb_array"`` frames (320 x 180).
        physics_hz: physics rate away from contacts (240); near a contact the simulator
            steps finer (see ``contact_travel``). A whole multiple of ``control_hz``.
        control_hz: env steps per second (60).
        contact_travel: near a possible contact, physics steps are made fine enough that
            nothing moves more than this (m) relative to what it may touch within one (0.005).
        rolling_resistance: how a rolling ball slows, in units of g (0.01: a 1 m/s ball rolls
            about 5 m).
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": T.CONTROL_HZ}
    #: Keys ``reset(options=...)`` accepts; tasks may add their own.
    reset_options: tuple[str, ...] = ("ball_position", "ball_velocity")
    #: The task's own discrete options and the values each takes (first: the default).
    task_options: dict[str, tuple[Any, ...]] = {}

    @classmethod
    def task_interface(cls, **kwargs: Any) -> TaskInterface:
        """This task's observation builder and action mapping for ``kwargs``, without building a
        simulator: what the real table needs to run a policy trained on the task."""
        env = cls.__new__(cls)
        env._simulate = False
        cls.__init__(env, **kwargs)
        return env.interface

    @classmethod
    def option_grid(cls) -> dict[str, tuple[Any, ...]]:
        """Every discrete option of this task with its values: what the tests iterate over."""
        return {
            "joint_velocities": (True, False),
            "observe_figurines": (False, True),
            "estimated_state": (False, True),
            **cls.task_options,
        }

    def __init__(
        self,
        layout: Layout,
        *,
        extras: Sequence[str] = (),
        opponent: Policy | None = None,
        goal_reward: float = 1000.0,
        out_of_table_penalty: float = 1000.0,
        ball_to_goal_weight: float = 0.0,
        figurine_to_ball_weight: float = 0.0,
        action_regularisation_weight: float = 0.0,
        shaping: str = "difference",
        gamma: float = 0.99,
        joint_velocities: bool = True,
        observe_figurines: bool = False,
        opponent_prismatic_only: bool = False,
        stagnation_steps: int = 0,
        ball_friction_range: tuple[float, float] | None = None,
        ball_restitution_range: tuple[float, float] | None = None,
        ball_mass_range: tuple[float, float] | None = None,
        drive_gain_range: tuple[float, float] | None = None,
        rolling_resistance_range: tuple[float, float] | None = None,
        estimated_state: bool = False,
        camera_noise: dict[str, Any] | None = None,
        render_mode: str | None = None,
        render_width: int = 320,
        render_height: int = 180,
        physics_hz: int = T.PHYSICS_HZ,
        control_hz: int = T.CONTROL_HZ,
        contact_travel: float = T.CONTACT_TRAVEL,
        rolling_resistance: float = T.ROLLING_RESISTANCE,
    ) -> None:
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(
                f"unknown render_mode {render_mode!r}; allowed: None, "
                f"{', '.join(map(repr, RENDER_MODES))}"
            )
        if layout.joints not in JOINT_SETS:
            raise ValueError(
                f"unknown joint set {layout.joints!r}; allowed: {', '.join(JOINT_SETS)}"
            )
        physics_hz, control_hz, contact_travel, rolling_resistance = check_physics(
            physics_hz, control_hz, contact_travel, rolling_resistance
        )
        for name, value in (
            ("render_width", render_width),
            ("render_height", render_height),
        ):
            if not isinstance(value, (int, np.integer)) or value <= 0:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        if not isinstance(stagnation_steps, (int, np.integer)) or stagnation_steps < 0:
            raise ValueError(
                f"stagnation_steps must be a non-negative integer, got {stagnation_steps!r}"
            )
        if _flag("opponent_prismatic_only", opponent_prismatic_only) and not layout.opponent:
            raise ValueError(
                f"opponent_prismatic_only applies only to tasks with an opponent; "
                f"{type(self).__name__} has none"
            )
        if opponent is not None and not layout.opponent:
            raise ValueError(f"{type(self).__name__} has no opponent to set")
        self.layout = layout
        self.render_mode = render_mode
        self.render_width, self.render_height = int(render_width), int(render_height)
        self.metadata = {**self.metadata, "render_fps": control_hz}
        self.weights = RewardWeights(
            goal=goal_reward,
            out_of_table=out_of_table_penalty,
            ball_to_goal=ball_to_goal_weight,
            figurine_to_ball=figurine_to_ball_weight,
            action_regularisation=action_regularisation_weight,
            shaping=shaping,
            gamma=gamma,
        )
        self.observation_options = ObservationOptions(
            joint_velocities=_flag("joint_velocities", joint_velocities),
            opponent_prismatic_only=opponent_prismatic_only,
            observe_figurines=_flag("observe_figurines", observe_figurines),
        )
        self.stagnation_steps = int(stagnation_steps)
        self.randomisation = {
            name: check_range(name, value, low, high)
            for name, value, low, high in (
                ("ball_friction_range", ball_friction_range, 0.0, 10.0),
                ("ball_restitution_range", ball_restitution_range, 0.0, 1.0),
                ("ball_mass_range", ball_mass_range, 1e-4, 1.0),
                ("drive_gain_range", drive_gain_range, 1e-3, 10.0),
                ("rolling_resistance_range", rolling_resistance_range, 0.0, 0.5),
            )
            if value is not None
        }

        self.dt = 1.0 / control_hz
        self.sim = None
        if getattr(self, "_simulate", True):
            # Imported here: the real table builds a task's interface without the simulator.
            from foosball_gym.simulator import TableSim

            self.sim = TableSim(
                layout.rods,
                physics_hz=physics_hz,
                control_hz=control_hz,
                contact_travel=contact_travel,
                rolling_resistance=rolling_resistance,
                gui=render_mode == "human",
            )
            self._base_gains = (self.sim.slide_gain, self.sim.spin_gain)
        n = len(layout.rods)
        self._n = n
        self._rods = [T.rod(r) for r in layout.rods]
        n_own = len(layout.controlled)
        # Action k drives joint _act_joint[k] (an index into the simulator's slides-then-spins).
        self._act_joint, self._act_scale = self._action_map(0, n_own)
        self._n_act = len(self._act_joint)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(self._n_act,), dtype=np.float32)

        self.interface = TaskInterface.create(layout, extras, self.observation_options)
        self.obs_builder = self.interface.builder
        self._estimated: EstimatedState | None = None
        if _flag("estimated_state", estimated_state):
            self._estimated = EstimatedState(
                self.obs_builder, CameraNoise.from_dict(camera_noise), self.np_random
            )
        elif camera_noise is not None:
            raise ValueError("camera_noise needs estimated_state=True")
        self.observation_space = self.obs_builder.space
        self._rewards = RewardComputer(self.weights, self._rods[:n_own])

        self._opp_builder: ObservationBuilder | None = None
        self._opp_joint: list[int] = []
        self._opp_scale: list[float] = []
        self._opponent: Policy | None = None
        if layout.opponent:
            self._opp_builder = mirrored_builder(self.obs_builder)
            self._opp_joint, self._opp_scale = self._action_map(n_own, len(layout.opponent))
            self.set_opponent(opponent)

        self._targets = [0.0] * (2 * n)
        self._pos: list[float] = [0.0] * (2 * n)
        self._vel: list[float] = [0.0] * (2 * n)
        self._ball = (0.0, 0.0, 0.0, 0.0)
        self._goals_for = 0
        self._goals_against = 0
        self._still_steps = 0
        self._last_render = 0.0
        self._started = False
        self._closed = False

    def _action_map(self, first: int, count: int) -> tuple[list[int], list[float]]:
        joints, scales = [], []
        for i in range(first, first + count):
            joints.append(i)
            scales.append(self._rods[i].slide_limit)
            if self.layout.joints == "both":
                joints.append(self._n + i)
                scales.append(T.SPIN_LIMIT)
        return joints, scales

    # ------------------------------------------------------------------ task hooks

    def _sample_start(
        self,
        ball_position: tuple[float, float] | None,
        ball_velocity: tuple[float, float] | None,
        options: dict[str, Any],
    ) -> Start:
        raise NotImplementedError

    def success(self, goals_for: int, goals_against: int) -> bool:
        """Whether the task is met with this score so far."""
        raise NotImplementedError

    def _is_success(self) -> bool:
        return self.success(self._goals_for, self._goals_against)

    def _continues_after_goal(self) -> bool:
        """True where a goal (or a dead ball) re-serves instead of ending the episode."""
        return False

    # ------------------------------------------------------------------ policies

    def scripted_policy(self) -> ScriptedTeam:
        """The scripted baseline for the learner's side of this task."""
        return ScriptedTeam(self.obs_builder.names, self.layout.controlled, self.layout.joints)

    @property
    def opponent(self) -> Policy | None:
        return self._opponent

    def set_opponent(self, policy: Policy | None) -> None:
        """Set the policy that plays the away side: a callable from the mirrored observation
        (the game as the away side sees it from its own goal) to an action in [-1, 1].
        ``None`` restores the scripted default."""
        if not self.layout.opponent:
            raise ValueError(f"{type(self).__name__} has no opponent to set")
        if policy is not None and not callable(policy):
            raise ValueError(f"an opponent must be a callable obs -> action, got {policy!r}")
        if policy is None:
            assert self._opp_builder is not None
            policy = ScriptedTeam(
                self._opp_builder.names, self._opp_builder.own, self.layout.joints
            )
        self._opponent = policy

    def opponent_targets(self) -> dict[tuple[str, str], float]:
        """The away rods' joint targets (m, rad) the opponent chooses in the current state."""
        if self._opponent is None:
            raise ValueError(f"{type(self).__name__} has no opponent")
        action = self._check_action(
            self._opponent(self.opponent_observation()), len(self._opp_joint), "opponent action"
        )
        return {
            self._joint_name(j): a * scale
            for j, scale, a in zip(self._opp_joint, self._opp_scale, action)
        }

    def _joint_name(self, index: int) -> tuple[str, str]:
        """(rod, joint) of an index into the simulator's slides-then-spins."""
        if index < self._n:
            return self.layout.rods[index], "slide"
        return self.layout.rods[index - self._n], "spin"

    def opponent_observation(self) -> np.ndarray:
        """What the opponent sees now: the mirrored observation."""
        if self._opp_builder is None:
            raise ValueError(f"{type(self).__name__} has no opponent")
        return self._opp_builder.build(self._pos, self._vel, self._ball)

    # ------------------------------------------------------------------ gym API

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        if self._closed:
            raise gym.error.ClosedEnvironmentError("the environment is closed; make a new one")
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - set(self.reset_options)
        if unknown:
            raise ValueError(
                f"unknown reset option(s) {sorted(unknown)}; allowed: "
                f"{', '.join(self.reset_options)}"
            )
        ball_position = options.get("ball_position")
        ball_velocity = options.get("ball_velocity")
        if ball_position is not None:
            ball_position = check_ball_position("ball_position", ball_position)
        if ball_velocity is not None:
            ball_velocity = check_pair("ball_velocity", ball_velocity)
        self._goals_for = self._goals_against = 0
        dynamics = self._randomise_dynamics()
        if self._estimated is not None:
            self._estimated.rng = self.np_random
        self._serve(self._sample_start(ball_position, ball_velocity, options))
        self._started = True
        obs = self._observe()
        info = {"goal": 0, "is_success": self._is_success(), **self._score_info()}
        if dynamics:
            info["dynamics"] = dynamics
        if self.render_mode == "human":
            self.render()
        return obs, info

    def serve(self) -> None:
        """Put a new ball in play the way this task starts an episode, leaving the rods where
        they are: a serve in a running game (the simulated real table uses it). The score and
        the shaping potentials start afresh."""
        for _ in range(20):
            start = self._sample_start(None, None, {})
            if all(
                clear_of_ball(rod, s, start.ball_position) == s
                for rod, s in zip(self._rods, self._pos[: self._n])
            ):
                break
        self.sim.place_ball(start.ball_position, start.ball_velocity)
        self._goals_for = self._goals_against = 0
        self.refresh()
        self._still_steps = 0
        self._rewards.reset(self._controlled_slides(), self._ball[0], self._ball[1], self._n_act)

    def refresh(self) -> None:
        """Re-read the simulator's state, after something other than :meth:`step` moved it."""
        self._read_state()

    def _randomise_dynamics(self) -> dict[str, float]:
        """Draw this episode's physical parameters where randomisation is on."""
        if not self.randomisation:
            return {}
        drawn = {
            name[: -len("_range")]: float(self.np_random.uniform(*bounds))
            for name, bounds in self.randomisation.items()
        }
        self.sim.set_ball_dynamics(
            friction=drawn.get("ball_friction"),
            restitution=drawn.get("ball_restitution"),
            mass=drawn.get("ball_mass"),
            rolling_resistance=drawn.get("rolling_resistance"),
        )
        if "drive_gain" in drawn:
            slide, spin = self._base_gains
            self.sim.set_drive_gains(slide * drawn["drive_gain"], spin * drawn["drive_gain"])
        return drawn

    def _serve(self, start: Start) -> None:
        slide = [
            clear_of_ball(rod, s, start.ball_position) for rod, s in zip(self._rods, start.slide)
        ]
        self.sim.reset(slide, start.spin, start.ball_position, start.ball_velocity)
        for i, value in enumerate((*slide, *start.spin)):
            self._targets[i] = float(value)
        self._read_state()
        self._still_steps = 0
        self._rewards.reset(self._controlled_slides(), self._ball[0], self._ball[1], self._n_act)
        if self._estimated is not None:
            self._estimated.reset(self._ball, self._pos, self.sim.figurine_positions())

    def _observe(self) -> np.ndarray:
        if self._estimated is not None:
            return self._estimated.observation(self._pos, self._vel)
        return self.obs_builder.build(self._pos, self._vel, self._ball)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._closed:
            raise gym.error.ClosedEnvironmentError("the environment is closed; make a new one")
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before step()")
        act = self._check_action(action, self._n_act, "action")
        targets = self._targets
        for k, a in enumerate(act):
            targets[self._act_joint[k]] = a * self._act_scale[k]
        if self._opponent is not None:
            opp = self._check_action(
                self._opponent(self.opponent_observation()), len(self._opp_joint), "opponent action"
            )
            for k, a in enumerate(opp):
                targets[self._opp_joint[k]] = a * self._opp_scale[k]
        self.sim.command("position", targets)
        goal, out = self.sim.step()
        self._read_state()
        if self._estimated is not None:
            self._estimated.advance(self.dt, self._ball, self._pos, self.sim.figurine_positions())
        if goal == T.HOME_SCORED:
            self._goals_for += 1
        elif goal == T.AWAY_SCORED:
            self._goals_against += 1
        stagnated = self._stagnated()
        ended = out or goal != 0 or stagnated
        continuous = ended and self._continues_after_goal()
        terms = self._rewards.step(
            goal,
            out,
            self._controlled_slides(),
            self._ball[0],
            self._ball[1],
            act,
            ended and not continuous,
        )
        info = {
            "goal": goal,
            "is_success": self._is_success(),
            "out_of_table": out,
            "stagnated": stagnated,
            **self._score_info(),
        }
        for name in TERMS:
            info["reward_" + name] = terms[name]
        if continuous:
            self._serve(self._sample_start(None, None, {}))
        obs = self._observe()
        if self.render_mode == "human":
            self.render()
        return obs, float(sum(terms.values())), ended and not continuous, False, info

    def _stagnated(self) -> bool:
        if not self.stagnation_steps:
            return False
        _, _, vx, vy = self._ball
        self._still_steps = self._still_steps + 1 if vx * vx + vy * vy < STILL_SPEED**2 else 0
        return self._still_steps >= self.stagnation_steps

    def render(self) -> np.ndarray | None:
        if self.render_mode == "rgb_array":
            return self.sim.render(self.render_width, self.render_height)
        if self.render_mode == "human":
            # Keep the GUI at real time: one control step per dt of wall clock.
            wait = self._last_render + self.dt - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            self._last_render = time.perf_counter()
        return None

    def close(self) -> None:
        self._closed = True
        sim = getattr(self, "sim", None)
        if sim is not None:
            sim.close()

    # ------------------------------------------------------------------ helpers

    @staticmethod
    def _check_action(action: Any, n: int, what: str) -> list[float]:
        try:
            values = action.tolist() if isinstance(action, np.ndarray) else action
            flat = np.ravel(values) if not isinstance(values, float) else np.array([values])
            # float() would take "0.5" and drop an imaginary part: only real numbers are actions.
            if flat.dtype.kind not in "biuf":
                raise TypeError
            values = [float(v) for v in flat]
        except (TypeError, ValueError):
            raise ValueError(f"{what} must be {n} number(s) in [-1, 1], got {action!r}") from None
        if len(values) != n:
            raise ValueError(
                f"{what} must have {n} value(s) in [-1, 1], got {len(values)}: {action!r}"
            )
        out = []
        for v in values:
            if v != v or v in (math.inf, -math.inf):
                raise ValueError(f"{what} must be finite, got {values}")
            out.append(-1.0 if v < -1.0 else 1.0 if v > 1.0 else v)
        return out

    def _read_state(self) -> None:
        self._pos, self._vel = self.sim.joint_states()
        self._ball = self.sim.ball_xy()

    def _controlled_slides(self) -> list[float]:
        return self._pos[: len(self.layout.controlled)]

    def _score_info(self) -> dict[str, Any]:
        if not self.layout.opponent:
            return {}
        return {"goals_for": self._goals_for, "goals_against": self._goals_against}

    def rod_joint_values(self) -> tuple[list[float], list[float]]:
        """Joint positions and velocities of the rods in play (all slides, then all spins, in
        ``layout.rods`` order), as of the last reset or step."""
        return list(self._pos), list(self._vel)
