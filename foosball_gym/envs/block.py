"""Foosball-Block-v0: the home keeper blocks shots at its goal."""

from __future__ import annotations

from typing import Literal

from typing_extensions import Unpack

from foosball_gym.envs.base import FoosballEnv
from foosball_gym.envs.options import EnvOptions
from foosball_gym.tasks.block import BlockTask


class BlockEnv(FoosballEnv):
    """Block shots with the home keeper.

    ## Description
    A ball is shot from the away half towards the home goal (x = -0.60); the home keeper slides
    along its rod to stop it. Only the keeper is in play; its rod does not turn.

    ## Action Space
    `Box(-1, 1, (1,), float32)`: the keeper's prismatic target, scaled to ±0.123 m.

    ## Observation Space
    `Box(6,)` float32, SI units, world frame:

    | index | name | unit |
    |---|---|---|
    | 0 | home_keeper_slide_pos | m |
    | 1 | home_keeper_slide_vel | m/s |
    | 2 | ball_x | m |
    | 3 | ball_y | m |
    | 4 | ball_vx | m/s |
    | 5 | ball_vy | m/s |

    With `joint_velocities=False` index 1 is left out. With `observe_figurines=True` the
    keeper's joint values are replaced by its figurine's centre (x, y) and its velocity.
    `env.unwrapped.obs_builder.names` always lists the entries.

    ## Rewards
    `-goal_reward` (-1000) when a goal is conceded, `-out_of_table_penalty` (-1000) when
    the ball leaves the table; no shaping by default, as in the authors' blocking task.
    Every term is in `info["reward_<name>"]`.

    ## Starting State
    Keeper centred. The ball starts at a uniform point of `serve_x_range` x `serve_y_range`
    and is shot at a uniform point of the home goal mouth (a goal if nothing stops it), at a
    speed drawn from `speed_range`. A share `bank_share` of the shots is aimed off a side
    wall instead, at the middle of the mouth, allowing for how the simulated wall flattens the
    path (with the keeper out of the way, 299 of 300 such shots score); with
    `bank_aim="mirror"` they are aimed as a player aims them, by equal angles in and out. A
    share `double_bank_share` is aimed off both side walls, as a player aims. `beside_mouth`
    widens where straight, mirrored and double shots are aimed beyond each post: those meet
    the end wall beside the goal and come back. A share `rebound_share` of the balls comes back
    off the keeper's own defence instead: from just in front of the defence rod, at any y, at
    a quarter of a speed from `speed_range` (the shot's speed after the keeper's and the
    defence's figurines, restitution 0.5 each), aimed at the mouth as widened.
    What a real opponent plays, and what `builtin:block` was trained on, is the distribution
    of any shot ("Shots a real opponent plays" in the environments' documentation):
    `speed_range=(2, 12), serve_x_range=(-0.1, 0.45), serve_y_range=(-0.32275, 0.32275),
    bank_share=0.3, bank_aim="mirror", double_bank_share=0.1, beside_mouth=0.03,
    rebound_share=0.1`.
    `reset(options={"ball_position": (x, y), "ball_velocity": (vx, vy)})` places the ball
    exactly (at most 20 m/s); with only a position, the shot is aimed from there.

    ## Episode End
    Terminated on a goal (either way) or when the ball leaves the table; truncated after 90
    steps (1.5 s) by the registered `TimeLimit`. `info["is_success"]`: no goal conceded
    so far. `info["goal"]`: +1 scored, -1 conceded, 0 none.

    ## Arguments
    - `speed_range`: the shots' speeds in m/s, `(low, high)`, drawn uniformly; at most 20,
      the fastest ball the table is built for.
    - `serve_x_range`: where along the table the ball starts, `(low, high)` in m, seen from
      the goal under fire; within [-0.1, 0.48275].
    - `serve_y_range`: where across the table the ball starts, `(low, high)` in m; within
      [-0.32275, 0.32275].
    - `bank_share`: the share of the shots aimed off a side wall, in [0, 1].
    - `bank_aim`: how those are aimed: `"model"` at the middle of the mouth allowing for the
      simulated wall's flattening, `"mirror"` by equal angles, as a player aims.
    - `double_bank_share`: the share of the shots aimed off both side walls, in [0, 1];
      with `bank_share` at most 1.
    - `beside_mouth`: how far beyond each post (m, in [0, 0.1]) straight, mirrored and double
      shots may be aimed.
    - `rebound_share`: the share of the balls that come back off the own defence, in [0, 1].

    The other arguments are those every environment takes, described under
    [FoosballEnv][foosball_gym.envs.base.FoosballEnv]. Block has no opponent:
    `opponent_prismatic_only` takes only `False`; its keeper does not turn: `angle_offset_range`
    takes only `None`, `rod_angle_noise` only 0.

    ## Version History
    - v0: first version.
    - v0, physics revision 2: the faithful table (the documentation's "The simulated table");
      `control_hz` replaces `substeps`.
    - v0: `serve_x_range`, `serve_y_range` and `bank_share`; their defaults serve what
      v0 always served, seed for seed.
    - v0: the options are the class's keyword arguments; `opponent`, which Block took only
      as `None`, is no longer one.
    - v0: `bank_aim`, `double_bank_share`, `beside_mouth` and `rebound_share`; their defaults
      serve what v0 always served, seed for seed.
    - v0: what a real table varies, off by default (episodes as before, seed for seed):
      `drive_speed_range`, `drive_accel_range`, `slide_offset_range`, `angle_offset_range`,
      `rod_angle_noise`, and `camera_noise`'s `latency_jitter_s`.
    - v0: `safety_layer`, on by default with `estimated_state`: an environment on estimated
      state plays like `foosball play`, its targets shaped by the real table's safety layer.
    """

    def __init__(
        self,
        *,
        speed_range: tuple[float, float] = (2.0, 7.0),
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
            BlockTask(
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
