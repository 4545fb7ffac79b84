"""Foosball-FullGame-v0: all eight rods, the whole game."""

from __future__ import annotations

from typing import ClassVar

from typing_extensions import Unpack

from foosball_gym.envs.base import FoosballEnv
from foosball_gym.envs.options import GameOptions, SharedOptions
from foosball_gym.tasks.full_game import FullGameTask
from foosball_gym.tasks.match import DEAD_BALL_STEPS


class FullGameEnv(FoosballEnv):
    """The full game: four rods a side.

    ## Description
    All 8 rods are in play. The learner drives the four home rods (slide and spin each); the
    opponent, a policy acting on the mirrored observation, drives the four away rods.

    ## Action Space
    `Box(-1, 1, (8,), float32)`: for keeper, defense, midfield, offense in turn, the
    prismatic target (scaled to the rod's range) and the revolute target (±2π rad).

    ## Observation Space
    `Box(36,)` float32:

    | index | content |
    |---|---|
    | 0-7 | home keeper, defense, midfield, offense: slide_pos, spin_pos each |
    | 8-15 | the same rods' slide_vel, spin_vel |
    | 16-23 | away keeper, defense, midfield, offense: slide_pos, spin_pos each |
    | 24-31 | the same rods' velocities |
    | 32-35 | ball_x, ball_y, ball_vx, ball_vy |

    `opponent_prismatic_only=True` keeps only the opponent's prismatic joints (28);
    `joint_velocities=False` drops rod velocities; `observe_figurines=True` replaces
    joint values with figurine centres. `env.unwrapped.obs_builder.names` lists the entries.

    ## Rewards
    `±goal_reward` (1000) for a goal scored / conceded, `-out_of_table_penalty` (1000);
    no shaping by default (`ball_to_goal_weight` helps early training).

    ## Starting State
    Kick-off from a side wall: the ball at (0, ±0.3) rolling towards the centre line with
    vx ~ ±U(0.25, 1) and |vy| ~ U(1, 2) m/s. All rods centred, feet down.

    ## Episode End
    Terminated on a goal, when the ball leaves the table, or as a draw on a dead ball: one
    lying still for `stagnation_steps` (60), or at rest out of every figurine's reach for
    `dead_ball_steps` (30); truncated after 3600 steps (one minute). With `continuous=True`
    none of these ends the episode: the ball is served again and the score runs on
    (`info["goals_for"]`, `info["goals_against"]`) until the time limit (or `match_seconds`,
    or a side's `first_to` goals), for evaluating whole matches; `is_success` is then "ahead
    on goals".

    A rod turns at most two turns in all, one either way from its figurines hanging down
    (the revolute target is ±2π rad): the rules forbid spinning a rod, and the drive's stop
    holds it there.

    ## Arguments
    - `continuous`: play a match of many serves instead of one: a goal or a dead ball serves
      again, and success is being ahead at the time limit.
    - `first_to`: with `continuous=True`, the match ends (terminated) as soon as a side has
      scored this many goals; 0 plays on until time is up.
    - `match_seconds`: with `continuous=True`, the match's length in seconds of play: it ends
      then (truncated, as a time limit does). `None` plays until the time limit. The time
      limit ends an episode all the same, so a match longer than the registered one needs
      it raised: `gymnasium.make(..., max_episode_steps=N)`.
    - `dead_ball_steps`: a ball at rest (slower than 5 cm/s) where no figurine in play can
      reach it, whatever the rods' slides, is dead after this many steps: served again in a
      match, a draw in a single serve, as the table's rules have it
      (`foosball_gym.table.within_reach`; `info["stagnated"]` says so). 0: never.

    The other arguments are those every environment takes, described under
    [FoosballEnv][foosball_gym.envs.base.FoosballEnv]; `opponent` defaults to the scripted
    team, the top of the scripted ladder (`foosball_gym.policies.ladder`; `"scripted:N"`
    names a level).

    ## Version History
    - v0: first version.
    - v0, physics revision 2: the faithful table (the documentation's "The simulated table");
      `control_hz` replaces `substeps`.
    - v0: the options are the class's keyword arguments.
    - v0: `first_to`, `match_seconds` and `dead_ball_steps` (on by default: a ball at rest
      out of reach is served again after half a second instead of a second); the scripted
      team is the top of a ladder of levels (`scripted:N`).
    - v0: what a real table varies, off by default (episodes as before, seed for seed):
      `drive_speed_range`, `drive_accel_range`, `slide_offset_range`, `angle_offset_range`,
      `rod_angle_noise`, and `camera_noise`'s `latency_jitter_s`.
    - v0: `safety_layer`, on by default with `estimated_state`: an environment on estimated
      state plays like `foosball play`, its targets shaped by the real table's safety layer.
    """

    # A ball lying still for a second is a draw.
    defaults: ClassVar[SharedOptions] = SharedOptions(stagnation_steps=60)

    def __init__(
        self,
        *,
        continuous: bool = False,
        first_to: int = 0,
        match_seconds: float | None = None,
        dead_ball_steps: int = DEAD_BALL_STEPS,
        **shared: Unpack[GameOptions],
    ) -> None:
        super().__init__(
            FullGameTask(
                continuous=continuous,
                first_to=first_to,
                match_seconds=match_seconds,
                dead_ball_steps=dead_ball_steps,
            ),
            **shared,
        )
