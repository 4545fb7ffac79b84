"""Foosball-Block-v0: the home keeper blocks shots at its goal."""

from __future__ import annotations

from typing import Any

from foosball_gym import table as T
from foosball_gym.envs.base import FoosballEnv, Layout, Start
from foosball_gym.envs.common import check_range, make_options, make_weights, shot_at_goal


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
    ``env.unwrapped.obs_builder.names`` always lists the indices.

    ## Rewards
    ``-goal_reward`` (default -1000) when a goal is conceded, ``-out_of_table_penalty`` when
    the ball leaves the table upwards; shaping terms (``ball_to_goal_weight``,
    ``figurine_to_ball_weight``, ``action_regularisation_weight``) are off by default, as in
    the paper's blocking task. Every term is in ``info["reward_<name>"]``.

    ## Starting State
    Keeper centred. Ball at x ~ U(0, 0.4), y ~ U(-0.3, 0.3), shot at ``speed`` ~ U(2, 7) m/s
    at a uniform point of the home goal mouth (a goal if nothing stops it).
    ``reset(options={"ball_position": (x, y), "ball_velocity": (vx, vy)})`` places the ball
    exactly; with only a position the shot is aimed from there.

    ## Episode End
    Terminated on a goal (either way) or when the ball leaves the table; truncated after 90
    steps (1.5 s) by the registered ``TimeLimit``. ``info["is_success"]``: no goal conceded
    so far. ``info["goal"]``: +1 scored, -1 conceded, 0 none.

    ## Arguments
    ``speed_range`` (m/s), the reward weights and ``shaping``/``gamma`` (see
    ``foosball_gym.envs.rewards``), ``joint_velocities``, ``observe_figurines``,
    ``render_mode`` (``"rgb_array"``, ``"human"``), ``render_width``, ``render_height``,
    ``physics_hz``, ``substeps``.

    ## Version History
    - v0: first version.
    """

    def __init__(
        self,
        *,
        speed_range: tuple[float, float] = (2.0, 7.0),
        goal_reward: float = 1000.0,
        out_of_table_penalty: float = 1000.0,
        ball_to_goal_weight: float = 0.0,
        figurine_to_ball_weight: float = 0.0,
        action_regularisation_weight: float = 0.0,
        shaping: str = "difference",
        gamma: float = 0.99,
        joint_velocities: bool = True,
        observe_figurines: bool = False,
        render_mode: str | None = None,
        render_width: int = 320,
        render_height: int = 180,
        physics_hz: int = T.PHYSICS_HZ,
        substeps: int = T.PHYSICS_HZ // T.CONTROL_HZ,
    ) -> None:
        self.speed_range = check_range("speed_range", speed_range)
        super().__init__(
            Layout(controlled=("home_keeper",), joints="slide"),
            weights=make_weights(
                goal_reward,
                out_of_table_penalty,
                ball_to_goal_weight,
                figurine_to_ball_weight,
                action_regularisation_weight,
                shaping,
                gamma,
            ),
            observation=make_options(joint_velocities, False, observe_figurines),
            render_mode=render_mode,
            render_width=render_width,
            render_height=render_height,
            physics_hz=physics_hz,
            substeps=substeps,
        )

    def _sample_start(self, ball_position, ball_velocity, options: dict[str, Any]) -> Start:
        rng = self.np_random
        if ball_position is None:
            ball_position = (float(rng.uniform(0.0, 0.4)), float(rng.uniform(-0.3, 0.3)))
        if ball_velocity is None:
            ball_velocity = shot_at_goal(rng, ball_position, self.speed_range, T.HOME)
        return Start([0.0], [0.0], ball_position, ball_velocity)

    def _is_success(self) -> bool:
        return self._goals_against == 0
