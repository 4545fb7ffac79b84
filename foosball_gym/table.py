"""The Ullrich "Home" table of the paper as plain numbers (SPEC §1).

One source of truth for the URDF generator, the simulator, the environments, the scripted
policies, the Kalman filter's walls and the hardware limits. Nothing here imports a simulator.

World frame: origin at the centre of the playing surface, z up, the home team defends the goal
at x = -0.60 and attacks towards +x. The away team is the home team turned by 180 degrees about
the z axis (point symmetry), so a joint value means the same thing from either side.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

HOME = "home"
AWAY = "away"
TEAMS = (HOME, AWAY)

# Playing field and walls.
FIELD_HALF_LENGTH = 0.60  # x
FIELD_HALF_WIDTH = 0.34  # y
WALL_HEIGHT = 0.15  # above the surface; a rolling ball never gets near it
WALL_THICKNESS = 0.02
SURFACE_THICKNESS = 0.02

# Goals. The end wall's middle is the goal line.
GOAL_HALF_WIDTH = 0.1025
GOAL_HEIGHT = 0.080
GOAL_LINE_X = 0.61725
END_WALL_THICKNESS = 2 * (GOAL_LINE_X - FIELD_HALF_LENGTH)
POCKET_BACK_X = 0.683

# A ball whose centre rises this far above the surface has left the table.
OUT_OF_TABLE_HEIGHT = 0.10

# Rods.
ROD_HEIGHT = 0.083  # axis above the surface
ROD_RADIUS = 0.008
ROD_LENGTH = 1.30  # reaches through both side walls at every slide position
ROD_MASS = 0.45
CARRIAGE_MASS = 0.25  # what moves along the rail besides the rod: carriage, revolute motor

# Figurines hang from the rod: foot 0.011 m above the surface, head 0.040 m above the axis.
FIGURINE_SIZE = (0.030, 0.034, 0.112)  # x, y, z
FIGURINE_FOOT_HEIGHT = 0.011
FIGURINE_HEAD_ABOVE_AXIS = 0.040
FIGURINE_CENTRE_BELOW_AXIS = FIGURINE_SIZE[2] / 2 - FIGURINE_HEAD_ABOVE_AXIS
FIGURINE_FOOT_BELOW_AXIS = ROD_HEIGHT - FIGURINE_FOOT_HEIGHT
FIGURINE_MASS = 0.025

# Drives (per rod).
SLIDE_MAX_FORCE = 70.0  # N
SLIDE_MAX_SPEED = 4.0  # m/s
SPIN_MAX_TORQUE = 1.41  # N m
SPIN_MAX_SPEED = 100 * math.pi  # rad/s
SPIN_LIMIT = 2 * math.pi  # rad, two revolutions in total by the rules

# Ball.
BALL_RADIUS = 0.01725
BALL_MASS = 0.022
BALL_RESTITUTION = 0.5
# Bullet has one Coulomb coefficient per body; the sliding (dynamic) value is the one that
# matters for a ball that mostly rolls and slides, so the static one is kept only for reference.
BALL_FRICTION_STATIC = 0.2
BALL_FRICTION = 0.1
BALL_LINEAR_DAMPING = 0.01
BALL_MAX_SPEED = 15.0

SURFACE_FRICTION_STATIC = 0.7
SURFACE_FRICTION = 0.5
SURFACE_RESTITUTION = 0.5  # the walls and the goal pockets are of the same material
FIGURINE_FRICTION = 0.2
FIGURINE_RESTITUTION = 0.5

# What a simulation step reports about goals (seen from the home side).
NO_GOAL = 0
HOME_SCORED = 1  # the ball crossed the away goal line (x > 0)
AWAY_SCORED = -1

# Timing.
PHYSICS_HZ = 240
CONTROL_HZ = 60


@dataclass(frozen=True)
class Rod:
    """One rod: where it sits, what hangs from it, how far it slides.

    Attributes:
        team: ``"home"`` or ``"away"``.
        role: ``"keeper"``, ``"defense"``, ``"midfield"`` or ``"offense"``.
        x: world x of the rod axis.
        figurine_offsets: y offsets of the figurines from the rod centre, in the rod's frame.
        slide_limit: the prismatic joint moves in ``[-slide_limit, slide_limit]``.
    """

    team: str
    role: str
    x: float
    figurine_offsets: tuple[float, ...]
    slide_limit: float

    @property
    def name(self) -> str:
        return f"{self.team}_{self.role}"

    @property
    def slide_joint(self) -> str:
        return f"{self.name}_slide"

    @property
    def spin_joint(self) -> str:
        return f"{self.name}_spin"

    @property
    def direction(self) -> float:
        """+1 for home, -1 for away: the away frame is turned by 180 degrees about z."""
        return 1.0 if self.team == HOME else -1.0

    def figurine_y(self, slide: float) -> tuple[float, ...]:
        """World y of each figurine for a prismatic joint value."""
        d = self.direction
        return tuple(d * (slide + off) for off in self.figurine_offsets)


def _rod(team: str, role: str, x: float, offsets: tuple[float, ...], limit: float) -> Rod:
    return Rod(team=team, role=role, x=x, figurine_offsets=offsets, slide_limit=limit)


_KEEPER = ((0.0,), 0.1230)
_DEFENSE = ((-0.1235, 0.1235), 0.1790)
_OFFENSE = ((-0.184, 0.0, 0.184), 0.1185)
_MIDFIELD = ((-0.241, -0.1205, 0.0, 0.1205, 0.241), 0.0615)

# From the home goal to the away goal.
RODS: tuple[Rod, ...] = (
    _rod(HOME, "keeper", -0.52200, *_KEEPER),
    _rod(HOME, "defense", -0.37295, *_DEFENSE),
    _rod(AWAY, "offense", -0.22372, *_OFFENSE),
    _rod(HOME, "midfield", -0.07469, *_MIDFIELD),
    _rod(AWAY, "midfield", +0.07469, *_MIDFIELD),
    _rod(HOME, "offense", +0.22372, *_OFFENSE),
    _rod(AWAY, "defense", +0.37295, *_DEFENSE),
    _rod(AWAY, "keeper", +0.52200, *_KEEPER),
)
ROD_BY_NAME: dict[str, Rod] = {rod.name: rod for rod in RODS}

# A team's rods in the order a team sees them from its own goal: keeper, defense, midfield,
# offense. The environments order joints this way so the mirror of a home observation is the
# away observation with the same layout.
ROLES = ("keeper", "defense", "midfield", "offense")


def team_rods(team: str) -> tuple[Rod, ...]:
    """A team's four rods, keeper first."""
    if team not in TEAMS:
        raise ValueError(f"unknown team {team!r}; allowed: {', '.join(TEAMS)}")
    return tuple(ROD_BY_NAME[f"{team}_{role}"] for role in ROLES)


def rod(name: str) -> Rod:
    """The rod called ``name`` (e.g. ``"home_keeper"``), with a clear error otherwise."""
    try:
        return ROD_BY_NAME[name]
    except KeyError:
        raise ValueError(f"unknown rod {name!r}; allowed: {', '.join(ROD_BY_NAME)}") from None


def in_goal_opening(y: float) -> bool:
    return abs(y) <= GOAL_HALF_WIDTH
