"""Foosball-Score-v0: the home keeper shoots the ball into the away goal."""

from foosball_gym.envs.base import FoosballEnv
from foosball_gym.tasks.score import ScoreTask


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
    ``"incoming"``: as Block, shot at the home goal at ``speed_range`` ~ U(3, 7) m/s, from
    ``serve_x_range`` and ``serve_y_range``, a share ``bank_share`` off a side wall. The keeper
    starts centred, or just beside the ball if centred would put the figurine inside it.
    Reset options: ``ball_position``, ``ball_velocity`` and, with obstacles,
    ``obstacle_positions`` (the three prismatic values, in the order above).

    ## Episode End
    Terminated on a goal either way or when the ball leaves the table; truncated after 180
    steps. ``info["is_success"]``: a goal was scored.

    ## Arguments
    ``ball_start``, ``obstacles``, ``speed_range``, ``serve_x_range``, ``serve_y_range``,
    ``bank_share`` (see ``Foosball-Block-v0``; they shape incoming balls only) and every
    keyword of :class:`FoosballEnv`.

    ## Version History
    - v0: first version.
    - v0, physics revision 2: the faithful table (README, "The simulated table");
      ``control_hz`` replaces ``substeps``.
    - v0: ``serve_x_range``, ``serve_y_range`` and ``bank_share``, as Block's.
    """

    task_class = ScoreTask
