"""The Gymnasium face of a foosball game.

A task (:mod:`foosball_gym.tasks`) says which rods are in play, how an episode starts and
what counts as success; the game (:mod:`foosball_gym.game`) plays it on the simulated table
with its opponent. This class adds the rest of what a Gymnasium user expects: checked
actions, observations, reward terms, info, rendering, seeding and domain randomisation.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Iterable, Mapping
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from typing_extensions import Unpack

from foosball_gym import table
from foosball_gym.envs import options as env_options
from foosball_gym.envs.estimated import EstimatedState
from foosball_gym.envs.options import (
    DEFAULTS,
    RENDER_MODES,
    CheckedOptions,
    GameOptions,
    SharedOptions,
    check_shared,
)
from foosball_gym.envs.rewards import TERMS, RewardComputer, rod_joints
from foosball_gym.envs.safety_layer import SafetyLayer
from foosball_gym.game import Game, Outcome, Policy, portable, unpacked
from foosball_gym.policy_io.task import TaskInterface, check_action, residual_action
from foosball_gym.tasks.base import Task, check_ball_position, check_ball_velocity

__all__ = ["RENDER_MODES", "FoosballEnv"]

# Each reward term's info key, built once: infos are made at every step.
_TERM_KEYS = tuple((f"reward_{name}", name) for name in TERMS)

# What a reset reports: no goal, no dead ball and no reward yet.
_NOTHING_YET = Outcome(goal=0, out_of_table=False, stagnated=False)


class FoosballEnv(gym.Env[np.ndarray, np.ndarray]):
    """The base of the foosball environments: what every one of them takes and does.

    Each environment's class (:class:`~foosball_gym.envs.block.BlockEnv`,
    :class:`~foosball_gym.envs.score.ScoreEnv`,
    :class:`~foosball_gym.envs.keeper_vs_keeper.KeeperVsKeeperEnv`,
    :class:`~foosball_gym.envs.full_game.FullGameEnv`) writes out its task's own options in its
    signature and takes the options every environment shares as ``**shared:
    Unpack[EnvOptions]``, declared once with their types in
    :class:`~foosball_gym.envs.options.EnvOptions` (:class:`~foosball_gym.envs.options.GameOptions`
    with an opponent), their defaults those of :class:`~foosball_gym.envs.options.SharedOptions`
    but where the class's ``defaults`` say otherwise. ``inspect.signature(EnvClass)`` lists them
    all, with their types and defaults. The shared options are described here, the task's on
    each class.

    ## Arguments
    Rewards (every term is also in `info["reward_<name>"]`; the reward is their sum):

    - `goal_reward`: the weight of a goal: `+goal_reward` for one scored, `-goal_reward` for
      one conceded.
    - `out_of_table_penalty`: `-out_of_table_penalty` when the ball leaves the table
      (upwards, or through a wall).
    - `ball_to_goal_weight`: the weight of the potential of the ball's distance to the
      opponent's goal (0: off).
    - `figurine_to_ball_weight`: the weight of the potential of the controlled figurines'
      distance to the ball (0: off).
    - `ball_aim_weight`: the weight of the potential of the ball's aim (not one of the paper's
      terms): 1 while the ball heads for the opponent's goal mouth along its straight path, the
      side walls' bounces included, falling by e for each 5 cm the path passes beside it, and
      0 while the ball is not moving towards that goal at 0.5 m/s or more (0: off).
    - `ball_lane_weight`: the weight of the potential of the ball's lane (not one of the
      paper's terms): the ball's aim, but 0 while its path meets a figurine of a rod the
      learner does not drive (one spun up, soles above the ball, stands in no lane) (0: off).
    - `ball_threat_weight`: the weight of the potential of the ball's threat (not one of the
      paper's terms): minus the ball's aim at the learner's own goal mouth, so that a shot
      turned away from it gains the weight and one turned towards it loses it (0: off).
    - `action_regularisation_weight`: the weight of `-mean((a_t - a_{t-1})^2)`, which
      penalises jerky actions (0: off).
    - `shaping`: how the potentials are rewarded. `"difference"` is the authors' per-step
      difference `w * (phi(s') - phi(s))`; `"potential"` is potential-based shaping
      `w * (gamma * phi(s') - phi(s))`, which leaves the optimal policy unchanged.
    - `gamma`: the discount of potential-based shaping, in [0, 1].

    Observation:

    - `joint_velocities`: observe the rods' velocities as well as their positions.
    - `observe_figurines`: observe the figurines' centres (x, y) and their velocities instead
      of the rods' joint values.
    - `opponent_prismatic_only`: observe only the prismatic joints of the opponent's rods, as
      the real table's camera sees them. Tasks without an opponent take only `False`.

    The game:

    - `opponent`: the away side's policy, a callable from the mirrored observation (the game
      as the away side sees it from its own goal) to an action in [-1, 1]; `None` is the
      scripted team, the top of the game's scripted ladder, and `"scripted:N"` its rung N
      (`foosball_gym.policies.ladder`). `set_opponent(policy)` swaps it between episodes.
    - `stagnation_steps`: end the game as a draw once the ball has lain still (slower than
      5 cm/s) for this many steps; 0 never does.

    Domain randomisation, each off at `None`; a range `(low, high)` turns it on, drawn
    uniformly at every reset (the values drawn are in `info["dynamics"]`, from the reset and
    every step of the episode):

    - `ball_friction_range`: the ball's friction coefficient (the table's is 0.1), within
      [0, 10].
    - `ball_restitution_range`: the restitution of every contact of the ball (0.5), within
      [0, 1].
    - `ball_mass_range`: the ball's mass in kg (0.022), within [0.0001, 1].
    - `drive_gain_range`: a factor on the drives' position gains, how briskly they respond,
      within [0.001, 10].
    - `rolling_resistance_range`: how a rolling ball slows, in units of g, within [0, 0.5];
      it overrides `rolling_resistance`.

    What a real table varies, for the joints the action drives, each off by default and drawn
    the same way; each drive or rod has a draw of its own, in `info["dynamics"]` under its
    name (`drive_speed_home_keeper_slide`, `slide_offset_home_keeper`, ...):

    - `drive_speed_range`: a factor on each drive's top speed (a rod's slide and spin apart),
      within [0.1, 1]: slower drives than the rated ones.
    - `drive_accel_range`: a factor on each drive's most acceleration (its force or torque),
      within [0.1, 2].
    - `slide_offset_range`: each rod's slide calibration offset in m, within [-0.05, 0.05]. As
      on a table whose encoder was zeroed off, the observation reads the slide that much
      further along and a slide target lands that much short; the rewards see the true state.
    - `angle_offset_range`: each turning rod's angle calibration offset in rad, within
      [-0.5, 0.5], read and commanded as the slide's.
    - `rod_angle_noise`: the standard deviation of Gaussian noise on each turning rod's
      observed angle in rad, drawn afresh at every observation, within [0, 0.5]; 0 is off.

    Robust training:

    - `estimated_state`: observe the ball and the opponent's rods as the real table does,
      through a simulated camera and the real table's Kalman filter
      (`foosball_gym.envs.estimated`).
    - `camera_noise`: the simulated camera's errors, a dict of the fields of
      `foosball_gym.camera.CameraNoise` (`fps`, `position_std`, `rod_std`, `drop_rate`,
      `hide_under_figurines`, `latency_s`, `latency_jitter_s`, `seed`: the detections' own
      seed, the balls unchanged); needs `estimated_state=True`.
    - `safety_layer`: send the action's targets through the real table's safety layer, as
      `foosball play` does: each kept inside its joint's limit less a margin (5 mm, 0.1 rad)
      and moved towards no faster than the drive's top speed and acceleration allow
      (`foosball_gym.envs.safety_layer`), with the limits of the simulated table of
      `foosball play --table sim`. `None` turns it on with `estimated_state`. Rewards see the
      policy's own action.
    - `residual`: above 0, the action corrects the task's scripted baseline, at most 2. The
      rods are sent `clip(scripted(obs) + residual * action, -1, 1)`, `obs` being the
      observation the action answers: an untrained policy (actions near 0) plays like the
      baseline, and learning improves on it instead of learning it afresh. A list gives each
      entry of the action a scale of its own; 0 leaves that joint to the baseline, so that
      neither the policy's corrections nor its exploration reach it.
    - `slide_around_ball`: above 0, a slide action spans this many metres either side of the
      ball the policy observed, not the rod's travel: an action `a` brings the rod's figurine
      nearest `ball_y + a * slide_around_ball` onto it, as far as the rod slides, so that the
      figurine's place under the ball, which sets where a kick goes, is one value of the
      action wherever the ball lies. Rewards see the policy's own action. The opponent's
      actions span the rods' travel: a copy of such a learner there plays as an
      `AroundBallPlayer` (`whole_action_policy`). Not with `residual`; at most the table's
      width.
    - `slide_skip`: with `slide_around_ball`, an action `a` other than 0 starts this many
      metres to its side of the ball, the figurine brought to `ball_y + a * slide_around_ball
      ± slide_skip`. A resting ball struck anywhere on the flat of the foot, 9 mm either side
      of its middle, leaves straight, and one struck on the foot's rounded edge turns by
      about 3 degrees a millimetre: at 0.009, the flat skipped, the kick's angle grows from 0
      with `a` instead of staying 0 while `|a| * slide_around_ball` is under 9 mm. At most
      the foot's half width and the ball's radius, 0.02925.

    Rendering:

    - `render_mode`: `None`, `"rgb_array"` (a top view) or `"human"` (the PyBullet GUI, kept
      to real time).
    - `render_width`, `render_height`: the size of `"rgb_array"` frames in pixels, each
      within [1, 4096].

    Physics:

    - `physics_hz`: the physics rate away from contacts, a whole multiple of `control_hz`.
      Near a possible contact the simulator steps finer (see `contact_travel`).
    - `control_hz`: environment steps per second; the time limits count these steps.
    - `contact_travel`: near a possible contact, physics steps are made fine enough that
      nothing moves further than this (m) relative to what it may touch, within
      [0.0001, 0.02].
    - `rolling_resistance`: how a rolling ball slows, in units of g (0.01: a ball rolling at
      1 m/s stops after about 5 m), within [0, 0.5].
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": table.CONTROL_HZ}
    observation_space: spaces.Box
    action_space: spaces.Box

    def __new__(cls, *args: Any, **options: Any) -> FoosballEnv:
        cls.check_option_names(options)
        return super().__new__(cls)

    @classmethod
    def option_defaults(cls) -> dict[str, Any]:
        """Every option this environment takes, with its default: its keyword arguments."""
        return env_options.option_defaults(cls)

    @classmethod
    def option_grid(cls) -> dict[str, tuple[Any, ...]]:
        """Every option that takes one of a few values, with those values, the default first:
        what the tests iterate over."""
        return env_options.option_grid(cls)

    @classmethod
    def argument_docs(cls) -> dict[str, str]:
        """Each option's entry in the "Arguments" of this class's docstring or its base's."""
        return env_options.argument_docs(cls)

    @classmethod
    def check_option_names(cls, names: Iterable[str]) -> None:
        """Raise TypeError naming any of ``names`` this environment does not take, and those
        it does."""
        env_options.check_option_names(cls, names)

    #: The shared options' defaults in this environment: :class:`SharedOptions`' own, but
    #: where its task wants others.
    defaults: ClassVar[SharedOptions] = DEFAULTS
    # What inspect.signature gives for each subclass: every option with its type and default,
    # the shared ones that **shared: Unpack hides among them.
    __signature__ = env_options.OptionSignature()

    @classmethod
    def check_options(cls, task: Task, **shared: Unpack[GameOptions]) -> CheckedOptions:
        """The shared options checked for ``task`` as this environment checks them (the
        others at its defaults), building nothing; see
        :func:`~foosball_gym.registration.check_env_options`."""
        return check_shared(task, cls.defaults, **shared)

    def __init__(self, task: Task, **shared: Unpack[GameOptions]) -> None:
        self._closed = False
        self.task = task
        self.layout = layout = task.layout
        checked = self.check_options(task, **shared)
        self.render_mode, self.render_width, self.render_height = checked.render
        self.weights = checked.weights
        self.interface: TaskInterface = checked.interface
        self.observation_options = self.interface.builder.options
        self.obs_builder = self.interface.builder
        self.observation_space = self.obs_builder.space
        self.randomisation = checked.randomisation
        self._rod_errors = checked.rod_errors
        self._estimated: EstimatedState | None = None
        if checked.camera_noise is not None:
            self._estimated = EstimatedState(self.obs_builder, checked.camera_noise, self.np_random)
        self._n_act = self.interface.n_actions
        self.action_space = spaces.Box(-1.0, 1.0, shape=(self._n_act,), dtype=np.float32)
        self.residual = checked.residual
        # Residual RL: the action corrects the scripted baseline, which sees what the agent saw.
        self._baseline = self.scripted_policy() if self.residual else None
        self._last_obs: np.ndarray | None = None
        # This episode's drawn physical parameters (domain randomisation), for every info.
        self._dynamics: dict[str, float] = {}
        # The rods in play that the learner does not drive: they stand in the ball's lanes.
        self._blocking = (
            [i for i, r in enumerate(layout.rods) if r not in layout.controlled]
            if self.weights.ball_lane
            else []
        )
        self._rewards = RewardComputer(
            self.weights,
            [table.rod(r) for r in layout.controlled],
            [table.rod(layout.rods[i]) for i in self._blocking],
        )

        # Imported here: checking the options and building a task's interface needs no
        # simulator.
        from foosball_gym.sim import TableSim

        physics_hz, control_hz, contact_travel, rolling_resistance = checked.physics
        self.sim = TableSim(
            layout.rods,
            physics_hz=physics_hz,
            control_hz=control_hz,
            contact_travel=contact_travel,
            rolling_resistance=rolling_resistance,
            gui=self.render_mode == "human",
        )
        self.dt = self.sim.control_dt
        self._safety: SafetyLayer | None = None
        if checked.safety_layer:
            self._safety = SafetyLayer(
                self.interface.action_joints, self.interface.action_scales, self.dt
            )
        self.metadata = {**self.metadata, "render_fps": self.sim.control_hz}
        self._base_gains = (self.sim.slide_gain, self.sim.spin_gain)
        try:
            self.game = Game(
                task,
                self.interface,
                self.sim,
                opponent=checked.values.opponent,
                stagnation_steps=checked.stagnation_steps,
            )
        except BaseException:
            self.close()  # the simulator is open already
            raise
        self._last_render = 0.0
        self._shown_score = ""
        self._started = False
        self._elapsed = 0
        self._match_steps: int | None = None

    # ------------------------------------------------------------------ policies

    def scripted_policy(self) -> Policy:
        """The scripted baseline for the learner's side of this task."""
        env_options.check_scripted_slides(self.interface.slide_around_ball)
        return self.task.scripted_policy(list(self.obs_builder.names), self._estimated is None)

    def success(self, goals_for: int, goals_against: int) -> bool:
        """Whether the task is met with this score so far."""
        return self.task.success(goals_for, goals_against)

    @property
    def opponent(self) -> Policy | None:
        return self.game.opponent

    def set_opponent(self, policy: Policy | str | None) -> None:
        """Set the policy that plays the away side: a callable from the mirrored observation
        (the game as the away side sees it from its own goal) to an action in [-1, 1], or
        ``"scripted:N"``, rung N of the game's scripted ladder. ``None`` (or ``"scripted"``)
        restores the scripted default, the top of the ladder."""
        if not self.layout.opponent:
            raise ValueError(f"{type(self).__name__} has no opponent to set")
        self.game.set_opponent(policy)

    def set_serves(self, **options: Any) -> None:
        """Change the incoming shots' options (``speed_range``, ``serve_x_range``,
        ``serve_y_range``, ``bank_share``, ``double_bank_share``, ``beside_mouth``,
        ``rebound_share``; Score with obstacles its ``obstacle_share``, keeper against keeper
        its ``home_serve_share``) from the next reset on, checked as the constructor checks
        them: a curriculum over serves (``TrainConfig.curriculum``).

        Raises:
            ValueError: the task has no such options (Score with the ball at rest and no
                obstacles, the full game), or an option is unknown or out of range.
        """
        self.task.set_serves(**options)

    def scripted_opponent(self, level: int | None = None) -> Policy:
        """A scripted team for the away side, acting on the mirrored observation: the default
        opponent, or rung ``level`` of the game's scripted ladder."""
        if not self.layout.opponent:
            raise ValueError(f"{type(self).__name__} has no opponent")
        return self.game.scripted_opponent(level)

    def scripted_level(self, level: int | None) -> Policy:
        """Rung ``level`` of the game's scripted ladder for the learner's side (None: the
        scripted baseline, as :meth:`scripted_policy`)."""
        return self.task.scripted_level(
            level, list(self.obs_builder.names), self._estimated is None
        )

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
        allowed = self.task.reset_options
        options = env_options.reset_options(options, allowed)
        super().reset(seed=seed)
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
            ball_velocity = check_ball_velocity("ball_velocity", ball_velocity)
        self._dynamics = self._randomise_dynamics()
        if self._rod_errors.ranges:
            self._dynamics.update(self._rod_errors.draw(self.np_random))
            self.game.own_offsets = list(self._rod_errors.offsets)
        if self._estimated is not None:
            self._estimated.reseed(self.np_random, seed)
        self._start(self.task.sample_start(self.np_random, ball_position, ball_velocity, options))
        self._started = True
        self._elapsed = 0
        self._match_steps = self.task.match_steps(self.sim.control_hz)
        obs = self._last_obs = self._observe()
        info = self.step_info(_NOTHING_YET, dict.fromkeys(TERMS, 0.0))
        if self.render_mode == "human":
            self.render()
        return obs, info

    def _randomise_dynamics(self) -> dict[str, float]:
        """Draw this episode's physical parameters where randomisation is on."""
        if not self.randomisation:
            return {}
        return self.sim.draw_dynamics(
            self.randomisation, self.np_random, self._base_gains, self.interface.action_joints
        )

    def _start(self, start) -> None:
        game = self.game
        game.start(start)
        if self._safety is not None:
            self._safety.reset(game.own_readings())
        self._rewards.reset(
            self._controlled_slides(), game.ball, self._n_act, self._blocking_joints()
        )
        if self._estimated is not None:
            self._estimated.reset(game.ball, game.positions, self.sim.figurine_positions())

    def _observe(self) -> np.ndarray:
        game = self.game
        positions = game.positions
        if self._rod_errors.on:
            positions = self._rod_errors.observed(positions, self.np_random)
        if self._estimated is not None:
            return self._estimated.observation(positions, game.velocities)
        return self.obs_builder.build(positions, game.velocities, game.ball)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._closed:
            raise gym.error.ClosedEnvironmentError("the environment is closed; make a new one")
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before step()")
        act = check_action(action, self._n_act, "action")
        if self._baseline is not None:
            assert self._last_obs is not None  # reset() sets it before any step
            base = self._baseline(self._last_obs)
            act = [float(a) for a in residual_action(base, self.residual, act)]
        sent = act
        if self.interface.slide_around_ball:
            assert self._last_obs is not None  # reset() sets it before any step
            sent = self.interface.table_action(act, self._last_obs)
        game = self.game
        game.command(sent if self._safety is None else self._safety.shape(sent))
        outcome = game.advance()
        if self._estimated is not None:
            self._estimated.advance(
                self.dt, game.ball, game.positions, self.sim.figurine_positions()
            )
        continuous = outcome.ended and self.task.continues_after_goal
        # A match's rules end it: a side has its first_to goals, or its time is up.
        decided = continuous and self.task.match_over(game.goals_for, game.goals_against)
        self._elapsed += 1
        time_up = self._match_steps is not None and self._elapsed >= self._match_steps
        terminated = outcome.ended and (not continuous or decided)
        terms = self._rewards.step(
            outcome.goal,
            outcome.out_of_table,
            self._controlled_slides(),
            game.ball,
            act,
            terminated,
            self._blocking_joints(),
        )
        info = self.step_info(outcome, terms)
        if continuous and not decided:
            goals = game.goals_for, game.goals_against
            self._start(self.task.sample_start(self.np_random))
            game.goals_for, game.goals_against = goals
        obs = self._last_obs = self._observe()
        if self.render_mode == "human":
            self.render()
        return obs, float(sum(terms.values())), terminated, time_up and not terminated, info

    # gymnasium returns a TypeVar bound to nothing from render(), which no frame type matches.
    def render(self) -> np.ndarray | None:  # type: ignore[override]
        if self.render_mode == "rgb_array":
            return self.sim.render(self.render_width, self.render_height)
        if self.render_mode == "human":
            # Keep the GUI at real time: one control step per dt of wall clock.
            wait = self._last_render + self.dt - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            self._last_render = time.perf_counter()
            score = f"goals for {self.game.goals_for}, against {self.game.goals_against}"
            if self.layout.opponent and score != self._shown_score:
                # In the window's clear band above the table, written as it changes.
                self.sim.show_text([score])
                self._shown_score = score
        return None

    def close(self) -> None:
        self._closed = True
        sim = getattr(self, "sim", None)
        if sim is not None:
            sim.close()

    # ------------------------------------------------------------------ copies

    def __getstate__(self) -> dict[str, Any]:
        # A copy is an env of its own: the game and its simulator copy themselves. gym.make
        # keeps the opponent among the spec's kwargs too; it is copied as the game copies it.
        state = self.__dict__.copy()
        spec = state.get("spec")
        if spec is not None and spec.kwargs.get("opponent") is not None:
            spec = state["spec"] = copy.copy(spec)
            spec.kwargs = {**spec.kwargs, "opponent": portable(spec.kwargs["opponent"])}
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        spec = state.get("spec")
        if spec is not None and "opponent" in spec.kwargs:
            spec.kwargs["opponent"] = unpacked(spec.kwargs["opponent"])
        self.__dict__.update(state)

    # ------------------------------------------------------------------ helpers

    def _controlled_slides(self) -> list[float]:
        return self.game.positions[: len(self.layout.controlled)]

    def _blocking_joints(self) -> list[float]:
        """The slides then the spins of the rods the ball's aim looks past."""
        if not self._blocking:
            return []
        return rod_joints(self.game.positions, len(self.layout.rods), self._blocking)

    def step_info(self, outcome: Outcome, terms: Mapping[str, float]) -> dict[str, Any]:
        """The info of a step that brought ``outcome`` and these reward terms.

        A reset's info is that of a step where nothing happened, so that every info of an
        environment has the same keys with values of the same types: recorders of infos (such
        as Minari's ``DataCollector``) need that.

        Args:
            outcome: what the step brought.
            terms: the step's reward terms, keyed by name.
        """
        game = self.game
        info: dict[str, Any] = {
            "goal": int(outcome.goal),
            "is_success": bool(game.success),
            "out_of_table": bool(outcome.out_of_table),
            "stagnated": bool(outcome.stagnated),
        }
        if self.layout.opponent:
            info["goals_for"], info["goals_against"] = int(game.goals_for), int(game.goals_against)
        # Floats always: an integer weight would make some terms ints and others floats.
        info.update((key, float(terms[name])) for key, name in _TERM_KEYS)
        if self._dynamics:
            info["dynamics"] = dict(self._dynamics)
        return info

    def rod_joint_values(self) -> tuple[list[float], list[float]]:
        """Joint positions and velocities of the rods in play (all slides, then all spins, in
        ``layout.rods`` order), as of the last reset or step."""
        return list(self.game.positions), list(self.game.velocities)
