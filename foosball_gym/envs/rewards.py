"""Reward terms of the paper (docs/envs/index.md), each with its own weight.

Base terms: ``goal`` (+weight for a goal scored, -weight for one conceded) and
``out_of_table`` (-weight when the ball leaves the table upwards). Shaping terms, off at weight
0: ``ball_to_goal``, ``figurine_to_ball``, ``ball_aim``, ``ball_lane`` and ``ball_threat``
(not the paper's: how near the goal mouth the ball's path leads, the same for a path past the
figurines in its way, and minus how near the learner's own goal mouth it leads) are
potentials Φ(s) rewarded either as the authors' per-step difference ``w·(Φ(s') - Φ(s))``
or as potential-based shaping ``w·(γ·Φ(s') - Φ(s))`` (with Φ = 0 at the end of an episode,
so the optimal policy is unchanged); ``action_regularisation`` is
``-w·mean((a_t - a_{t-1})²)`` every step.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from foosball_gym import table

SHAPING_MODES = ("difference", "potential")
TERMS = (
    "goal",
    "out_of_table",
    "ball_to_goal",
    "figurine_to_ball",
    "ball_aim",
    "ball_lane",
    "ball_threat",
    "action_regularisation",
)
# The terms that reward a change of potential.
POTENTIALS = ("ball_to_goal", "figurine_to_ball", "ball_aim", "ball_lane", "ball_threat")
_NO_POTENTIALS = (0.0, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class RewardWeights:
    goal: float = 1000.0
    out_of_table: float = 1000.0
    ball_to_goal: float = 0.0
    figurine_to_ball: float = 0.0
    ball_aim: float = 0.0
    ball_lane: float = 0.0
    ball_threat: float = 0.0
    action_regularisation: float = 0.0
    shaping: str = "difference"
    gamma: float = 0.99

    def __post_init__(self) -> None:
        if self.shaping not in SHAPING_MODES:
            raise ValueError(
                f"unknown shaping {self.shaping!r}; allowed: {', '.join(SHAPING_MODES)}"
            )
        for name in TERMS:
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"reward weight {name} must be a finite number, got {value!r}")
        if not 0.0 <= self.gamma <= 1.0:
            raise ValueError(f"gamma must lie in [0, 1], got {self.gamma}")


def ball_to_goal_potential(x: float, y: float) -> float:
    """exp(-6 d), d the distance from the ball to the away goal mouth (home attacks +x)."""
    dy = abs(y) - table.GOAL_MOUTH_HALF
    d = math.hypot(x - table.GOAL_LINE_X, dy if dy > 0 else 0.0)
    return math.exp(-6.0 * d)


def figurine_to_ball_potential(ball_y: float, figurine_y: Sequence[Sequence[float]]) -> float:
    """-(1 - mean over rods of exp(-6 · min over the rod's figurines |y_fig - y_ball|))."""
    total = 0.0
    for ys in figurine_y:
        total += math.exp(-6.0 * min(abs(fy - ball_y) for fy in ys))
    return -(1.0 - total / len(figurine_y))


# A ball slower than this towards the goal is not on its way there.
AIM_MIN_SPEED = 0.5  # m/s
# Φ falls by e for each 5 cm that the path passes beside the mouth.
AIM_FALL = 20.0  # 1/m


# A figurine stops a ball whose centre passes nearer its leg's middle than this.
LANE_BLOCK = table.FIGURINE_LEG_HALF_WIDTH + table.BALL_RADIUS
# A rod spun further than this holds its soles above a ball on the table.
SOLES_UP_SPIN = math.acos((table.ROD_HEIGHT - 2 * table.BALL_RADIUS) / table.FIGURINE_REACH)

#: A rod in the ball's way: its axis' x and the y of each of its figurines.
Blocker = tuple[float, Sequence[float]]


def path_y(x: float, y: float, vx: float, vy: float, target_x: float) -> float:
    """Where the ball's straight path from (x, y) at (vx, vy), vx > 0, crosses ``target_x``,
    each bounce off a side wall mirroring it."""
    half = table.FIELD_HALF_WIDTH - table.BALL_RADIUS
    crossing = (y + vy * (target_x - x) / vx + half) % (4 * half)
    return (crossing if crossing <= 2 * half else 4 * half - crossing) - half


def lane_blockers(rods: Sequence[table.Rod], joints: Sequence[float]) -> list[Blocker]:
    """The rods among ``rods`` whose soles are down, as blockers; ``joints`` holds their slides
    then their spins."""
    n = len(rods)
    return [
        (rod.x, rod.figurine_y(joints[i]))
        for i, rod in enumerate(rods)
        if abs(joints[n + i]) < SOLES_UP_SPIN
    ]


def rod_joints(positions: Sequence[float], n_rods: int, indices: Sequence[int]) -> list[float]:
    """The slides then the spins of the rods at ``indices`` among the ``n_rods`` in play, whose
    joint values ``positions`` holds, all slides then all spins."""
    return [positions[i] for i in indices] + [positions[n_rods + i] for i in indices]


def ball_aim_potential(
    x: float, y: float, vx: float, vy: float, blockers: Sequence[Blocker] = ()
) -> float:
    """exp(-20 m), m how far beside the away goal mouth the ball's straight path crosses the
    goal line, the side walls' bounces folded in (0 in the mouth), while the ball moves towards
    that line at AIM_MIN_SPEED or more; 0 otherwise, and 0 where the path meets a figurine of
    ``blockers`` ahead of the ball (home attacks +x)."""
    if vx < AIM_MIN_SPEED or x >= table.GOAL_LINE_X:
        return 0.0
    for rod_x, figurines in blockers:
        if rod_x > x:
            crossing = path_y(x, y, vx, vy, rod_x)
            if any(abs(crossing - fy) < LANE_BLOCK for fy in figurines):
                return 0.0
    beside = abs(path_y(x, y, vx, vy, table.GOAL_LINE_X)) - (
        table.GOAL_HALF_WIDTH - table.BALL_RADIUS
    )
    return math.exp(-AIM_FALL * beside) if beside > 0 else 1.0


def ball_threat_potential(x: float, y: float, vx: float, vy: float) -> float:
    """Minus the ball's aim at the home goal: -1 while its straight path leads into the mouth
    the learner defends, nearer 0 the further beside it, 0 while the ball does not move
    towards it at AIM_MIN_SPEED or more (the aim of the ball turned about the table's
    centre)."""
    return -ball_aim_potential(-x, -y, -vx, -vy)


class RewardComputer:
    """Keeps the previous potentials and action; returns the terms of each step.

    Args:
        weights: the term weights.
        rods: the controlled rods (for figurine-to-ball).
        blockers: the rods whose figurines stand in the ball's lanes (for ball-lane).
    """

    def __init__(
        self,
        weights: RewardWeights,
        rods: Sequence[table.Rod],
        blockers: Sequence[table.Rod] = (),
    ) -> None:
        self.w = weights
        self.rods = tuple(rods)
        self.blockers = tuple(blockers)
        # The potentials' weights in POTENTIALS' order, looked up once.
        self._weights = tuple(getattr(weights, name) for name in POTENTIALS)
        self._phi = _NO_POTENTIALS
        self._last_action: list[float] | None = None
        self._potential = weights.shaping == "potential"

    def _potentials(
        self, slide: Sequence[float], ball: Sequence[float], blocking: Sequence[float]
    ) -> tuple[float, float, float, float, float]:
        """The potentials in POTENTIALS' order (0 where a term is off)."""
        w = self.w
        x, y, vx, vy = ball[:4]
        goal = ball_to_goal_potential(x, y) if w.ball_to_goal else 0.0
        figurine = 0.0
        if w.figurine_to_ball and self.rods:
            figurine = figurine_to_ball_potential(
                y, [rod.figurine_y(s) for rod, s in zip(self.rods, slide)]
            )
        aim = ball_aim_potential(x, y, vx, vy) if w.ball_aim else 0.0
        lane = 0.0
        if w.ball_lane:
            lane = ball_aim_potential(x, y, vx, vy, lane_blockers(self.blockers, blocking))
        threat = ball_threat_potential(x, y, vx, vy) if w.ball_threat else 0.0
        return goal, figurine, aim, lane, threat

    def reset(
        self,
        slide: Sequence[float],
        ball: Sequence[float],
        n_actions: int,
        blocking: Sequence[float] = (),
    ) -> None:
        """Start an episode from a state; ``slide`` holds the controlled rods' slide values,
        ``ball`` the ball's x, y, vx and vy, ``blocking`` the blockers' slides then spins."""
        self._phi = self._potentials(slide, ball, blocking)
        self._last_action = [0.0] * n_actions

    def step(
        self,
        goal: int,
        out_of_table: bool,
        slide: Sequence[float],
        ball: Sequence[float],
        action: Sequence[float],
        terminal: bool,
        blocking: Sequence[float] = (),
    ) -> dict[str, float]:
        """Reward terms for one step, keyed by term name (their sum is the reward);
        ``blocking`` holds the blockers' slides then spins."""
        w = self.w
        if terminal and self._potential:
            phi = _NO_POTENTIALS
        else:
            phi = self._potentials(slide, ball, blocking)
        g = w.gamma if self._potential else 1.0
        (w_goal, w_fig, w_aim, w_lane, w_threat), old = self._weights, self._phi
        terms = {
            "goal": w.goal * goal,
            "out_of_table": -w.out_of_table if out_of_table else 0.0,
            "ball_to_goal": w_goal * (g * phi[0] - old[0]),
            "figurine_to_ball": w_fig * (g * phi[1] - old[1]),
            "ball_aim": w_aim * (g * phi[2] - old[2]),
            "ball_lane": w_lane * (g * phi[3] - old[3]),
            "ball_threat": w_threat * (g * phi[4] - old[4]),
            "action_regularisation": 0.0,
        }
        if w.action_regularisation:
            last = self._last_action
            if last is None:
                raise RuntimeError("call reset() before step()")
            diff = sum((a - b) ** 2 for a, b in zip(action, last)) / max(len(action), 1)
            terms["action_regularisation"] = -w.action_regularisation * diff
        self._last_action = list(action)
        self._phi = phi
        return terms
