"""Score: the home keeper puts the ball into the away goal, from rest or from a shot, with
or without still obstacles in the way."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import numpy as np

from foosball_gym import table
from foosball_gym.policies.aiming import clearance
from foosball_gym.policies.scripted import ScriptedTeam
from foosball_gym.policy_io.observations import check_flag
from foosball_gym.policy_io.task import Layout
from foosball_gym.tasks.base import GAP_Y, REACH_X, Start, Task, figurine_at_ball
from foosball_gym.tasks.serves import Shots, check_choice, check_share, resting_in_front_of

BALL_STARTS = ("resting", "incoming")
OBSTACLES = ("away_keeper", "away_defense", "away_offense")
# A quarter turn holds a rod's figurines level, their soles well above the ball.
SPUN_UP = float(np.pi / 2)
# Redraws for a shut lane before the last draw is kept: a straight lane is open for about
# a third of the resting balls, so 50 open ones in a row come about once in 10^22 resets.
MAX_REDRAWS = 50


def straight_lane_open(start: Start) -> bool:
    """Whether a straight kick from where a resting ball starts passes every standing
    obstacle and goes in, as the aiming keeper judges it."""
    rods = (table.rod(name) for name in OBSTACLES)
    blockers = [
        (rod.x, rod.figurine_y(slide))
        for rod, slide, spin in zip(rods, start.slide[1:], start.spin[1:])
        if spin == 0.0
    ]
    x, y = start.ball_position
    return clearance(float(x), float(y), 0.0, blockers) > 0.0


class ScoreTask(Task):
    """A goal with the home keeper; success is scoring one."""

    reset_options = ("ball_position", "ball_velocity", "obstacle_positions")

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
        bank_aim: str = "model",
        beside_mouth: float = 0.0,
        rebound_share: float = 0.0,
    ) -> None:
        self.ball_start = check_choice("ball_start", ball_start, BALL_STARTS)
        self.obstacles = check_flag("obstacles", obstacles)
        self.obstacle_share = check_share("obstacle_share", obstacle_share)
        if self.obstacle_share != 1.0 and not self.obstacles:
            raise ValueError(
                f"obstacle_share {obstacle_share!r} needs obstacles=True: it is the chance that "
                "each obstacle rod stands in the ball's way"
            )
        self.shut_lane_share = check_share("shut_lane_share", shut_lane_share)
        if self.shut_lane_share and not (self.obstacles and ball_start == "resting"):
            raise ValueError(
                f"shut_lane_share {shut_lane_share!r} needs obstacles=True and "
                "ball_start='resting': it is the chance that a resting ball's straight lane "
                "to the goal is shut by a standing figurine"
            )
        self.shots = Shots.checked(
            speed_range,
            serve_x_range,
            serve_y_range,
            bank_share,
            double_bank_share,
            bank_aim,
            beside_mouth,
            rebound_share,
        )
        self.extras = OBSTACLES if self.obstacles else ()
        self.layout = Layout(controlled=("home_keeper",), joints="both", static=self.extras)

    def sample_start(
        self,
        rng: np.random.Generator,
        ball_position=None,
        ball_velocity=None,
        options: dict[str, Any] | None = None,
    ) -> Start:
        start = self._sample_start(rng, ball_position, ball_velocity, options)
        placed = ball_position is not None or (options or {}).get("obstacle_positions") is not None
        # No draw at a share of 0, so that the task's own episodes stay as they were.
        if not self.shut_lane_share or placed or rng.random() >= self.shut_lane_share:
            return start
        for _ in range(MAX_REDRAWS):
            if not straight_lane_open(start):
                break
            start = self._sample_start(rng, None, ball_velocity, options)
        return start

    def _sample_start(
        self,
        rng: np.random.Generator,
        ball_position=None,
        ball_velocity=None,
        options: dict[str, Any] | None = None,
    ) -> Start:
        options = options or {}
        if self.ball_start == "resting":
            position, velocity = resting_in_front_of(rng, table.HOME), (0.0, 0.0)
        else:
            position, velocity = self.shots.start(rng)
        if ball_position is not None:
            position = ball_position
            if self.ball_start == "incoming":
                velocity = self.shots.aim(rng, position, table.HOME)
        if ball_velocity is not None:
            velocity = ball_velocity
        slide = [0.0]
        spin = [0.0]
        if self.obstacles:
            given = options.get("obstacle_positions")
            slide += self._obstacle_positions(rng, given)
            # No draw at a share of 1, so that the task's own episodes stay as they were.
            standing = (
                [True] * len(OBSTACLES)
                if self.obstacle_share == 1.0
                else list(rng.random(len(OBSTACLES)) < self.obstacle_share)
            )
            spin += [0.0 if up else SPUN_UP for up in standing]
            if given is not None:
                # The game slides a figurine that would start inside the ball; one the user
                # placed stays where it was put, so the ball may not start against it.
                self._check_clear(
                    [s for s, up in zip(slide[1:], standing) if up],
                    position,
                    [n for n, up in zip(OBSTACLES, standing) if up],
                )
        elif options.get("obstacle_positions") is not None:
            raise ValueError("obstacle_positions needs obstacles=True")
        return Start(slide, spin, position, velocity)

    @staticmethod
    def _obstacle_positions(rng: np.random.Generator, given: Any) -> list[float]:
        rods = [table.rod(name) for name in OBSTACLES]
        if given is None:
            return [float(rng.uniform(-r.slide_limit, r.slide_limit)) for r in rods]
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

    @staticmethod
    def _check_clear(
        slides: list[float], ball: tuple[float, float], names: Sequence[str] = OBSTACLES
    ) -> None:
        for name, slide in zip(names, slides):
            rod = table.rod(name)
            k = figurine_at_ball(rod, slide, ball)
            if k is not None:
                fig_y = rod.figurine_y(slide)[k]
                raise ValueError(
                    f"ball_position {tuple(ball)} lies against a figurine of {name} (at y = "
                    f"{fig_y:.4f} with obstacle_positions' {slide}); the ball's centre must be "
                    f"at least {REACH_X:.5f} m from the rod along x or {GAP_Y:.5f} m from each "
                    "of its figurines along y"
                )

    def served_shots(self) -> Shots | None:
        return self.shots if self.ball_start == "incoming" else None

    def serve_options(self) -> dict[str, Any]:
        own = super().serve_options()
        if not self.obstacles:
            return own
        shares = {"obstacle_share": self.obstacle_share}
        if self.ball_start == "resting":
            shares["shut_lane_share"] = self.shut_lane_share
        return {**own, **shares}

    def set_serves(self, **options: Any) -> None:
        """As :meth:`Task.set_serves`, and with obstacles ``obstacle_share`` (and, the ball at
        rest, ``shut_lane_share``) too."""
        names = [n for n in ("obstacle_share", "shut_lane_share") if n in options]
        if not names:
            super().set_serves(**options)
            return
        if not self.obstacles:
            raise ValueError(f"{names[0]} needs obstacles=True")
        if "shut_lane_share" in names and self.ball_start != "resting":
            raise ValueError("shut_lane_share needs ball_start='resting'")
        # Every value checked before any changes.
        shares = {n: check_share(n, options.pop(n)) for n in names}
        if options:
            super().set_serves(**options)
        for name, share in shares.items():
            setattr(self, name, share)

    def scripted_policy(self, names: Sequence[str], precise_state: bool = True) -> ScriptedTeam:
        """The scripted keeper, deflecting incoming balls to the goal (or striking them where
        it cannot: blocked ones trickle out of reach) and aiming past the obstacles.

        A deflection needs the ball's path to a millimetre: on an estimated state it scored
        10 % of incoming balls where the volley scores 49.5 % (200 shots each), so there the
        keeper volleys."""
        return ScriptedTeam(
            names, self.layout.controlled, "both", volley=True, aim=True, deflect=precise_state
        )

    def success(self, goals_for: int, goals_against: int) -> bool:
        return goals_for > 0
