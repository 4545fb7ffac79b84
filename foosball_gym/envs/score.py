"""Foosball-Score-v0: the home keeper shoots the ball into the away goal."""

from __future__ import annotations

from typing import Any

import numpy as np

from foosball_gym import table as T
from foosball_gym.envs.base import FoosballEnv, Start
from foosball_gym.envs.common import (
    SHOT_SPEED_LIMITS,
    check_choice,
    check_range,
    random_shot_start,
    resting_in_front_of,
    shot_at_goal,
)
from foosball_gym.interface.task import Layout
from foosball_gym.policies.scripted import ScriptedTeam

BALL_STARTS = ("resting", "incoming")
OBSTACLES = ("away_keeper", "away_defense", "away_offense")


class ScoreEnv(FoosballEnv):
    """Score a goal with the home keeper.

    ## Description
    The home keeper, which can slide and turn, must put the ball into the away goal
    (x = +0.60). With ``obstacles=True`` the away keeper, defense and offense stand in the way
    at random prismatic positions, still for the whole episode.

    ## Action Space
    ``Box(-1, 1, (2,), float32)``: the keeper's prismatic target (scaled to ±0.123 m) and its
    revolute target (scaled to ±2π rad; positive swings the foot towards the away goal).

    ## Observation Space
    ``Box(8,)`` float32 (``Box(11,)`` with obstacles), SI units, world frame:

    | index | name | unit |
    |---|---|---|
    | 0 | home_keeper_slide_pos | m |
    | 1 | home_keeper_spin_pos | rad |
    | 2 | home_keeper_slide_vel | m/s |
    | 3 | home_keeper_spin_vel | rad/s |
    | 4-7 | ball_x, ball_y, ball_vx, ball_vy | m, m/s |
    | 8-10 | away_keeper, away_defense, away_offense slide_pos (obstacles only) | m |

    ``joint_velocities=False`` leaves out indices 2-3; ``observe_figurines=True`` replaces
    0-3 with the figurine's centre (x, y) and velocity. ``env.unwrapped.obs_builder.names``
    always lists the entries.

    ## Rewards
    ``+goal_reward`` (1000) for a goal, ``-goal_reward`` for an own goal,
    ``-out_of_table_penalty`` (1000) when the ball leaves the table, and action
    regularisation with weight 0.5, as in the authors' scoring tasks.

    ## Starting State
    ``ball_start="resting"``: the ball lies still at x = -0.497 ± 0.005, y ~ U(-0.1, 0.1).
    ``"incoming"``: as Block, shot at the home goal at ``speed_range`` ~ U(3, 7) m/s. The keeper
    starts centred, or just beside the ball if centred would put the figurine inside it.
    Reset options: ``ball_position``, ``ball_velocity`` and, with obstacles,
    ``obstacle_positions`` (the three prismatic values, in the order above).

    ## Episode End
    Terminated on a goal either way or when the ball leaves the table; truncated after 180
    steps. ``info["is_success"]``: a goal was scored.

    ## Arguments
    ``ball_start``, ``obstacles``, ``speed_range`` and every keyword of :class:`FoosballEnv`.

    ## Version History
    - v0: first version.
    - v0, physics revision 2: the faithful table (README, "The simulated table");
      ``control_hz`` replaces ``substeps``.
    """

    reset_options = ("ball_position", "ball_velocity", "obstacle_positions")
    task_options = {"ball_start": BALL_STARTS, "obstacles": (False, True)}

    def __init__(
        self,
        *,
        ball_start: str = "resting",
        obstacles: bool = False,
        speed_range: tuple[float, float] = (3.0, 7.0),
        action_regularisation_weight: float = 0.5,
        **kwargs: Any,
    ) -> None:
        self.ball_start = check_choice("ball_start", ball_start, BALL_STARTS)
        if not isinstance(obstacles, (bool, np.bool_)):
            raise ValueError(f"obstacles must be True or False, got {obstacles!r}")
        self.obstacles = bool(obstacles)
        self.speed_range = check_range("speed_range", speed_range, *SHOT_SPEED_LIMITS)
        static = OBSTACLES if self.obstacles else ()
        super().__init__(
            Layout(controlled=("home_keeper",), joints="both", static=static),
            extras=static,
            action_regularisation_weight=action_regularisation_weight,
            **kwargs,
        )

    def _sample_start(self, ball_position, ball_velocity, options: dict[str, Any]) -> Start:
        rng = self.np_random
        if self.ball_start == "resting":
            position, velocity = resting_in_front_of(rng, T.HOME), (0.0, 0.0)
        else:
            position, velocity = random_shot_start(rng, self.speed_range)
        if ball_position is not None:
            position = ball_position
            if self.ball_start == "incoming":
                velocity = shot_at_goal(rng, position, self.speed_range, T.HOME)
        if ball_velocity is not None:
            velocity = ball_velocity
        slide = [0.0]
        if self.obstacles:
            slide += self._obstacle_positions(options.get("obstacle_positions"))
        elif options.get("obstacle_positions") is not None:
            raise ValueError("obstacle_positions needs obstacles=True")
        return Start(slide, [0.0] * len(slide), position, velocity)

    def _obstacle_positions(self, given: Any) -> list[float]:
        rods = [T.rod(name) for name in OBSTACLES]
        if given is None:
            return [float(self.np_random.uniform(-r.slide_limit, r.slide_limit)) for r in rods]
        try:
            values = [float(v) for v in given]
        except (TypeError, ValueError):
            values = []
        if len(values) != len(rods) or not all(
            abs(v) <= r.slide_limit for v, r in zip(values, rods)
        ):
            limits = ", ".join(f"{r.name} ±{r.slide_limit}" for r in rods)
            raise ValueError(
                f"obstacle_positions must be three prismatic values within ({limits}), "
                f"got {given!r}"
            )
        return values

    def scripted_policy(self) -> ScriptedTeam:
        """The scripted keeper, striking incoming balls (blocked ones trickle out of reach)
        and aiming past the obstacles."""
        names, rods = self.obs_builder.names, self.layout.controlled
        return ScriptedTeam(names, rods, "both", volley=True, aim=True)

    def success(self, goals_for: int, goals_against: int) -> bool:
        return goals_for > 0
