"""Foosball-Score-v0: the home keeper shoots the ball into the away goal."""

from __future__ import annotations

from typing import ClassVar, Literal

from typing_extensions import Unpack

from foosball_gym.envs.base import FoosballEnv
from foosball_gym.envs.options import EnvOptions, SharedOptions
from foosball_gym.tasks.score import ScoreTask


class ScoreEnv(FoosballEnv):
    """Score a goal with the home keeper.

    ## Description
    The home keeper, which can slide and turn, must put the ball into the away goal
    (x = +0.60). With `obstacles=True` the away keeper, defense and offense stand in the way
    at random prismatic positions, still for the whole episode.

    ## Action Space
    `Box(-1, 1, (2,), float32)`: the keeper's prismatic target (scaled to ±0.123 m) and its
    revolute target (scaled to ±2π rad; positive swings the foot towards the away goal).

    ## Observation Space
    `Box(8,)` float32 (`Box(11,)` with obstacles), SI units, world frame:

    | index | name | unit |
    |---|---|---|
    | 0 | home_keeper_slide_pos | m |
    | 1 | home_keeper_spin_pos | rad |
    | 2 | home_keeper_slide_vel | m/s |
    | 3 | home_keeper_spin_vel | rad/s |
    | 4-7 | ball_x, ball_y, ball_vx, ball_vy | m, m/s |
    | 8-10 | away_keeper, away_defense, away_offense slide_pos (obstacles only) | m |

    `joint_velocities=False` leaves out indices 2-3; `observe_figurines=True` replaces
    0-3 with the figurine's centre (x, y) and velocity. `env.unwrapped.obs_builder.names`
    always lists the entries.

    ## Rewards
    `+goal_reward` (1000) for a goal, `-goal_reward` for an own goal,
    `-out_of_table_penalty` (1000) when the ball leaves the table, and action
    regularisation with weight 0.5, as in the authors' scoring tasks.

    ## Starting State
    `ball_start="resting"`: the ball lies still at x = -0.497 ± 0.005, y ~ U(-0.1, 0.1).
    `"incoming"`: as in Block, a shot at the home goal from `serve_x_range` x
    `serve_y_range` at a speed from `speed_range`, a share `bank_share` off a side wall.
    The keeper starts centred, or just beside the ball if centred would put the figurine
    inside it. Reset options: `ball_position`, `ball_velocity` and, with obstacles,
    `obstacle_positions` (the three prismatic values, in the order above).

    ## Episode End
    Terminated on a goal either way or when the ball leaves the table; truncated after 180
    steps. `info["is_success"]`: a goal was scored.

    ## Arguments
    - `ball_start`: how the ball starts: `"resting"` in front of the keeper, or
      `"incoming"`, shot at the home goal.
    - `obstacles`: put the away keeper, defense and offense in the way, still.
    - `obstacle_share`: with obstacles, the chance, in [0, 1], that each of the three rods
      stands in the ball's way at a reset; the others are spun up a quarter turn, their
      figurines level above the ball (a curriculum over the rods: the observation still
      gives their slides).
    - `shut_lane_share`: with obstacles and the ball at rest, the chance, in [0, 1], that a
      reset is drawn again until a straight kick from the ball would meet a standing figurine
      or miss the mouth (a curriculum towards the aimed shot; 0, the task's own balls).
    - `speed_range`: the incoming shots' speeds in m/s, `(low, high)`, drawn uniformly; at
      most 20, the fastest ball the table is built for.
    - `serve_x_range`: where along the table an incoming ball starts, `(low, high)` in m,
      seen from the goal under fire; within [-0.1, 0.48275].
    - `serve_y_range`: where across the table an incoming ball starts, `(low, high)` in m;
      within [-0.32275, 0.32275].
    - `bank_share`: the share of the incoming shots aimed off a side wall, in [0, 1].
    - `bank_aim`: how the banked incoming shots are aimed: `"model"` at the middle of the
      mouth allowing for the simulated wall's flattening, `"mirror"` by equal angles, as a
      player aims.
    - `double_bank_share`: the share of the incoming shots aimed off both side walls, in
      [0, 1]; with `bank_share` at most 1.
    - `beside_mouth`: how far beyond each post (m, in [0, 0.1]) straight, mirrored and double
      incoming shots may be aimed.
    - `rebound_share`: the share of the incoming balls that come back off the own defence, in
      [0, 1].

    The other arguments are those every environment takes, described under
    [FoosballEnv][foosball_gym.envs.base.FoosballEnv]. Score has no opponent:
    `opponent_prismatic_only` takes only `False`.

    ## Version History
    - v0: first version.
    - v0, physics revision 2: the faithful table (the documentation's "The simulated table");
      `control_hz` replaces `substeps`.
    - v0: `serve_x_range`, `serve_y_range` and `bank_share`, as Block's.
    - v0: `bank_aim`, `double_bank_share`, `beside_mouth` and `rebound_share`, as Block's.
    - v0: the options are the class's keyword arguments; `opponent`, which Score took only
      as `None`, is no longer one.
    - v0: what a real table varies, off by default (episodes as before, seed for seed):
      `drive_speed_range`, `drive_accel_range`, `slide_offset_range`, `angle_offset_range`,
      `rod_angle_noise`, and `camera_noise`'s `latency_jitter_s`.
    - v0: `safety_layer`, on by default with `estimated_state`: an environment on estimated
      state plays like `foosball play`, its targets shaped by the real table's safety layer.
    - v0: `obstacle_share`, 1 by default (episodes as before, seed for seed).
    - v0: `shut_lane_share`, 0 by default (episodes as before, seed for seed).
    """

    # The authors' scoring tasks regularise the action.
    defaults: ClassVar[SharedOptions] = SharedOptions(action_regularisation_weight=0.5)

    def __init__(
        self,
        *,
        ball_start: Literal["resting", "incoming"] = "resting",
        obstacles: bool = False,
        obstacle_share: float = 1.0,
        shut_lane_share: float = 0.0,
        speed_range: tuple[float, float] = (3.0, 7.0),
        serve_x_range: tuple[float, float] = (0.0, 0.4),
        serve_y_range: tuple[float, float] = (-0.3, 0.3),
        bank_share: float = 0.0,
        double_bank_share: float = 0.0,
        bank_aim: Literal["model", "mirror"] = "model",
        beside_mouth: float = 0.0,
        rebound_share: float = 0.0,
        **shared: Unpack[EnvOptions],
    ) -> None:
        super().__init__(
            ScoreTask(
                ball_start=ball_start,
                obstacles=obstacles,
                obstacle_share=obstacle_share,
                shut_lane_share=shut_lane_share,
                speed_range=speed_range,
                serve_x_range=serve_x_range,
                serve_y_range=serve_y_range,
                bank_share=bank_share,
                double_bank_share=double_bank_share,
                bank_aim=bank_aim,
                beside_mouth=beside_mouth,
                rebound_share=rebound_share,
            ),
            **shared,
        )
