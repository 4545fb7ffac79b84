"""The Gymnasium environment every foosball task builds on.

A task says which rods the learner controls (and which of their joints), which rods an
opponent plays, which rods stand still as obstacles, how an episode starts and what counts as
success. This class does the rest: action scaling, driving the simulator, observations,
reward terms, info, rendering and seeding.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from foosball_gym import table as T
from foosball_gym.envs.observations import (
    JOINT_SETS,
    ObservationBuilder,
    ObservationOptions,
    mirrored_builder,
)
from foosball_gym.envs.rewards import TERMS, RewardComputer, RewardWeights
from foosball_gym.simulator import AWAY_SCORED, HOME_SCORED, TableSim

Policy = Callable[[np.ndarray], Any]

RENDER_MODES = ("human", "rgb_array")
_BALL_LIMIT_X = T.FIELD_HALF_LENGTH - T.BALL_RADIUS
_BALL_LIMIT_Y = T.FIELD_HALF_WIDTH - T.BALL_RADIUS


@dataclass(frozen=True)
class Layout:
    """Which rods a task puts in play and who moves them.

    Attributes:
        controlled: home rods the learner drives, keeper first.
        joints: ``"slide"`` (prismatic only) or ``"both"``: the learner's action joints.
        opponent: away rods an opponent policy drives (the mirror of ``controlled``).
        static: rods held still at the start position (obstacles).
    """

    controlled: tuple[str, ...]
    joints: str
    opponent: tuple[str, ...] = ()
    static: tuple[str, ...] = ()

    @property
    def rods(self) -> tuple[str, ...]:
        return self.controlled + self.opponent + self.static


@dataclass
class Start:
    """An episode's first state; joint arrays follow ``Layout.rods``."""

    slide: list[float]
    spin: list[float]
    ball_position: tuple[float, float]
    ball_velocity: tuple[float, float]
    extra: dict[str, Any] = field(default_factory=dict)


def _pair(name: str, value: Any) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"option {name!r} must be two numbers (x, y), got {value!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"option {name!r} must be finite, got {value!r}")
    return x, y


def check_ball_position(name: str, value: Any) -> tuple[float, float]:
    x, y = _pair(name, value)
    if abs(x) > _BALL_LIMIT_X or abs(y) > _BALL_LIMIT_Y:
        raise ValueError(
            f"option {name!r} = ({x}, {y}) is off the field; the ball's centre "
            f"must lie within |x| <= {_BALL_LIMIT_X:.5f}, |y| <= {_BALL_LIMIT_Y:.5f} m"
        )
    return x, y


class FoosballEnv(gym.Env[np.ndarray, np.ndarray]):
    """Base class of the foosball tasks; see the task classes for what each one is."""

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": T.CONTROL_HZ}
    #: Keys ``reset(options=...)`` accepts; tasks may add their own.
    reset_options: tuple[str, ...] = ("ball_position", "ball_velocity")

    def __init__(
        self,
        layout: Layout,
        *,
        weights: RewardWeights,
        observation: ObservationOptions,
        extras: Sequence[str] = (),
        opponent: Policy | None = None,
        render_mode: str | None = None,
        render_width: int = 320,
        render_height: int = 180,
        physics_hz: int = T.PHYSICS_HZ,
        substeps: int = T.PHYSICS_HZ // T.CONTROL_HZ,
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
        for name, value in (
            ("render_width", render_width),
            ("render_height", render_height),
            ("physics_hz", physics_hz),
            ("substeps", substeps),
        ):
            if not isinstance(value, (int, np.integer)) or value <= 0:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        self.layout = layout
        self.render_mode = render_mode
        self.render_width, self.render_height = int(render_width), int(render_height)
        self.metadata = {**self.metadata, "render_fps": physics_hz / substeps}
        self.weights = weights
        self.observation_options = observation

        self.sim = TableSim(
            layout.rods, physics_hz=physics_hz, substeps=substeps, gui=render_mode == "human"
        )
        self.dt = self.sim.control_dt
        n = len(layout.rods)
        self._n = n
        rods = [T.rod(r) for r in layout.rods]
        # Action k drives joint _act_joint[k] (index into the simulator's slides-then-spins).
        self._act_joint: list[int] = []
        self._act_scale: list[float] = []
        for i, rod in enumerate(rods[: len(layout.controlled)]):
            self._act_joint.append(i)
            self._act_scale.append(rod.slide_limit)
            if layout.joints == "both":
                self._act_joint.append(n + i)
                self._act_scale.append(T.SPIN_LIMIT)
        self._n_act = len(self._act_joint)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(self._n_act,), dtype=np.float32)

        self.obs_builder = ObservationBuilder(
            layout.rods, layout.controlled, layout.joints, layout.opponent, extras, observation
        )
        self.observation_space = self.obs_builder.space
        self._rewards = RewardComputer(weights, rods[: len(layout.controlled)])

        self._opp_builder: ObservationBuilder | None = None
        self._opp_joint: list[int] = []
        self._opp_scale: list[float] = []
        if layout.opponent:
            self._opp_builder = mirrored_builder(self.obs_builder)
            first = len(layout.controlled)
            for i, rod in enumerate(rods[first : first + len(layout.opponent)], start=first):
                self._opp_joint.append(i)
                self._opp_scale.append(rod.slide_limit)
                if layout.joints == "both":
                    self._opp_joint.append(n + i)
                    self._opp_scale.append(T.SPIN_LIMIT)
        self._opponent: Policy | None = None
        if opponent is not None:
            self.set_opponent(opponent)

        self._targets = [0.0] * (2 * n)
        self._pos: list[float] = [0.0] * (2 * n)
        self._vel: list[float] = [0.0] * (2 * n)
        self._ball = (0.0, 0.0, 0.0, 0.0)
        self._goals_for = 0
        self._goals_against = 0
        self._last_render = 0.0
        self._started = False

    # ------------------------------------------------------------------ task hooks

    def _sample_start(
        self,
        ball_position: tuple[float, float] | None,
        ball_velocity: tuple[float, float] | None,
        options: dict[str, Any],
    ) -> Start:
        raise NotImplementedError

    def _is_success(self) -> bool:
        raise NotImplementedError

    def _after_goal(self, goal: int) -> bool:
        """Called on a goal; returns True when the episode ends there."""
        return True

    # ------------------------------------------------------------------ opponent

    @property
    def opponent(self) -> Policy | None:
        return self._opponent

    def set_opponent(self, policy: Policy | None) -> None:
        """Set the policy that plays the away side: a callable from the mirrored observation
        (the game as the away side sees it from its own goal) to an action in [-1, 1]."""
        if not self.layout.opponent:
            raise ValueError(f"{type(self).__name__} has no opponent to set")
        if policy is not None and not callable(policy):
            raise ValueError(f"an opponent must be a callable obs -> action, got {policy!r}")
        self._opponent = policy if policy is not None else self._default_opponent()

    def _default_opponent(self) -> Policy:
        raise NotImplementedError

    def opponent_observation(self) -> np.ndarray:
        """What the opponent sees now (the mirrored observation)."""
        if self._opp_builder is None:
            raise ValueError(f"{type(self).__name__} has no opponent")
        return self._opp_builder.build(self._pos, self._vel, self._ball)

    # ------------------------------------------------------------------ gym API

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
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
            ball_velocity = _pair("ball_velocity", ball_velocity)
        start = self._sample_start(ball_position, ball_velocity, options)
        self.sim.reset(start.slide, start.spin, start.ball_position, start.ball_velocity)
        for i, value in enumerate((*start.slide, *start.spin)):
            self._targets[i] = float(value)
        self._read_state()
        self._goals_for = self._goals_against = 0
        self._started = True
        self._rewards.reset(self._controlled_slides(), self._ball[0], self._ball[1], self._n_act)
        obs = self.obs_builder.build(self._pos, self._vel, self._ball)
        info = {"goal": 0, "is_success": self._is_success(), **self._score_info()}
        if self.render_mode == "human":
            self.render()
        return obs, info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
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
        if goal == HOME_SCORED:
            self._goals_for += 1
        elif goal == AWAY_SCORED:
            self._goals_against += 1
        terminated = out or (goal != 0 and self._after_goal(goal))
        terms = self._rewards.step(
            goal, out, self._controlled_slides(), self._ball[0], self._ball[1], act, terminated
        )
        reward = sum(terms.values())
        obs = self.obs_builder.build(self._pos, self._vel, self._ball)
        info = {
            "goal": goal,
            "is_success": self._is_success(),
            "out_of_table": out,
            **self._score_info(),
        }
        for name in TERMS:
            info["reward_" + name] = terms[name]
        if self.render_mode == "human":
            self.render()
        return obs, float(reward), bool(terminated), False, info

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
        sim = getattr(self, "sim", None)
        if sim is not None:
            sim.close()

    # ------------------------------------------------------------------ helpers

    @staticmethod
    def _check_action(action: Any, n: int, what: str) -> list[float]:
        try:
            values = action.tolist() if isinstance(action, np.ndarray) else action
            values = (
                [float(v) for v in np.ravel(values)] if not isinstance(values, float) else [values]
            )
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
        return {}

    def rod_joint_values(self) -> tuple[list[float], list[float]]:
        """Current joint positions and velocities of the rods in play (slides, then spins)."""
        return list(self._pos), list(self._vel)
