"""The Gymnasium face of a foosball game.

A task (:mod:`foosball_gym.tasks`) says which rods are in play, how an episode starts and
what counts as success; the game (:mod:`foosball_gym.game`) plays it on the simulated table
with its opponent. This class adds the rest of what a Gymnasium user expects: checked
actions, observations, reward terms, info, rendering, seeding and domain randomisation.
"""

from __future__ import annotations

import inspect
import math
import time
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from foosball_gym import table as T
from foosball_gym.envs.estimated import CameraNoise, EstimatedState
from foosball_gym.envs.rewards import TERMS, RewardComputer, RewardWeights
from foosball_gym.game import Game, Policy
from foosball_gym.policy_io.observations import JOINT_SETS, check_flag
from foosball_gym.policy_io.task import TaskInterface, check_action, residual_action
from foosball_gym.physics_options import check_physics
from foosball_gym.policies.scripted import ScriptedTeam
from foosball_gym.tasks.base import Task, check_ball_position, check_pair, split_options
from foosball_gym.tasks.registry import interface_of
from foosball_gym.tasks.serves import check_range

RENDER_MODES = ("human", "rgb_array")


RESIDUAL_LIMIT = 2.0


def check_residual(value: Any) -> float:
    """The residual scale: 0 (off) up to RESIDUAL_LIMIT, or a ValueError saying so."""
    try:
        scale = float(value)
    except (TypeError, ValueError):
        scale = math.nan
    if isinstance(value, bool) or not 0.0 <= scale <= RESIDUAL_LIMIT:
        raise ValueError(
            f"residual must be a number in [0, {RESIDUAL_LIMIT}] (0: off), got {value!r}"
        )
    return scale


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
            :class:`~foosball_gym.camera.CameraNoise` (fps, position_std, rod_std,
            drop_rate, hide_under_figurines, latency_s).

    Residual learning (off by default):
        residual: where above 0, the action is a correction to the task's scripted baseline:
            the rods are sent ``clip(scripted(obs) + residual * action, -1, 1)``, ``obs`` being
            the observation the action answers. An untrained policy (actions near 0) plays
            like the baseline; learning improves on it instead of re-learning it. At most 2.

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
    #: The task this environment plays; its options are keyword arguments of the env too.
    task_class: ClassVar[type[Task]]

    @classmethod
    def option_grid(cls) -> dict[str, tuple[Any, ...]]:
        """Every discrete option of this task with its values: what the tests iterate over."""
        return {
            "joint_velocities": (True, False),
            "observe_figurines": (False, True),
            "estimated_state": (False, True),
            **cls.task_class.options,
        }

    @classmethod
    def option_defaults(cls) -> dict[str, Any]:
        """Every keyword argument this environment takes, with its default."""
        task = inspect.signature(cls.task_class.__init__).parameters
        env = inspect.signature(cls._setup).parameters
        defaults = {
            name: p.default
            for params in (task, env)
            for name, p in params.items()
            if p.default is not inspect.Parameter.empty
        }
        return {**defaults, **cls.task_class.env_defaults}

    def __init__(self, **kwargs: Any) -> None:
        allowed = self.option_defaults()
        unknown = sorted(set(kwargs) - set(allowed))
        if unknown:
            raise TypeError(
                f"{type(self).__name__} has no option {', '.join(map(repr, unknown))}; "
                f"allowed: {', '.join(sorted(allowed))}"
            )
        task_kwargs, env_kwargs = split_options(self.task_class, kwargs)
        self._closed = False
        self._setup(self.task_class(**task_kwargs), **env_kwargs)

    def _setup(
        self,
        task: Task,
        *,
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
        residual: float = 0.0,
        render_mode: str | None = None,
        render_width: int = 320,
        render_height: int = 180,
        physics_hz: int = T.PHYSICS_HZ,
        control_hz: int = T.CONTROL_HZ,
        contact_travel: float = T.CONTACT_TRAVEL,
        rolling_resistance: float = T.ROLLING_RESISTANCE,
    ) -> None:
        layout = task.layout
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
        if opponent is not None and not layout.opponent:
            raise ValueError(f"{type(self).__name__} has no opponent to set")
        self.task = task
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
        self.interface: TaskInterface = interface_of(
            task,
            {
                "joint_velocities": joint_velocities,
                "observe_figurines": observe_figurines,
                "opponent_prismatic_only": opponent_prismatic_only,
            },
        )
        self.observation_options = self.interface.builder.options
        self.obs_builder = self.interface.builder
        self.observation_space = self.obs_builder.space
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
        self._estimated: EstimatedState | None = None
        if check_flag("estimated_state", estimated_state):
            self._estimated = EstimatedState(
                self.obs_builder, CameraNoise.from_dict(camera_noise), self.np_random
            )
        elif camera_noise is not None:
            raise ValueError("camera_noise needs estimated_state=True")
        self._n_act = self.interface.n_actions
        self.action_space = spaces.Box(-1.0, 1.0, shape=(self._n_act,), dtype=np.float32)
        self.residual = check_residual(residual)
        # Residual RL: the action corrects the scripted baseline, which sees what the agent saw.
        self._baseline = self.scripted_policy() if self.residual else None
        self._last_obs: np.ndarray | None = None
        self._rewards = RewardComputer(self.weights, [T.rod(r) for r in layout.controlled])
        self.dt = 1.0 / control_hz

        # Imported here: building a task's interface needs no simulator.
        from foosball_gym.sim import TableSim

        self.sim = TableSim(
            layout.rods,
            physics_hz=physics_hz,
            control_hz=control_hz,
            contact_travel=contact_travel,
            rolling_resistance=rolling_resistance,
            gui=render_mode == "human",
        )
        self._base_gains = (self.sim.slide_gain, self.sim.spin_gain)
        self.game = Game(
            task, self.interface, self.sim, opponent=opponent, stagnation_steps=stagnation_steps
        )
        self._last_render = 0.0
        self._started = False

    # ------------------------------------------------------------------ policies

    def scripted_policy(self) -> ScriptedTeam:
        """The scripted baseline for the learner's side of this task."""
        return self.task.scripted_policy(self.obs_builder.names, self._estimated is None)

    def success(self, goals_for: int, goals_against: int) -> bool:
        """Whether the task is met with this score so far."""
        return self.task.success(goals_for, goals_against)

    @property
    def opponent(self) -> Policy | None:
        return self.game.opponent

    def set_opponent(self, policy: Policy | None) -> None:
        """Set the policy that plays the away side: a callable from the mirrored observation
        (the game as the away side sees it from its own goal) to an action in [-1, 1].
        ``None`` restores the scripted default."""
        if not self.layout.opponent:
            raise ValueError(f"{type(self).__name__} has no opponent to set")
        self.game.set_opponent(policy)

    def scripted_opponent(self) -> ScriptedTeam:
        """A scripted team for the away side (the default opponent), acting on the mirrored
        observation."""
        if not self.layout.opponent:
            raise ValueError(f"{type(self).__name__} has no opponent")
        return self.game.scripted_opponent()

    def opponent_observation(self) -> np.ndarray:
        """What the opponent sees now: the mirrored observation."""
        if not self.layout.opponent:
            raise ValueError(f"{type(self).__name__} has no opponent")
        return self.game.opponent_observation()

    # ------------------------------------------------------------------ gym API

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        if self._closed:
            raise gym.error.ClosedEnvironmentError("the environment is closed; make a new one")
        super().reset(seed=seed)
        options = dict(options or {})
        allowed = self.task.reset_options
        unknown = set(options) - set(allowed)
        if unknown:
            raise ValueError(
                f"unknown reset option(s) {sorted(unknown)}; allowed: {', '.join(allowed)}"
            )
        ball_position = options.pop("ball_position", None)
        ball_velocity = options.pop("ball_velocity", None)
        if ball_position is not None:
            ball_position = check_ball_position("ball_position", ball_position)
        if ball_velocity is not None:
            ball_velocity = check_pair("ball_velocity", ball_velocity)
        dynamics = self._randomise_dynamics()
        if self._estimated is not None:
            self._estimated.rng = self.np_random
        self._start(self.task.sample_start(self.np_random, ball_position, ball_velocity, options))
        self._started = True
        obs = self._last_obs = self._observe()
        info = {"goal": 0, "is_success": self.game.success, **self._score_info()}
        if dynamics:
            info["dynamics"] = dynamics
        if self.render_mode == "human":
            self.render()
        return obs, info

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

    def _start(self, start) -> None:
        game = self.game
        game.start(start)
        self._rewards.reset(self._controlled_slides(), game.ball[0], game.ball[1], self._n_act)
        if self._estimated is not None:
            self._estimated.reset(game.ball, game.positions, self.sim.figurine_positions())

    def _observe(self) -> np.ndarray:
        game = self.game
        if self._estimated is not None:
            return self._estimated.observation(game.positions, game.velocities)
        return self.obs_builder.build(game.positions, game.velocities, game.ball)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._closed:
            raise gym.error.ClosedEnvironmentError("the environment is closed; make a new one")
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before step()")
        act = check_action(action, self._n_act, "action")
        if self._baseline is not None:
            base = self._baseline(self._last_obs)
            act = [float(a) for a in residual_action(base, self.residual, act)]
        game = self.game
        game.command(act)
        outcome = game.advance()
        if self._estimated is not None:
            self._estimated.advance(
                self.dt, game.ball, game.positions, self.sim.figurine_positions()
            )
        continuous = outcome.ended and self.task.continues_after_goal
        terms = self._rewards.step(
            outcome.goal,
            outcome.out_of_table,
            self._controlled_slides(),
            game.ball[0],
            game.ball[1],
            act,
            outcome.ended and not continuous,
        )
        info = {
            "goal": outcome.goal,
            "is_success": game.success,
            "out_of_table": outcome.out_of_table,
            "stagnated": outcome.stagnated,
            **self._score_info(),
        }
        for name in TERMS:
            info["reward_" + name] = terms[name]
        if continuous:
            goals = game.goals_for, game.goals_against
            self._start(self.task.sample_start(self.np_random))
            game.goals_for, game.goals_against = goals
        obs = self._last_obs = self._observe()
        if self.render_mode == "human":
            self.render()
        return obs, float(sum(terms.values())), outcome.ended and not continuous, False, info

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

    def _controlled_slides(self) -> list[float]:
        return self.game.positions[: len(self.layout.controlled)]

    def _score_info(self) -> dict[str, Any]:
        if not self.layout.opponent:
            return {}
        return {"goals_for": self.game.goals_for, "goals_against": self.game.goals_against}

    def rod_joint_values(self) -> tuple[list[float], list[float]]:
        """Joint positions and velocities of the rods in play (all slides, then all spins, in
        ``layout.rods`` order), as of the last reset or step."""
        return list(self.game.positions), list(self.game.velocities)
