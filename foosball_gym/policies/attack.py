"""The attacking team: the top of the scripted ladder (:mod:`foosball_gym.policies.ladder`).

It defends as :class:`~foosball_gym.policies.scripted.ScriptedTeam` does (each rod blocks where
the ball will cross its line, deflecting fast balls towards the goal), and attacks where that
team only kicks:

- a rod with a slow ball in front of it shoots where no defender ahead can reach in the time
  the ball takes to get there (:func:`~foosball_gym.policies.shots.plan_shot_past`), not just
  past where the defenders stand;
- it lines the foot up for a straight kick while it winds up, and moves it to the corner that
  angles the shot only as it swings, so the shot's direction shows as late as it can;
- its own rods ahead lift their feet before the shot, so that it passes under them: a ball
  that stops in front of the next rod is a chance from closer in;
- it keeps the ball on the table and out of its own goal (:func:`safe_spin`), and puts its
  feet down before a ball that rolls at a rod.

docs/results/ladder.md has how it was reached and what each of these is worth.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from foosball_gym import table
from foosball_gym.policies.aiming import offset_for_angle
from foosball_gym.policies.scripted import (
    KICK_ANGLE,
    WIND_UP_ANGLE,
    ScriptedTeam,
    slide_for,
)
from foosball_gym.policies.shots import plan_shot_past

# How far from the rod's axis (m) a foot reaches a ball on the table, and how far in front of
# it a ball is clear of a foot coming down from behind.
REACH = 0.065
SHOOT_CLEAR = 0.015
# A ball less far in front (m) lies under the foot's arc as it winds up.
UNDER = 0.01
# A foot this far from hanging down (rad) is raised.
RAISED = 0.5
# A ball nearer a side wall than this (|y|, m) is not struck.
WALL_BALL = 0.28
# A ball whose centre is this far in front of a rod's axis (m) is met by a swing from the
# wind-up near the bottom of the foot's arc; nearer, the foot comes down on it, and beyond
# SHOOT_FAR it passes over it (measured: a resting ball 0.065 m out is not touched).
SHOOT_NEAR = SHOOT_CLEAR
SHOOT_FAR = 0.058
# A ball slower than this (m/s) in that zone is shot; faster ones are blocked or deflected.
SHOOT_SPEED = 0.5
# A ball coming at a rod faster than this (m/s) is met with the feet down.
APPROACHING = 0.1
# Wound up: the feet are behind the rod, far enough back for a full swing.
WOUND_UP = -1.0
# A swing under way (rad/s): it is carried through rather than reversed.
SWINGING = 5.0
# How close to its line-up (m) a foot has to be to swing: a straight kick forgives a few
# millimetres, an angled one about 5 degrees a millimetre.
STRAIGHT_TOLERANCE = 0.006
AIM_TOLERANCE = 0.001
LATE_TOLERANCE = 0.004


def safe_spin(rod: table.Rod, spin: float, target: float, x: float, y: float) -> float:
    """``target`` for a rod's spin (rad), or the spin it holds where a swing there could throw
    the ball off the table or into its own goal.

    A foot that comes down on the ball from above presses it into the table and it bounces up,
    and a ball swung at against a side wall is squeezed up it; a ball in the air is lifted
    higher by the next foot it meets. In 30 matches between attacking teams without these
    rules 5 balls left the table: 3 struck against a side wall, 2 by a foot coming down on them.
    So a foot held up behind the rod stays up while the ball lies under its arc in front of it
    (and one up in front while the ball lies under its arc behind), and no foot swings at a
    ball against a side wall. Nor does a foot wind up over a ball just behind its rod, which
    would sweep it back (the keeper's: into its own goal).

    Args:
        rod: the rod.
        spin: its spin now (rad).
        target: the spin asked of it (rad).
        x: the ball's x.
        y: the ball's y.
    """
    ahead = x - rod.x
    if -REACH < ahead < REACH and abs(y) > WALL_BALL:
        return spin  # against a wall: neither kick it nor come down on it
    if spin < -RAISED and target > spin and -REACH < ahead < SHOOT_CLEAR:
        return min(spin, WIND_UP_ANGLE)
    if spin > RAISED and target < spin and -SHOOT_CLEAR < ahead < REACH:
        return max(spin, -WIND_UP_ANGLE)
    if abs(spin) <= RAISED and target < spin and -REACH < ahead < UNDER:
        return spin  # a wind-up would sweep a ball behind the rod back (the keeper's: in)
    return target


class AttackingTeam(ScriptedTeam):
    """Rods that defend as :class:`ScriptedTeam` does and shoot where defenders cannot reach.

    Args:
        names: the observation's entry names (``env.unwrapped.obs_builder.names``); it needs
            its own rods' slide and spin positions and the other team's slide positions.
        rods: the rods it plays, named as in the observation, in action order.
        deflect: meet fast balls coming at a rod with still feet placed to bounce them
            towards the goal (needs the ball's path to a millimetre: off for an estimated
            state).
        late_aim: line up straight while winding up and aim only as the foot swings.
        corner: where the other side's last rod follows the ball, bank an unstoppable shot
            into the corner beside its goal (:func:`~foosball_gym.policies.shots.corner_shot`):
            the keepers' game, where no shot over a metre beats a keeper that reacts.
    """

    def __init__(
        self,
        names: Sequence[str],
        rods: Sequence[str],
        *,
        deflect: bool = True,
        late_aim: bool = True,
        corner: bool = False,
    ) -> None:
        super().__init__(names, rods, "both", kick=True, aim=True, deflect=deflect)
        joints = [own for own in self._own if own is not None]
        if len(joints) != len(self._own):
            raise ValueError(
                "the attacking team needs its rods' slide and spin positions in the observation"
            )
        self._joints: list[tuple[int, int]] = joints
        names = list(names)
        self._spin_rate = [
            names.index(f"{r}_spin_vel") if f"{r}_spin_vel" in names else None for r in rods
        ]
        self.late_aim = late_aim
        self.corner = corner

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        values: list[float] = np.asarray(obs).tolist()
        x, y, vx, vy = (values[i] for i in self._ball)
        shooter = self._shooter(x, vx, vy)
        out: list[float] = []
        for k, (rod, own) in enumerate(zip(self.rods, self._joints)):
            if shooter is not None and k == shooter:
                slide, spin = self._shot(k, values, x, y)
            elif shooter is not None and rod.x > self.rods[shooter].x:
                # Clear the way: the shot passes under lifted feet.
                slide, spin = slide_for(rod, y) / rod.slide_limit, WIND_UP_ANGLE / table.SPIN_LIMIT
            else:
                slide, spin = self.rod_action(rod, own, values, x, y, vx, vy)
                if vx < -APPROACHING and x - rod.x > SHOOT_NEAR:
                    # Feet down before a ball coming at the rod: one that rolls under a foot
                    # lifted to kick it is past the rod (the keeper: in the goal).
                    spin = 0.0
            spin = safe_spin(rod, values[own[1]], spin * table.SPIN_LIMIT, x, y)
            out += (slide, spin / table.SPIN_LIMIT)
        return np.array(out, dtype=np.float32)

    def deflection_aim(self, rod: table.Rod, cross: float, obs: Sequence[float]) -> float:
        # At the middle of the goal: a deflection aimed past the defenders, as a kick is,
        # left the ball in its own half (2 goals for, 8 against the kicking team in 10
        # matches; at the middle, 12 for and 3 against).
        return math.atan2(-cross, table.GOAL_LINE_X - rod.x)

    def shot_angle(
        self, x: float, y: float, defenders: Sequence[tuple[table.Rod, float]]
    ) -> float | None:
        """The direction (rad from +x) to shoot a ball at (x, y) past ``defenders`` (the other
        team's rods with their prismatic values), or None to hold the swing: the foot stays
        wound up and lined up behind the ball. A subclass that picks its shots another way
        overrides this alone."""
        return plan_shot_past(x, y, defenders, self.corner)

    def shooter(self, obs: np.ndarray) -> int | None:
        """The index of the rod that has a ball to shoot in ``obs``, if one has."""
        x, _, vx, vy = (float(obs[i]) for i in self._ball)
        return self._shooter(x, vx, vy)

    def _shooter(self, x: float, vx: float, vy: float) -> int | None:
        """The rod with a slow ball in front of it that is not coming at it, if one has."""
        if vx * vx + vy * vy >= SHOOT_SPEED**2 or vx < -APPROACHING:
            return None
        for k, rod in enumerate(self.rods):
            if SHOOT_NEAR < x - rod.x < SHOOT_FAR:
                return k
        return None

    def _shot(self, k: int, obs: Sequence[float], x: float, y: float) -> tuple[float, float]:
        """Slide and spin actions of rod ``k``, which has the ball in front of it to shoot."""
        rod = self.rods[k]
        slide_at, spin_at = (float(obs[i]) for i in self._joints[k])
        at = self._spin_rate[k]
        rate = 0.0 if at is None else float(obs[at])
        defenders = [(r, float(obs[i])) for r, i in self._blockers]
        angle = self.shot_angle(x, y, defenders)
        offset = 0.0 if angle is None else offset_for_angle(angle)
        aimed = slide_for(rod, y - offset)
        straight = slide_for(rod, y)
        if rate > SWINGING and spin_at < KICK_ANGLE - 0.3:
            return aimed / rod.slide_limit, KICK_ANGLE / table.SPIN_LIMIT
        if angle is None:
            return straight / rod.slide_limit, WIND_UP_ANGLE / table.SPIN_LIMIT
        if spin_at < WOUND_UP:
            if offset == 0.0:
                ready = abs(slide_at - straight) < STRAIGHT_TOLERANCE
            else:
                # Aiming late, the foot still closes most of what is left during the swing.
                ready = abs(slide_at - aimed) < (LATE_TOLERANCE if self.late_aim else AIM_TOLERANCE)
            if ready:
                return aimed / rod.slide_limit, KICK_ANGLE / table.SPIN_LIMIT
            low, high = sorted((straight, aimed))
            if self.late_aim and low - STRAIGHT_TOLERANCE < slide_at < high + STRAIGHT_TOLERANCE:
                # Lined up and wound up: aim now, and swing as the foot gets there.
                return aimed / rod.slide_limit, WIND_UP_ANGLE / table.SPIN_LIMIT
        line_up = straight if self.late_aim else aimed
        return line_up / rod.slide_limit, WIND_UP_ANGLE / table.SPIN_LIMIT
