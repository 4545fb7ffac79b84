"""Foosball-KeeperVsKeeper-v0: the two keepers play each other."""

from foosball_gym.envs.base import FoosballEnv
from foosball_gym.tasks.keeper_vs_keeper import KeeperVsKeeperTask


class KeeperVsKeeperEnv(FoosballEnv):
    """Keeper against keeper, the game the paper's real table can play today.

    ## Description
    Only the two keepers are in play. The learner drives the home keeper (slide and spin); the
    opponent, a policy acting on the mirrored observation, drives the away keeper. The paper
    trains this task by self-play (``foosball_gym.training.SelfPlayCallback``).

    ## Action Space
    ``Box(-1, 1, (2,), float32)``: home keeper prismatic target (±0.123 m) and revolute
    target (±2π rad).

    ## Observation Space
    ``Box(10,)`` float32 by default (the opponent seen only along its prismatic joint, as
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

    ``opponent_prismatic_only=False`` adds the opponent's spin position and velocity (12);
    ``joint_velocities=False`` drops every rod velocity; ``observe_figurines=True`` replaces
    joint values with figurine centres. ``env.unwrapped.obs_builder.names`` lists the entries.

    ## Rewards
    ``±goal_reward`` (1000) for a goal scored / conceded, ``-out_of_table_penalty`` (1000);
    no shaping by default.

    ## Starting State
    The ball lies still in front of a keeper chosen at random: x = ±(0.497 ± 0.005),
    y ~ U(-0.1, 0.1). Both keepers start centred (or just beside the ball).

    ## Episode End
    Terminated on a goal, when the ball leaves the table, or as a draw when the ball has lain
    still for ``stagnation_steps`` (60, one second); truncated after 1800 steps (30 s).
    With ``continuous=True`` none of these ends the episode: the ball is served again (the
    keepers centred, the ball in front of either) and the score runs on for the whole 30 s;
    success is being ahead then. Two sound keepers mostly draw a single serve; a match gives
    each many chances.
    ``info``: ``is_success`` (the learner scored), ``goal``, ``goals_for``,
    ``goals_against``, ``stagnated``.

    ## Arguments
    ``continuous``, ``opponent`` (default: the scripted keeper), ``stagnation_steps`` and
    every keyword of
    :class:`FoosballEnv`. ``set_opponent(policy)`` swaps the opponent between episodes.

    ## Version History
    - v0: first version.
    - v0, physics revision 2: the faithful table (README, "The simulated table");
      ``control_hz`` replaces ``substeps``.
    - v0: ``continuous``, a match of many serves.
    """

    task_class = KeeperVsKeeperTask
