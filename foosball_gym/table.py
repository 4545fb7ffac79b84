"""The Ullrich "Home" table of the paper as plain numbers (docs/simulated-table.md).

One source of truth for the URDF generator, the simulator, the environments, the scripted
policies, the Kalman filter's walls and the hardware limits. Nothing here imports a simulator.

World frame: origin at the centre of the playing surface, z up, the home team defends the goal
at x = -0.60 and attacks towards +x. The away team is the home team turned by 180 degrees about
the z axis (point symmetry), so a joint value means the same thing from either side.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

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
FIGURINE_SIZE = (0.030, 0.034, 0.112)  # x, y, z: the overall box, what the camera sees
FIGURINE_FOOT_HEIGHT = 0.011
FIGURINE_HEAD_ABOVE_AXIS = 0.040
FIGURINE_CENTRE_BELOW_AXIS = FIGURINE_SIZE[2] / 2 - FIGURINE_HEAD_ABOVE_AXIS
FIGURINE_FOOT_BELOW_AXIS = ROD_HEIGHT - FIGURINE_FOOT_HEIGHT
FIGURINE_MASS = 0.025
# Where it meets the ball the authors' CAD figurine is a slim leg, not the overall box. Its
# cross-sections, as (height above the surface, x from, x to) in metres, from the sole up: at
# full thickness out to FIGURINE_LEG_FLAT_HALF_WIDTH either side along y, then narrowing to a
# point at FIGURINE_LEG_HALF_WIDTH. Above FIGURINE_LEG_TOP the figurine is the full box (a ball
# on the table reaches only 0.0345 m high).
FIGURINE_LEG_SECTIONS = (
    (0.011, -0.0020, 0.0024),
    (0.012, -0.0025, 0.0029),
    (0.017, -0.0045, 0.0048),
    (0.040, -0.0045, 0.0048),
)
FIGURINE_LEG_FLAT_HALF_WIDTH = 0.009
FIGURINE_LEG_HALF_WIDTH = 0.012
FIGURINE_LEG_TOP = FIGURINE_LEG_SECTIONS[-1][0]
# The simulated leg: the convex hull of these cross-sections (as above), each with rounded
# ends from FIGURINE_LEG_FLAT_HALF_WIDTH to FIGURINE_LEG_HALF_WIDTH.
FIGURINE_LEG_HULL = FIGURINE_LEG_SECTIONS

# The farthest any point of a figurine gets from its rod's axis (the sole's edge): a spinning
# rod reaches no further.
FIGURINE_REACH = math.hypot(
    FIGURINE_FOOT_BELOW_AXIS, max(-FIGURINE_LEG_HULL[0][1], FIGURINE_LEG_HULL[0][2])
)

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
BALL_LINEAR_DAMPING = 0.01
BALL_MAX_SPEED = 15.0
# Rolling resistance as a deceleration in units of g: a rolling ball slows by this times
# 9.81 m/s^2 (besides its linear damping). 0.01 stops a 1 m/s ball within about 5 m on a flat
# table; a worn ball or a dusty table rolls less far.
ROLLING_RESISTANCE = 0.01
# Where the ball's centre can be: against a side wall (y) or an end wall (x); and a ball whose
# centre is within GOAL_MOUTH_HALF of the middle crosses the goal line inside the mouth.
BALL_LIMIT_X = FIELD_HALF_LENGTH - BALL_RADIUS
BALL_LIMIT_Y = FIELD_HALF_WIDTH - BALL_RADIUS
GOAL_MOUTH_HALF = GOAL_HALF_WIDTH - BALL_RADIUS
# How far along x from a rod's axis a figurine's sole reaches a ball lying on the table: the
# sole swings FIGURINE_REACH from the axis and the ball's centre lies ROD_HEIGHT - BALL_RADIUS
# below it (a resting ball 0.065 m in front of a rod is not touched by a full swing).
FOOT_REACH_X = math.sqrt((FIGURINE_REACH + BALL_RADIUS) ** 2 - (ROD_HEIGHT - BALL_RADIUS) ** 2)


@dataclass(frozen=True)
class Material:
    """A contact material as the authors' model binds it: Coulomb friction and restitution."""

    static_friction: float
    dynamic_friction: float
    restitution: float


# The materials bound to the colliders in the authors' model (docs/simulated-table.md). Their
# engine combines two materials by averaging each coefficient; see :func:`combine`.
BALL_MATERIAL = Material(0.2, 0.1, 0.5)
TABLE_MATERIAL = Material(0.2, 0.1, 0.5)  # surface, walls, goal pockets
FIGURINE_MATERIAL = Material(0.2, 0.2, 0.5)


def combine(a: float, b: float) -> float:
    """How the authors' engine combines one coefficient of two materials in contact."""
    return (a + b) / 2


# The coefficients of each contact the ball makes. Bullet keeps one friction coefficient per
# body for sticking and sliding alike; a ball slides where friction matters (kicks, bounces),
# so the dynamic value is the one simulated.
BALL_TABLE_FRICTION = combine(BALL_MATERIAL.dynamic_friction, TABLE_MATERIAL.dynamic_friction)
BALL_TABLE_RESTITUTION = combine(BALL_MATERIAL.restitution, TABLE_MATERIAL.restitution)
# The authors' materials give the ball 0.15 on a figurine, averaged; but here a figurine is held
# only by its drive's 1.41 N m and recoils from the ball, and a foot swinging through a ball
# slides along it: friction then throws the ball up. Measured, balls that left the table: 0.15,
# 3 of 3 shots at 10-15 m/s at a standing keeper and 4 of 60 scripted incoming-ball games;
# 0.05, 5 of 40 scripted full games; 0.02, 3 of 100 (0.0 still 4 of 100: the rest is balls
# bounced off the surface and struck in the air; revision 1 lost 22 of 100). So the ball on a
# figurine keeps 0.02: what Bullet's own rule (the product, 0.1 x 0.2) makes of the authors'
# materials.
AUTHORS_BALL_FIGURINE_FRICTION = combine(
    BALL_MATERIAL.dynamic_friction, FIGURINE_MATERIAL.dynamic_friction
)
BALL_FIGURINE_FRICTION = BALL_MATERIAL.dynamic_friction * FIGURINE_MATERIAL.dynamic_friction
BALL_FIGURINE_RESTITUTION = combine(BALL_MATERIAL.restitution, FIGURINE_MATERIAL.restitution)

# What these materials make of a rolling ball at a side wall: it leaves with its slope
# (|vy| / |vx|) flattened by this ratio, by the angle (degrees) its path made with the rod
# axis. Measured in the simulator (physics revision 2) at 2, 5 and 10 m/s, which agree within
# 0.01: the normal restitution of 0.5 plus the speed the wall's friction takes from vx, more
# for steeper paths.
WALL_BOUNCE_ANGLES = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 55.0, 60.0, 65.0, 70.0, 75.0, 80.0)
WALL_BOUNCE_SLOPE_RATIOS = (0.5, 0.52, 0.53, 0.55, 0.58, 0.61, 0.64, 0.68, 0.74, 0.74, 0.76, 0.8)


def wall_bounce_slope_ratio(slope: float) -> float:
    """Out over in of a rolling ball's |vy| / |vx| at a side wall (see WALL_BOUNCE_ANGLES)."""
    degrees = math.degrees(math.atan(abs(slope)))
    return float(np.interp(degrees, WALL_BOUNCE_ANGLES, WALL_BOUNCE_SLOPE_RATIOS))


def wall_bounce_along_ratio(slope: float) -> float:
    """The share of its speed along a wall that a rolling ball keeps in a bounce, by its slope
    across over along the wall (|vy| / |vx| at a side wall): what the wall's friction leaves
    of it, the part of :func:`wall_bounce_slope_ratio` that is not the restitution."""
    return BALL_RESTITUTION / wall_bounce_slope_ratio(slope)


# What a simulation step reports about goals (seen from the home side).
NO_GOAL = 0
HOME_SCORED = 1  # the ball crossed the away goal line (x > 0)
AWAY_SCORED = -1

# Timing. PHYSICS_HZ is the rate of the drives and of a ball in free flight; near a contact the
# simulator takes finer steps, so that nothing moves more than CONTACT_TRAVEL relative to
# what it may touch within one physics step.
PHYSICS_HZ = 240
CONTROL_HZ = 60
CONTACT_TRAVEL = 0.005
# Relative speeds up to this (m/s; the fastest balls of real play) are resolved to
# CONTACT_TRAVEL; beyond it (a foot swinging at full speed) a physics step's travel grows in
# proportion.
RESOLVED_SPEED = 20.0

# Raised whenever a change to the simulated physics (contacts, shapes, materials, stepping) can
# change what a policy meets; runs record it, and loading a model trained on another revision
# warns.
PHYSICS_REVISION = 2


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

    def figurine_swing(self, spin: float) -> tuple[float, float]:
        """World (x, z) of the figurines' centres at a revolute joint value.

        Positive spin swings the part below the axis towards the team's attacking side.
        """
        below = FIGURINE_CENTRE_BELOW_AXIS
        return self.x + self.direction * below * math.sin(spin), ROD_HEIGHT - below * math.cos(spin)

    def figurine_vx(self, spin: float, spin_rate: float) -> float:
        """World x velocity of the figurines' centres (the rate of :meth:`figurine_swing`)."""
        return self.direction * FIGURINE_CENTRE_BELOW_AXIS * math.cos(spin) * spin_rate


def _rod(team: str, role: str, x: float, offsets: tuple[float, ...], limit: float) -> Rod:
    return Rod(team=team, role=role, x=x, figurine_offsets=offsets, slide_limit=limit)


_KEEPER = ((0.0,), 0.1230)
_DEFENSE = ((-0.1235, 0.1235), 0.1790)
_OFFENSE = ((-0.184, 0.0, 0.184), 0.1185)
_MIDFIELD = ((-0.241, -0.1205, 0.0, 0.1205, 0.241), 0.0615)

# The colours (RGBA) the table is drawn in: the URDF's materials, the GUI window and the
# replay pages alike.
COLOURS: dict[str, tuple[float, float, float, float]] = {
    "field": (0.10, 0.45, 0.15, 1.0),
    "wall": (0.35, 0.22, 0.12, 1.0),
    "pocket": (0.15, 0.15, 0.15, 1.0),
    "rod": (0.75, 0.75, 0.78, 1.0),
    "home": (0.95, 0.95, 0.95, 1.0),
    "away": (0.10, 0.10, 0.10, 1.0),
    "ball": (1.0, 0.55, 0.0, 1.0),
}

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


def slide_for(rod: Rod, y: float) -> float:
    """The prismatic value that brings the figurine of ``rod`` nearest to ``y`` onto it, as far
    as the rod slides: a rod of the side that plays it, in that side's own frame."""
    best_miss, best = math.inf, 0.0
    for off in rod.figurine_offsets:
        s = min(max(y - off, -rod.slide_limit), rod.slide_limit)
        miss = abs(s + off - y)
        if miss < best_miss:
            best_miss, best = miss, s
    return best


def rod_spin_inertia(rod: Rod) -> float:
    """The rod's moment of inertia about its axis, figurines included (kg m^2), as the URDF
    gives it."""
    fx, _, fz = FIGURINE_SIZE
    figurine = FIGURINE_MASS * (FIGURINE_CENTRE_BELOW_AXIS**2 + (fx * fx + fz * fz) / 12)
    return ROD_MASS * ROD_RADIUS**2 / 2 + len(rod.figurine_offsets) * figurine


def drive_acceleration(rod: Rod, joint: str) -> float:
    """The most a drive can change its joint's speed per second, with nothing else pushing
    (m/s^2 for ``"slide"``, rad/s^2 for ``"spin"``): the simulated drives reach it, and a real
    table's configuration may not ask for more."""
    if joint == "slide":
        moving = CARRIAGE_MASS + ROD_MASS + len(rod.figurine_offsets) * FIGURINE_MASS
        return SLIDE_MAX_FORCE / moving
    if joint == "spin":
        return SPIN_MAX_TORQUE / rod_spin_inertia(rod)
    raise ValueError(f"joint must be 'slide' or 'spin', got {joint!r}")


def within_reach(rod: Rod, x: float, y: float) -> bool:
    """Whether a figurine of ``rod``, slid anywhere along its range, can touch a ball lying at
    (x, y): the table's rules serve again a ball at rest that none can."""
    if abs(x - rod.x) > FOOT_REACH_X:
        return False
    side = FIGURINE_LEG_HALF_WIDTH + BALL_RADIUS
    for off in rod.figurine_offsets:
        low, high = sorted(rod.direction * (s + off) for s in (-rod.slide_limit, rod.slide_limit))
        if low - side <= y <= high + side:
            return True
    return False


def in_goal_opening(y: float) -> bool:
    return abs(y) <= GOAL_HALF_WIDTH
