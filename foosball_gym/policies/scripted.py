"""Hand-written policies: baselines, sanity checks and default opponents.

They act on an environment's observation vector through the names of its entries
(``ObservationBuilder.names``), so one policy works in every task that observes what it needs,
and on the mirrored observation an opponent gets. They always reason from the home side: their
own goal at x = -0.60, attacking +x. They keep no state between calls.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from foosball_gym import table
from foosball_gym.policies.aiming import clearance, offset_for_angle, plan_shot
from foosball_gym.policies.deflection import deflection_offset
from foosball_gym.policies.volley import volley_offset
from foosball_gym.table import slide_for

_WALL = table.BALL_LIMIT_Y
# How far in front of a rod (ball centre minus rod x) a swing of the foot reaches the ball.
_REACH_NEAR = table.FIGURINE_SIZE[0] / 2 + table.BALL_RADIUS - 0.004
_REACH_FAR = 0.075
_SLOW = 1.5  # m/s: a ball slower than this in reach gets kicked
_AIM_SPEED = 0.3  # m/s: a ball slower than this in reach gets an aimed kick
KICK_ANGLE = math.pi / 2  # spin target of a kick: the feet swing through and end up in front
WIND_UP_ANGLE = -math.pi / 2  # feet raised behind the rod, clear of the ball
# A swing from the wind-up takes about 32 ms to bring the feet down (torque-limited), so a
# volley starts when the ball is this many seconds from the feet.
VOLLEY_LEAD = 0.035
VOLLEY_WINDOW = 0.25
VOLLEY_MIN_SPEED = 1.0  # slower balls are stopped first, then kicked
# The slide closes its last millimetre slowly: on shots that arrive within 0.1 s it was still
# 0.2-1.3 mm short at contact, which turns a deflection 5-20 degrees. Commanding past the target
# by this share of the remaining gap lands it (scripted Score incoming 88 % -> 95 %).
DEFLECT_SLIDE_LEAD = 0.3
# A deflection keeps its line-up until the ball has left: it may still meet a foot it passes.
_DEFLECT_BEHIND = 0.01


def crossing_y(x: float, y: float, vx: float, vy: float, line_x: float) -> float | None:
    """Where a ball moving at (vx, vy) crosses x = line_x, with side-wall bounces that flatten
    its path as the simulated walls do; None if it is moving away from that line."""
    found = crossing(x, y, vx, vy, line_x)
    return None if found is None else found[0]


def crossing(x: float, y: float, vx: float, vy: float, line_x: float) -> tuple[float, float] | None:
    """As :func:`crossing_y`, with the path's slope there: (y, dy/|dx|)."""
    dx = line_x - x
    if vx == 0 or dx / vx < 0:
        return None
    run, slope = abs(dx), vy / abs(vx)
    y = min(max(y, -_WALL), _WALL)
    for _ in range(8):
        reach = y + slope * run
        if abs(reach) <= _WALL:
            return reach, slope
        wall = math.copysign(_WALL, slope)
        run -= (wall - y) / slope
        y, slope = wall, -slope * table.wall_bounce_slope_ratio(slope)
    return y, slope


def _find(names: Sequence[str], name: str) -> int:
    try:
        return list(names).index(name)
    except ValueError:
        raise ValueError(
            f"this policy needs {name!r} in the observation; it holds {list(names)}"
        ) from None


def _home_rod(name: str) -> table.Rod:
    """The home rod with the role of ``name``: scripted play always reasons from home."""
    return (
        table.rod(f"{table.HOME}_{name.split('_', 1)[1]}")
        if name.startswith(table.AWAY)
        else table.rod(name)
    )


class ScriptedTeam:
    """Rods that block, track and kick.

    Each rod slides its nearest figurine to where the ball will cross the rod's line when the
    ball comes towards it (bouncing off the side walls), and otherwise follows the ball's y.
    With revolute joints to drive, a rod shoots a slow ball that lies within reach in front of
    it: it lifts its feet behind it while it lines a figurine up with the ball, then swings
    through. It lifts its feet when the ball is behind it and moving forward (so its own team's
    shots pass), and keeps them down otherwise.

    Args:
        names: the observation's entry names (``env.unwrapped.obs_builder.names``).
        rods: the rods it plays, named as in the observation, in action order. An opponent's
            rods (``away_*`` in its mirrored observation) play as the home rods of that role.
        joints: ``"slide"`` (one action per rod) or ``"both"`` (slide, spin per rod).
        kick: shoot balls in reach (only with ``joints="both"``).
        aim: kick past the other team's figurines that the observation places (and into the
            goal mouth), with a corner of the foot for an angled shot or off a side wall.
        volley: strike fast balls coming at a rod instead of blocking them (with ``kick``),
            with the figurine placed where the swing sends the ball at the goal most often
            (``policies.volley``). It scores more from shots but concedes the ones it
            mistimes, so it suits attacking tasks, not defending.
        deflect: meet fast balls coming at a rod with still, upright feet, placed so that the
            ball bounces off towards the goal (``policies.deflection``; past the figurines the
            observation places, with ``aim``). Where no placement does, a ball is volleyed
            (with ``volley``) or blocked.
        guard_mouth: the keeper stays in front of its goal's mouth (:func:`guarded_target`)
            instead of following a ball that will pass beside it.
    """

    def __init__(
        self,
        names: Sequence[str],
        rods: Sequence[str] = ("home_keeper",),
        joints: str = "slide",
        kick: bool = True,
        volley: bool = False,
        aim: bool = False,
        deflect: bool = False,
        guard_mouth: bool = False,
    ) -> None:
        if joints not in ("slide", "both"):
            raise ValueError(f"joints must be 'slide' or 'both', got {joints!r}")
        self.rods = tuple(_home_rod(r) for r in rods)
        self.joints = joints
        self.kick = kick and joints == "both"
        self.volley = volley and self.kick
        self.deflect = deflect and self.kick
        self._ball = [_find(names, n) for n in ("ball_x", "ball_y", "ball_vx", "ball_vy")]
        names = list(names)
        # The rods' own joint values, where the observation holds them, let a kick wind up.
        self._own: list[tuple[int, int] | None] = []
        for name in rods:
            slide, spin = f"{name}_slide_pos", f"{name}_spin_pos"
            ok = slide in names and spin in names
            self._own.append((names.index(slide), names.index(spin)) if ok else None)
        self.n_actions = len(self.rods) * (2 if joints == "both" else 1)
        self.aim = aim and self.kick
        self.guard_mouth = guard_mouth
        # The other team's rods the observation places, as the home side sees them.
        other = table.HOME if str(rods[0]).startswith(table.AWAY) else table.AWAY
        self._blockers = []
        if self.aim:
            for role in table.ROLES:
                name = f"{other}_{role}_slide_pos"
                if name in names:
                    self._blockers.append((table.rod(f"{table.AWAY}_{role}"), names.index(name)))

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        # Python floats: numpy's scalars cost more to compute with than they save.
        values: list[float] = np.asarray(obs).tolist()
        x, y, vx, vy = (values[i] for i in self._ball)
        out: list[float] = []
        for rod, own in zip(self.rods, self._own):
            out.extend(self.rod_action(rod, own, values, x, y, vx, vy))
        return np.array(out, dtype=np.float32)

    def rod_action(
        self,
        rod: table.Rod,
        own: tuple[int, int] | None,
        obs: Sequence[float],
        x: float,
        y: float,
        vx: float,
        vy: float,
    ) -> tuple[float, ...]:
        """The action of one rod (its slide, and its spin with ``joints="both"``): ``own`` is
        where the observation holds its slide and spin positions, if it does."""
        if self.deflect and own is not None:
            move = self._deflection(rod, float(obs[own[0]]), x, y, vx, vy, obs)
            if move is not None:
                return move
        if self.guard_mouth and rod.role == "keeper":
            target = guarded_target(rod, x, y, vx, vy)
        elif self.volley and own is not None and vx < -VOLLEY_MIN_SPEED and x > rod.x:
            target = self.volley_target(rod, x, y, vx, vy)
        else:
            target = self.target_y(rod, x, y, vx, vy)
        offset = 0.0
        if self.aim and self._in_reach(rod, x, vx, vy):
            offset = offset_for_angle(plan_shot(x, y, self._blocker_positions(obs)))
            target = y - offset
        slide = slide_for(rod, target) / rod.slide_limit
        if self.joints != "both":
            return (slide,)
        state = None if own is None else (float(obs[own[0]]), float(obs[own[1]]))
        return slide, self.spin_for(rod, x, y, vx, vy, state, offset) / table.SPIN_LIMIT

    def _blocker_positions(self, obs: Sequence[float]) -> list[tuple[float, tuple[float, ...]]]:
        """The other team's placed rods: their x and their figurines' y."""
        return [(r.x, r.figurine_y(float(obs[i]))) for r, i in self._blockers]

    def _deflection(
        self,
        rod: table.Rod,
        slide: float,
        x: float,
        y: float,
        vx: float,
        vy: float,
        obs: Sequence[float],
    ) -> tuple[float, float] | None:
        """Slide and spin actions that deflect a fast ball coming at ``rod`` to the goal, or
        None where this ball is not one to deflect."""
        if vx > -VOLLEY_MIN_SPEED or x - rod.x < -_DEFLECT_BEHIND:
            return None
        path = crossing(x, y, vx, vy, rod.x)
        if path is None:
            return None
        cross, slope = path
        want = self.deflection_aim(rod, cross, obs)
        offset = deflection_offset(math.hypot(vx, vy), math.atan(slope), want)
        if offset is None:
            return None
        target = slide_for(rod, cross - offset)
        if min(abs(target + f - cross + offset) for f in rod.figurine_offsets) > 0.0005:
            return None  # beyond the slide's range: the foot cannot be placed
        command = target + DEFLECT_SLIDE_LEAD * (target - slide)
        command = min(max(command, -rod.slide_limit), rod.slide_limit)
        return command / rod.slide_limit, 0.0

    def deflection_aim(self, rod: table.Rod, cross: float, obs: Sequence[float]) -> float:
        """The direction (rad from +x) to deflect a ball crossing ``rod``'s line at ``cross``:
        at the middle of the goal, or past the figurines the observation places."""
        want = math.atan2(-cross, table.GOAL_LINE_X - rod.x)
        if self._blockers:
            blockers = self._blocker_positions(obs)
            if clearance(rod.x, cross, want, blockers) <= 0.0:
                want = plan_shot(rod.x, cross, blockers)
        return want

    @staticmethod
    def volley_target(rod: table.Rod, x: float, y: float, vx: float, vy: float) -> float:
        """World y where ``rod`` puts its nearest figurine to volley a fast ball coming at it:
        off the ball's crossing point by the offset that scores most often."""
        path = crossing(x, y, vx, vy, rod.x)
        if path is None:
            return y
        cross, slope = path
        return cross - volley_offset(cross, slope, math.hypot(vx, vy), rod.x)

    def _in_reach(self, rod: table.Rod, x: float, vx: float, vy: float) -> bool:
        # Only a ball lying still in front is worth the time a precise line-up takes: one
        # rolling at the rod gets past while the foot moves aside for a corner kick.
        return 0.0 < x - rod.x < _REACH_FAR and vx * vx + vy * vy < _AIM_SPEED**2

    @staticmethod
    def target_y(rod: table.Rod, x: float, y: float, vx: float, vy: float) -> float:
        """World y where ``rod`` should put its nearest figurine."""
        if vx < -0.05 and x > rod.x:
            cross = crossing_y(x, y, vx, vy, rod.x)
            if cross is not None:
                return cross
        return y

    def spin_for(
        self,
        rod: table.Rod,
        x: float,
        y: float,
        vx: float,
        vy: float,
        state: tuple[float, float] | None,
        offset: float = 0.0,
    ) -> float:
        ahead = x - rod.x
        slow = vx * vx + vy * vy < _SLOW**2
        if self.volley and state is not None and vx < -VOLLEY_MIN_SPEED and ahead > 0:
            # Strike a fast ball coming at the rod: blocking it only lets it trickle away.
            arrival = (ahead - _REACH_NEAR) / -vx
            if arrival <= VOLLEY_LEAD:
                return KICK_ANGLE
            if arrival <= VOLLEY_WINDOW:
                return WIND_UP_ANGLE
        if self.kick and -_REACH_NEAR < ahead < _REACH_FAR and slow:
            if state is None:
                return KICK_ANGLE if ahead > _REACH_NEAR else 0.0
            slide, spin = state
            # A corner kick's angle changes by about 5 degrees per millimetre of offset.
            tolerance = 0.006 if offset == 0.0 else 0.001
            aligned = abs(slide - slide_for(rod, y - offset)) < tolerance
            if aligned and spin < -1.0:
                return KICK_ANGLE  # wound up behind the rod and lined up: swing through
            if aligned and abs(spin) < 0.3 and ahead > _REACH_NEAR:
                return KICK_ANGLE  # feet down, ball clear in front: swing now
            return WIND_UP_ANGLE  # lift the feet behind the rod while lining up
        if ahead < -_REACH_NEAR and vx > 0.3 and rod.role != "keeper":
            return WIND_UP_ANGLE
        return 0.0


# GUARD_EDGE: the farthest (|y|, m) a guarding keeper goes for a ball that will pass beside the
# mouth; CLEAR: how far (m) its figurine keeps from where a ball behind it will cross its line.
GUARD_EDGE = 0.06
CLEAR = 0.07


def guarded_target(rod: table.Rod, x: float, y: float, vx: float, vy: float) -> float:
    """Where a keeper that guards its mouth puts its figurine.

    A ball that will pass beside the mouth meets the end wall there and comes back: a keeper
    that followed it to the end of its slide stands in its way, and the ball, struck by the
    back of the figurine, goes in (the wide shots' one way past the scripted keeper). So the
    keeper goes no farther than GUARD_EDGE towards such a ball, and keeps out of the way of a
    ball behind it. Where the ball is not coming at it, it stands between the ball and the
    middle of the goal.
    """
    if x < rod.x:
        if vx < 0.0:
            # On to the end wall first, and back off it at the wall's restitution.
            y = y + vy * (x + table.BALL_LIMIT_X) / -vx
            x, vx = -table.BALL_LIMIT_X, -vx * table.BALL_TABLE_RESTITUTION
        cross = crossing_y(x, y, vx, vy, rod.x) if vx > 0.05 else None
        cross = y if cross is None else cross
        return cross - math.copysign(CLEAR, cross)
    if vx < -0.05:
        cross = crossing_y(x, y, vx, vy, rod.x)
        goal = crossing_y(x, y, vx, vy, -table.GOAL_LINE_X)
        if cross is not None and goal is not None:
            if abs(goal) > table.GOAL_HALF_WIDTH and abs(cross) > GUARD_EDGE:
                return math.copysign(GUARD_EDGE, cross)
            return cross
    # Not coming at it: on the line from the ball to the middle of the goal, where a shot at
    # either post is nearest. A camera gives a new shot's speed only some frames late, and
    # from there no post is far.
    return y * (rod.x + table.GOAL_LINE_X) / (x + table.GOAL_LINE_X)


class ScriptedKeeper(ScriptedTeam):
    """The home keeper alone: blocks shots, and kicks balls in reach when it can spin.

    Args:
        names: the observation's entry names.
        n_actions: 1 (prismatic) or 2 (prismatic, revolute).
        kick: swing at balls in reach (with 2 actions).
        guard_mouth: stay in front of the mouth rather than follow a ball that will pass
            beside it (:func:`guarded_target`).
    """

    def __init__(
        self, names: Sequence[str], n_actions: int = 1, kick: bool = True, guard_mouth: bool = True
    ) -> None:
        if n_actions not in (1, 2):
            raise ValueError(f"n_actions must be 1 or 2, got {n_actions}")
        joints = "slide" if n_actions == 1 else "both"
        super().__init__(names, ("home_keeper",), joints, kick, guard_mouth=guard_mouth)
