"""Foosball-KeeperVsKeeper-v0: the two keepers play each other."""

from __future__ import annotations

from typing import ClassVar

from typing_extensions import Unpack

from foosball_gym.envs.base import FoosballEnv
from foosball_gym.envs.options import GameOptions, SharedOptions
from foosball_gym.tasks.keeper_vs_keeper import KeeperVsKeeperTask
from foosball_gym.tasks.match import DEAD_BALL_STEPS


class KeeperVsKeeperEnv(FoosballEnv):
    """Keeper against keeper, the game the paper's real table can play today.

    ## Description
    Only the two keepers are in play. The learner drives the home keeper (slide and spin); the
    opponent, a policy acting on the mirrored observation, drives the away keeper. The paper
    trains this task by self-play (`foosball_gym.training.SelfPlayCallback`).

    ## Action Space
    `Box(-1, 1, (2,), float32)`: home keeper prismatic target (±0.123 m) and revolute
    target (±2π rad).

    ## Observation Space
    `Box(10,)` float32 by default (the opponent seen only along its prismatic joint, as
    the real table's camera sees it):

    | index | name | unit |
    |---|---|---|
    | 0 | home_keeper_slide_pos | m |
    | 1 | home_keeper_spin_pos | rad |
    | 2 | home_keeper_slide_vel | m/s |
    | 3 | home_keeper_spin_vel | rad/s |
    | 4 | away_keeper_slide_pos | m |
    | 5 | away_keeper_slide_vel | m/s |
    | 6-9 | ball_x, ball_y, ball_vx, ball_vy | m, m/s |

    `opponent_prismatic_only=False` adds the opponent's spin position and velocity (12);
    `joint_velocities=False` drops every rod velocity; `observe_figurines=True` replaces
    joint values with figurine centres. `env.unwrapped.obs_builder.names` lists the entries.

    ## Rewards
    `±goal_reward` (1000) for a goal scored / conceded, `-out_of_table_penalty` (1000);
    no shaping by default.

    ## Starting State
    The ball lies still in front of a keeper chosen at random: x = ±(0.497 ± 0.005),
    y ~ U(-0.1, 0.1). Both keepers start centred (or just beside the ball).

    ## Episode End
    Terminated on a goal, when the ball leaves the table, or as a draw on a dead ball: one
    that has lain still for `stagnation_steps` (60, one second), or at rest out of both
    keepers' reach for `dead_ball_steps` (30); truncated after 1800 steps (30 s).
    With `continuous=True` none of these ends the episode: the ball is served again (the
    keepers centred, the ball in front of either) and the score runs on for the whole 30 s
    (or `match_seconds`, or until a side has `first_to` goals); success is being ahead then.
    Two sound keepers mostly draw a single serve; a match gives each many chances.
    `info`: `is_success` (the learner scored), `goal`, `goals_for`,
    `goals_against`, `stagnated`.

    A keeper turns at most two turns in all, one either way from its figurine hanging down
    (the revolute target is ±2π rad): the rules forbid spinning a rod.

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
    - `home_serve_share`: the chance that a serve lies in front of the learner's (home)
      keeper, the others in front of the opponent's: 0.5, either at random, by default; 0
      serves every ball to the opponent, a task of defence alone, and 1 every ball to the
      learner.

    The other arguments are those every environment takes, described under
    [FoosballEnv][foosball_gym.envs.base.FoosballEnv]; `opponent` defaults to the scripted
    keeper, the top of the scripted ladder (`foosball_gym.policies.ladder`; `"scripted:N"`
    names a level).

    ## Version History
    - v0: first version.
    - v0, physics revision 2: the faithful table (the documentation's "The simulated table");
      `control_hz` replaces `substeps`.
    - v0: `continuous`, a match of many serves.
    - v0: the options are the class's keyword arguments.
    - v0: `first_to`, `match_seconds` and `dead_ball_steps` (on by default: a ball at rest
      out of both keepers' reach is served again after half a second instead of a second);
      the scripted keeper is the top of a ladder of levels (`scripted:N`).
    - v0: what a real table varies, off by default (episodes as before, seed for seed):
      `drive_speed_range`, `drive_accel_range`, `slide_offset_range`, `angle_offset_range`,
      `rod_angle_noise`, and `camera_noise`'s `latency_jitter_s`.
    - v0: `safety_layer`, on by default with `estimated_state`: an environment on estimated
      state plays like `foosball play`, its targets shaped by the real table's safety layer.
    - v0: `home_serve_share` (0.5 by default: the serves as before, seed for seed).
    """

    defaults: ClassVar[SharedOptions] = SharedOptions(
        # The real table's camera sees only where the opponent's rod is slid to.
        opponent_prismatic_only=True,
        # A ball lying still for a second is a draw.
        stagnation_steps=60,
    )

    def __init__(
        self,
        *,
        continuous: bool = False,
        first_to: int = 0,
        match_seconds: float | None = None,
        dead_ball_steps: int = DEAD_BALL_STEPS,
        home_serve_share: float = 0.5,
        **shared: Unpack[GameOptions],
    ) -> None:
        super().__init__(
            KeeperVsKeeperTask(
                continuous=continuous,
                first_to=first_to,
                match_seconds=match_seconds,
                dead_ball_steps=dead_ball_steps,
                home_serve_share=home_serve_share,
            ),
            **shared,
        )
