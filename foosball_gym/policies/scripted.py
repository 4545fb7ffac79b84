"""Hand-written policies: baselines, sanity checks and default opponents.

They act on an environment's observation vector through the names of its entries
(``ObservationBuilder.names``), so one policy works in every task that observes what it needs,
and on the mirrored observation an opponent gets. They always reason from the home side:
their own goal at x = -0.60.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from foosball_gym import table as T

_WALL = T.FIELD_HALF_WIDTH - T.BALL_RADIUS


def fold_into_walls(y: float, half_width: float = _WALL) -> float:
    """Where a straight path that reached ``y`` really is after bouncing off the side walls."""
    period = 4 * half_width
    y = (y + half_width) % period
    return (y if y <= 2 * half_width else period - y) - half_width


def crossing_y(x: float, y: float, vx: float, vy: float, line_x: float) -> float | None:
    """Where a ball moving at (vx, vy) crosses x = line_x, with side-wall bounces; None if it
    is moving away from that line."""
    dx = line_x - x
    if vx == 0 or dx / vx < 0:
        return None
    return fold_into_walls(y + vy * dx / vx)


def _find(names: Sequence[str], name: str) -> int:
    try:
        return list(names).index(name)
    except ValueError:
        raise ValueError(
            f"this policy needs {name!r} in the observation; it holds {list(names)}"
        ) from None


class ScriptedKeeper:
    """A keeper that moves to where the ball will cross its line.

    When the ball comes towards the goal it predicts the crossing point on the keeper's line
    (bouncing off the side walls) and slides the figurine there; otherwise it follows the
    ball's y. With a revolute joint to drive it keeps the figurine upright, and with
    ``kick=True`` it swings through a ball that lies within reach in front of it.

    Args:
        names: the observation's entry names (``env.unwrapped.obs_builder.names``).
        n_actions: 1 (prismatic) or 2 (prismatic, revolute).
        rod: the rod it plays, from its own side (``"home_keeper"``, ``"home_defense"``, ...).
        kick: shoot balls that stop in front of the rod.
    """

    def __init__(
        self, names: Sequence[str], n_actions: int = 1, rod: str = "home_keeper", kick: bool = False
    ) -> None:
        if n_actions not in (1, 2):
            raise ValueError(f"n_actions must be 1 or 2, got {n_actions}")
        self.rod = T.rod(rod)
        if self.rod.team != T.HOME:
            raise ValueError("scripted policies reason from the home side; give a home rod")
        self.n_actions = n_actions
        self.kick = kick
        self._ball = [_find(names, n) for n in ("ball_x", "ball_y", "ball_vx", "ball_vy")]
        self._phase = 0

    def target_y(self, x: float, y: float, vx: float, vy: float) -> float:
        """World y where the rod should put its nearest figurine."""
        if vx < -0.05:
            cross = crossing_y(x, y, vx, vy, self.rod.x)
            if cross is not None:
                return cross
        return y

    def slide_for(self, y: float) -> float:
        """The prismatic value that brings the figurine nearest to ``y`` onto it."""
        best = None
        for off in self.rod.figurine_offsets:
            s = min(max(y - off, -self.rod.slide_limit), self.rod.slide_limit)
            miss = abs(s + off - y)
            if best is None or miss < best[0]:
                best = (miss, s)
        return best[1]

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        x, y, vx, vy = (float(obs[i]) for i in self._ball)
        slide = self.slide_for(self.target_y(x, y, vx, vy)) / self.rod.slide_limit
        if self.n_actions == 1:
            return np.array([slide], dtype=np.float32)
        return np.array([slide, self._spin(x, y, vx)], dtype=np.float32)

    def _spin(self, x: float, y: float, vx: float) -> float:
        if not self.kick:
            return 0.0
        ahead = x - self.rod.x
        in_reach = 0.0 < ahead < 0.06 and abs(vx) < 1.0
        if self._phase > 0:
            self._phase -= 1
            return 1.0 / 8 if self._phase > 4 else 0.0
        if in_reach:
            self._phase = 10
            return -1.0 / 8
        return 0.0
