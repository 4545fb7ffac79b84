"""Foosball-FullGame-v0: all eight rods, the whole game."""

from foosball_gym.envs.base import FoosballEnv
from foosball_gym.tasks.full_game import FullGameTask


class FullGameEnv(FoosballEnv):
    """The full game: four rods a side.

    ## Description
    All 8 rods are in play. The learner drives the four home rods (slide and spin each); the
    opponent, a policy acting on the mirrored observation, drives the four away rods.

    ## Action Space
    ``Box(-1, 1, (8,), float32)``: for keeper, defense, midfield, offense in turn, the
    prismatic target (scaled to the rod's range) and the revolute target (±2π rad).

    ## Observation Space
    ``Box(36,)`` float32:

    | index | content |
    |---|---|
    | 0-7 | home keeper, defense, midfield, offense: slide_pos, spin_pos each |
    | 8-15 | the same rods' slide_vel, spin_vel |
    | 16-23 | away keeper, defense, midfield, offense: slide_pos, spin_pos each |
    | 24-31 | the same rods' velocities |
    | 32-35 | ball_x, ball_y, ball_vx, ball_vy |

    ``opponent_prismatic_only=True`` keeps only the opponent's prismatic joints (28);
    ``joint_velocities=False`` drops rod velocities; ``observe_figurines=True`` replaces
    joint values with figurine centres. ``env.unwrapped.obs_builder.names`` lists the entries.

    ## Rewards
    ``±goal_reward`` (1000) for a goal scored / conceded, ``-out_of_table_penalty`` (1000);
    no shaping by default (``ball_to_goal_weight`` helps early training).

    ## Starting State
    Kick-off from a side wall: the ball at (0, ±0.3) rolling towards the centre line with
    vx ~ ±U(0.25, 1) and |vy| ~ U(1, 2) m/s. All rods centred, feet down.

    ## Episode End
    Terminated on a goal, when the ball leaves the table, or as a draw when it has lain still
    for ``stagnation_steps`` (60); truncated after 3600 steps (one minute). With
    ``continuous=True`` none of these ends the episode: the ball is served again and the score
    runs on (``info["goals_for"]``, ``info["goals_against"]``) until the time limit, for
    evaluating whole matches; ``is_success`` is then "ahead on goals".

    ## Arguments
    ``continuous``, ``opponent`` (default: the scripted team), ``stagnation_steps`` and every
    keyword of :class:`FoosballEnv`. ``set_opponent(policy)`` swaps the opponent.

    ## Version History
    - v0: first version.
    - v0, physics revision 2: the faithful table (README, "The simulated table");
      ``control_hz`` replaces ``substeps``.
    """

    task_class = FullGameTask
