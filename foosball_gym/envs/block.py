"""Foosball-Block-v0: the home keeper blocks shots at its goal."""

from foosball_gym.envs.base import FoosballEnv
from foosball_gym.tasks.block import BlockTask


class BlockEnv(FoosballEnv):
    """Block shots with the home keeper.

    ## Description
    A ball is shot from the away half towards the home goal (x = -0.60); the home keeper slides
    along its rod to stop it. Only the keeper is in play; its rod does not turn.

    ## Action Space
    ``Box(-1, 1, (1,), float32)``: the keeper's prismatic target, scaled to ±0.123 m.

    ## Observation Space
    ``Box(6,)`` float32, SI units, world frame:

    | index | name | unit |
    |---|---|---|
    | 0 | home_keeper_slide_pos | m |
    | 1 | home_keeper_slide_vel | m/s |
    | 2 | ball_x | m |
    | 3 | ball_y | m |
    | 4 | ball_vx | m/s |
    | 5 | ball_vy | m/s |

    With ``joint_velocities=False`` index 1 is left out. With ``observe_figurines=True`` the
    keeper's joint values are replaced by its figurine's centre (x, y) and its velocity.
    ``env.unwrapped.obs_builder.names`` always lists the entries.

    ## Rewards
    ``-goal_reward`` (-1000) when a goal is conceded, ``-out_of_table_penalty`` (-1000) when
    the ball leaves the table upwards; no shaping by default, as in the authors' blocking task.
    Every term is in ``info["reward_<name>"]``.

    ## Starting State
    Keeper centred. Ball at x ~ U(``serve_x_range``) = U(0, 0.4), y ~ U(``serve_y_range``) =
    U(-0.3, 0.3), shot at ``speed_range`` ~ U(2, 7) m/s at a uniform point of the home goal
    mouth (a goal if nothing stops it). A share ``bank_share`` (default 0) of the shots is
    aimed off a side wall instead, at the middle of the mouth, allowing for how the simulated
    wall flattens the path (with the keeper out of the way, 299 of 300 such shots score).
    What a real opponent plays, and what ``builtin:block`` was trained on, is the wide
    distribution ``speed_range=(2, 10), serve_x_range=(-0.1, 0.45),
    serve_y_range=(-0.32275, 0.32275), bank_share=0.5``.
    ``reset(options={"ball_position": (x, y), "ball_velocity": (vx, vy)})`` places the ball
    exactly; with only a position, the shot is aimed from there.

    ## Episode End
    Terminated on a goal (either way) or when the ball leaves the table; truncated after 90
    steps (1.5 s) by the registered ``TimeLimit``. ``info["is_success"]``: no goal conceded
    so far. ``info["goal"]``: +1 scored, -1 conceded, 0 none.

    ## Arguments
    ``speed_range`` (m/s, at most 30), ``serve_x_range`` (m, within [-0.1, 0.48275]),
    ``serve_y_range`` (m, within ±0.32275), ``bank_share`` (in [0, 1]), and every keyword
    of :class:`FoosballEnv` (reward weights,
    ``shaping``, ``gamma``, ``joint_velocities``, ``observe_figurines``, ``render_mode``,
    ``render_width``, ``render_height``, and the physics options ``physics_hz``,
    ``control_hz``, ``contact_travel``, ``rolling_resistance``).

    ## Version History
    - v0: first version.
    - v0, physics revision 2: the faithful table (README, "The simulated table");
      ``control_hz`` replaces ``substeps``.
    - v0: ``serve_x_range``, ``serve_y_range`` and ``bank_share``; their defaults serve what
      v0 always served, seed for seed.
    """

    task_class = BlockTask
