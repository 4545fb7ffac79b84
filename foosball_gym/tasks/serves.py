"""Ball serves the tasks share, and the checks of their options."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from foosball_gym import table

# A shot no faster than the table is built for (the tasks' MAX_BALL_SPEED).
SHOT_SPEED_LIMITS = (1e-3, table.RESOLVED_SPEED)
# The spec's resting ball: 0.497 m from the centre line, +-5 mm, in front of a keeper.
REST_X, REST_X_JITTER, REST_Y = 0.497, 0.005, 0.1


def check_range(name: str, value: Any, low: float, high: float) -> tuple[float, float]:
    """A (low, high) pair within [low, high] bounds, or a ValueError saying what is allowed."""
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (low, high), got {value!r}") from None
    if not (low <= lo <= hi <= high):
        raise ValueError(f"{name} must satisfy {low} <= low <= high <= {high}, got {value!r}")
    return lo, hi


def check_choice(name: str, value: str, allowed: tuple[str, ...]) -> str:
    if value not in allowed:
        raise ValueError(f"unknown {name} {value!r}; allowed: {', '.join(allowed)}")
    return value


def shot_at_goal(
    rng: np.random.Generator,
    position: tuple[float, float],
    speed_range: tuple[float, float],
    defender: str,
    half: float = table.GOAL_MOUTH_HALF,
) -> tuple[float, float]:
    """Velocity of a shot from ``position`` at a uniform point of ``defender``'s goal mouth,
    taken ``half`` (m) either side of its middle."""
    goal_x = -table.GOAL_LINE_X if defender == table.HOME else table.GOAL_LINE_X
    target_y = float(rng.uniform(-half, half))
    speed = float(rng.uniform(*speed_range))
    dx, dy = goal_x - position[0], target_y - position[1]
    norm = math.hypot(dx, dy)
    return speed * dx / norm, speed * dy / norm


def resting_in_front_of(rng: np.random.Generator, team: str) -> tuple[float, float]:
    """A ball position at rest in front of ``team``'s keeper."""
    x = REST_X + float(rng.uniform(-REST_X_JITTER, REST_X_JITTER))
    y = float(rng.uniform(-REST_Y, REST_Y))
    return (-x, y) if team == table.HOME else (x, y)


# Steeper bank shots are not served: they hardly move towards the goal.
BANK_MAX_ANGLE = 70.0
# Bank shots bounce in front of this x (defender's frame): a bounce behind the keeper's rod
# would meet the end wall beside the goal, not the mouth.
BANK_LAST_BOUNCE_X = -0.45
# Bank shots meet the goal line a median 8.5 mm further towards their wall than this aim says,
# and within 2.2 cm of that for 90 % of them, 4 cm for 95 % (150 shots, keeper lifted): the
# bounce ends a little deeper than the wall, and a slow ball curls as its spin settles. So they
# are aimed at the middle of the mouth, allowing for the offset.
BANK_AIM_HALF = table.GOAL_MOUTH_HALF - 0.03
BANK_AIM_OFFSET = 0.0085
SERVE_X_LIMITS = (-0.1, table.BALL_LIMIT_X - 0.1)
# The serve options a run may change from one episode to the next (a curriculum), by the
# Shots field each sets.
SERVE_FIELDS = {
    "speed_range": "speed_range",
    "serve_x_range": "x_range",
    "serve_y_range": "y_range",
    "bank_share": "bank_share",
    "double_bank_share": "double_bank_share",
    "beside_mouth": "beside_mouth",
    "rebound_share": "rebound_share",
}
SERVE_Y_LIMITS = (-table.BALL_LIMIT_Y, table.BALL_LIMIT_Y)


def within(value: Any, limit: float) -> float:
    """``value`` as a float in [0, ``limit``], NaN where it is none (a bool, text, out of
    range): what an option's check turns into its own error."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        return math.nan
    return number if not isinstance(value, bool) and 0.0 <= number <= limit else math.nan


def check_share(name: str, value: Any) -> float:
    """A fraction in [0, 1], or a ValueError saying what is allowed."""
    try:
        share = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number in [0, 1], got {value!r}") from None
    if not 0.0 <= share <= 1.0:
        raise ValueError(f"{name} must be a number in [0, 1], got {value!r}")
    return share


BANK_AIMS = ("model", "mirror")
# A ball that meets a figurine of the defence keeps about this share of its speed: the
# figurines' restitution (0.5) head-on, more at a glancing touch.
REBOUND_SPEED_SHARE = 0.25
# Where a ball coming back off the own defence starts (defender's frame): just goal-side of
# the defence rod's figurines, at any y their slides reach.
REBOUND_X = table.rod(f"{table.HOME}_defense").x - 0.5 * table.FIGURINE_SIZE[0] - table.BALL_RADIUS
REBOUND_X_JITTER = 0.02
# How far beside the mouth (m, beyond each post's line) a shot may be aimed: wider ones no
# longer come back along the end wall to the mouth.
BESIDE_MOUTH_LIMIT = 0.1


@dataclass(frozen=True)
class Shots:
    """Shots at a goal: where they start, how fast they go, and how many bank off a wall.

    Positions are in the frame of a defender at the home goal (x = -0.617): ``x_range`` and
    ``y_range`` bound a uniform start, ``speed_range`` a uniform speed. A share ``bank_share``
    of the shots is aimed off a side wall (either, at random), a share ``double_bank_share``
    off both; the others go straight. A straight shot goes at a uniform point of the mouth
    widened by ``beside_mouth`` beyond each post (a shot beside the mouth meets the end wall
    beside the goal). A bank is aimed at the middle of the mouth allowing for how the
    simulated wall flattens the path (``bank_aim="model"``), or as a player aims it, by equal
    angles in and out, at the same widened mouth (``"mirror"``). A share ``rebound_share`` of
    the balls instead comes back off the defender's own defence: from just in front of the
    defence rod at a uniform y, at a uniform point of the widened mouth, at
    ``REBOUND_SPEED_SHARE`` of a speed from ``speed_range``. With every new share and
    ``beside_mouth`` at 0 the draws are those of the plain shot, so seeded serves stay what
    they were.
    """

    speed_range: tuple[float, float] = (2.0, 7.0)
    x_range: tuple[float, float] = (0.0, 0.4)
    y_range: tuple[float, float] = (-0.3, 0.3)
    bank_share: float = 0.0
    double_bank_share: float = 0.0
    bank_aim: str = "model"
    beside_mouth: float = 0.0
    rebound_share: float = 0.0

    @classmethod
    def checked(
        cls,
        speed_range: Any,
        x_range: Any,
        y_range: Any,
        bank_share: Any,
        double_bank_share: Any = 0.0,
        bank_aim: Any = "model",
        beside_mouth: Any = 0.0,
        rebound_share: Any = 0.0,
    ) -> Shots:
        """Shots from user options, or a ValueError naming the bad one and what is allowed."""
        bank = check_share("bank_share", bank_share)
        double = check_share("double_bank_share", double_bank_share)
        if bank + double > 1.0:
            raise ValueError(
                f"bank_share + double_bank_share must be at most 1, got {bank} + {double}"
            )
        beside = within(beside_mouth, BESIDE_MOUTH_LIMIT)
        if math.isnan(beside):
            raise ValueError(
                f"beside_mouth must be a number in [0, {BESIDE_MOUTH_LIMIT}] m, "
                f"got {beside_mouth!r}"
            )
        return cls(
            check_range("speed_range", speed_range, *SHOT_SPEED_LIMITS),
            check_range("serve_x_range", x_range, *SERVE_X_LIMITS),
            check_range("serve_y_range", y_range, *SERVE_Y_LIMITS),
            bank,
            double,
            check_choice("bank_aim", bank_aim, BANK_AIMS),
            beside,
            check_share("rebound_share", rebound_share),
        )

    def options(self) -> dict[str, Any]:
        """The serve options, by the names the environments take, that give these shots."""
        return {name: getattr(self, attr) for name, attr in SERVE_FIELDS.items()}

    def changed(self, **options: Any) -> Shots:
        """These shots with some serve options changed, checked as :meth:`checked` checks
        them; a ValueError names an option no serve has, with those that are."""
        unknown = sorted(set(options) - set(SERVE_FIELDS))
        if unknown:
            raise ValueError(
                f"unknown serve option {unknown[0]!r}; allowed: {', '.join(SERVE_FIELDS)}"
            )
        given = {**self.options(), **options}
        return Shots.checked(
            given["speed_range"],
            given["serve_x_range"],
            given["serve_y_range"],
            given["bank_share"],
            given["double_bank_share"],
            self.bank_aim,
            given["beside_mouth"],
            given["rebound_share"],
        )

    def start(
        self, rng: np.random.Generator, defender: str = table.HOME
    ) -> tuple[tuple[float, float], tuple[float, float]]:
        """A start position and the shot from it at ``defender``'s goal."""
        if self.rebound_share and rng.uniform() < self.rebound_share:
            return self.rebound(rng, defender)
        position = (float(rng.uniform(*self.x_range)), float(rng.uniform(*self.y_range)))
        if defender == table.AWAY:
            position = (-position[0], -position[1])
        return position, self.aim(rng, position, defender)

    def rebound(
        self, rng: np.random.Generator, defender: str = table.HOME
    ) -> tuple[tuple[float, float], tuple[float, float]]:
        """A ball coming back off ``defender``'s own defence towards its goal."""
        x = REBOUND_X + float(rng.uniform(-REBOUND_X_JITTER, REBOUND_X_JITTER))
        y = float(rng.uniform(-table.BALL_LIMIT_Y, table.BALL_LIMIT_Y))
        target_y = self._target(rng)
        speed = REBOUND_SPEED_SHARE * float(rng.uniform(*self.speed_range))
        dx, dy = -table.GOAL_LINE_X - x, target_y - y
        norm = math.hypot(dx, dy)
        vx, vy = speed * dx / norm, speed * dy / norm
        if defender == table.AWAY:
            return (-x, -y), (-vx, -vy)
        return (x, y), (vx, vy)

    def _target(self, rng: np.random.Generator) -> float:
        half = table.GOAL_MOUTH_HALF + self.beside_mouth
        return float(rng.uniform(-half, half))

    def aim(
        self, rng: np.random.Generator, position: tuple[float, float], defender: str
    ) -> tuple[float, float]:
        """The velocity of a shot from ``position`` at ``defender``'s goal mouth."""
        banks = self.bank_share + self.double_bank_share
        draw = rng.uniform() if banks else 1.0
        if draw >= banks:
            return self._straight(rng, position, defender)
        flip = 1.0 if defender == table.HOME else -1.0
        x, y = flip * position[0], flip * position[1]
        side = 1.0 if rng.uniform() < 0.5 else -1.0
        if draw >= self.bank_share:
            aimed = self._mirror(rng, x, y, side, walls=2)
        elif self.bank_aim == "mirror":
            aimed = self._mirror(rng, x, y, side, walls=1)
        else:
            aimed = self._modelled_bank(rng, x, y, side)
        if aimed is None:
            return self._straight(rng, position, defender)
        vx, vy = aimed
        return flip * vx, flip * vy

    def _straight(
        self, rng: np.random.Generator, position: tuple[float, float], defender: str
    ) -> tuple[float, float]:
        half = table.GOAL_MOUTH_HALF + self.beside_mouth
        return shot_at_goal(rng, position, self.speed_range, defender, half)

    def _modelled_bank(
        self, rng: np.random.Generator, x: float, y: float, side: float
    ) -> tuple[float, float] | None:
        """A bank off the wall at ``side`` aimed with the simulated wall's flattening, in the
        home defender's frame; None where neither wall takes it."""
        target_y = float(rng.uniform(-BANK_AIM_HALF, BANK_AIM_HALF))
        speed = float(rng.uniform(*self.speed_range))
        slope = bank_slope(x, y, target_y - side * BANK_AIM_OFFSET, side)
        if slope is None:
            side = -side  # that wall needs too steep a shot: bank off the other
            slope = bank_slope(x, y, target_y - side * BANK_AIM_OFFSET, side)
        if slope is None:
            return None
        norm = math.hypot(1.0, slope)
        return -speed / norm, side * speed * slope / norm

    def _mirror(
        self, rng: np.random.Generator, x: float, y: float, side: float, walls: int
    ) -> tuple[float, float] | None:
        """A shot off ``walls`` side walls (the first at ``side``) aimed as a player aims it:
        straight at the target's mirror image, in the home defender's frame; None where both
        first walls need a shot steeper than BANK_MAX_ANGLE."""
        target_y = self._target(rng)
        speed = float(rng.uniform(*self.speed_range))
        run = x + table.GOAL_LINE_X
        for first in (side, -side):
            wall = first * table.BALL_LIMIT_Y
            # Unfolded: the image over the first wall, or over the second and then the first.
            image = 2 * wall - target_y if walls == 1 else target_y + 4 * wall
            rise = image - y
            if run > 0 and math.degrees(math.atan2(abs(rise), run)) <= BANK_MAX_ANGLE:
                norm = math.hypot(run, rise)
                return -speed * run / norm, speed * rise / norm
        return None


def bank_slope(x: float, y: float, target_y: float, side: float) -> float | None:
    """|vy| / |vx| of a shot from (x, y) that meets the home goal line at ``target_y`` after
    one bounce off the side wall at ``side`` (+1 or -1); None where that takes a shot steeper
    than BANK_MAX_ANGLE or a bounce behind BANK_LAST_BOUNCE_X."""
    wall = side * table.BALL_LIMIT_Y
    run = x + table.GOAL_LINE_X
    to_wall, from_wall = abs(wall - y), abs(wall - target_y)

    def short(slope: float) -> float:
        # How far short of the goal line (along x) the path at ``slope`` meets target_y.
        return run - to_wall / slope - from_wall / (table.wall_bounce_slope_ratio(slope) * slope)

    low, high = 1e-3, math.tan(math.radians(BANK_MAX_ANGLE))
    if short(high) < 0.0:
        return None
    for _ in range(40):  # the shortfall grows with the slope: bisect
        mid = 0.5 * (low + high)
        low, high = (low, mid) if short(mid) >= 0.0 else (mid, high)
    if x - to_wall / high < BANK_LAST_BOUNCE_X:
        return None
    return high
