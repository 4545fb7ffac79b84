"""Observation vectors, shared by the simulated and the real table.

An :class:`ObservationBuilder` turns a table state (joint positions and velocities of the rods
in play, and the ball's x, y, vx, vy) into the vector a policy sees. The simulator path and the
real-table path (encoders, camera, Kalman filter) both call it, so a policy cannot tell them
apart except by the state itself.

Layout, in order: the controlled rods' positions, then their velocities; the opponent rods'
positions, then their velocities; the ball ``x, y, vx, vy``; then any extra static rods'
prismatic positions. Joints appear rod by rod, prismatic before revolute.

:func:`mirrored_builder` gives the same vector as the away side sees the game from its own goal
(point symmetry: the away joints are already mirrored by construction; the ball's and the
figurines' world coordinates change sign), which is what an opponent policy acts on.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from operator import itemgetter

import numpy as np
from gymnasium import spaces

from foosball_gym import table

JOINT_SETS = ("slide", "both")
BALL_NAMES = ("ball_x", "ball_y", "ball_vx", "ball_vy")

# Generous bounds; Box spaces need some and the values never come near them.
_POS_BOUND = 10.0
_VEL_BOUND = 400.0


@dataclass(frozen=True)
class ObservationOptions:
    """The observation options every environment takes.

    Attributes:
        joint_velocities: include velocities (joint or figurine) of the rods.
        opponent_prismatic_only: of the opponent's rods, observe only the prismatic joints
            (what the real table's camera can see).
        observe_figurines: observe the figurines' (x, y) centres (and velocities) instead of
            joint values.
    """

    joint_velocities: bool = True
    opponent_prismatic_only: bool = False
    observe_figurines: bool = False


def check_flag(name: str, value: object) -> bool:
    """``value`` as a bool, or a ValueError: options that are flags take True or False only."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def observation_options(
    has_opponent: bool,
    joint_velocities: bool = True,
    observe_figurines: bool = False,
    opponent_prismatic_only: bool = False,
) -> ObservationOptions:
    """Checked observation options for a task with or without an opponent."""
    if check_flag("opponent_prismatic_only", opponent_prismatic_only) and not has_opponent:
        raise ValueError("opponent_prismatic_only applies only to tasks with an opponent")
    return ObservationOptions(
        joint_velocities=check_flag("joint_velocities", joint_velocities),
        opponent_prismatic_only=bool(opponent_prismatic_only),
        observe_figurines=check_flag("observe_figurines", observe_figurines),
    )


OBSERVATION_OPTIONS = ("joint_velocities", "observe_figurines", "opponent_prismatic_only")


def _joints(rod: table.Rod, joints: str) -> tuple[str, ...]:
    return ("slide",) if joints == "slide" else ("slide", "spin")


class ObservationBuilder:
    """Builds observation vectors for one task layout.

    Args:
        rods_in_play: every rod the state arrays describe, in their order; positions and
            velocities are given as all slides, then all spins, in this order.
        own: the controlled rods; ``own_joints`` says which of their joints are observed.
        opponent: rods played by an opponent (observed with both joints unless
            ``options.opponent_prismatic_only``).
        extras: rods whose prismatic position is appended after the ball (static obstacles).
        options: see :class:`ObservationOptions`.
        mirrored: build the vector as the away side sees it (world-frame values negated).
    """

    def __init__(
        self,
        rods_in_play: Sequence[str],
        own: Sequence[str],
        own_joints: str,
        opponent: Sequence[str] = (),
        extras: Sequence[str] = (),
        options: ObservationOptions = ObservationOptions(),
        mirrored: bool = False,
    ) -> None:
        if own_joints not in JOINT_SETS:
            raise ValueError(f"unknown joint set {own_joints!r}; allowed: {', '.join(JOINT_SETS)}")
        self.rods_in_play = tuple(rods_in_play)
        self.own = tuple(own)
        self.own_joints = own_joints
        self.opponent = tuple(opponent)
        self.extras = tuple(extras)
        self.options = options
        self.mirrored = mirrored
        self._sign = -1.0 if mirrored else 1.0
        opp_joints = "slide" if options.opponent_prismatic_only else "both"
        self.opponent_joints = opp_joints
        self._index = {name: i for i, name in enumerate(self.rods_in_play)}
        for name in (*self.own, *self.opponent, *self.extras):
            if name not in self._index:
                raise ValueError(f"rod {name!r} is not in play; in play: {self.rods_in_play}")
        n = len(self.rods_in_play)
        # Source vector: slides (n), spins (n), slide vels (n), spin vels (n), ball (4).
        self._ball_at = 4 * n
        self._n = n

        names: list[str] = []
        take: list[int] = []
        self._figurine_blocks: list[tuple[int, tuple[tuple[int, table.Rod], ...], bool, bool]] = []
        for side, rods, joints in (
            ("own", self.own, own_joints),
            ("opponent", self.opponent, opp_joints),
        ):
            if options.observe_figurines:
                start = len(names)
                y_only = side == "opponent" and options.opponent_prismatic_only
                names += self._figurine_names(rods, y_only, velocities=False)
                if options.joint_velocities:
                    names += self._figurine_names(rods, y_only, velocities=True)
                self._figurine_blocks.append(
                    (
                        start,
                        tuple((self._index[r], table.rod(r)) for r in rods),
                        y_only,
                        options.joint_velocities,
                    )
                )
                take += [-1] * (len(names) - start)
                continue
            for kind, offset in (("pos", 0), ("vel", 2 * n)):
                if kind == "vel" and not options.joint_velocities:
                    continue
                for rod_name in rods:
                    for joint in _joints(table.rod(rod_name), joints):
                        names.append(f"{rod_name}_{joint}_{kind}")
                        j = self._index[rod_name] + (n if joint == "spin" else 0)
                        take.append(offset + j)
        names += list(BALL_NAMES)
        take += [self._ball_at + k for k in range(4)]
        for rod_name in self.extras:
            names.append(f"{rod_name}_slide_pos")
            take.append(self._index[rod_name])
        self.names: tuple[str, ...] = tuple(names)
        self._take = take
        self._getter = itemgetter(*take)  # never empty: the ball's four entries are in it

        low = np.empty(len(names), dtype=np.float32)
        for i, name in enumerate(names):
            low[i] = -_VEL_BOUND if ("vel" in name or name.startswith("ball_v")) else -_POS_BOUND
        self.space = spaces.Box(low=low, high=-low, dtype=np.float32)

    @staticmethod
    def _figurine_names(rods: Sequence[str], y_only: bool, velocities: bool) -> list[str]:
        names = []
        for rod_name in rods:
            for i in range(len(table.rod(rod_name).figurine_offsets)):
                axes = ("y",) if y_only else ("x", "y")
                prefix = "v" if velocities else ""
                names += [f"{rod_name}_figurine_{i}_{prefix}{a}" for a in axes]
        return names

    @property
    def tracked_rods(self) -> tuple[str, ...]:
        """Rods whose state the real table can only see through its camera: the opponent's
        and the static obstacles'."""
        return (*self.opponent, *self.extras)

    @property
    def size(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """Where ``name`` (e.g. ``"ball_x"``, ``"home_keeper_slide_pos"``) sits in the vector."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"{name!r} is not in this observation; it holds {self.names}") from None

    def build(
        self, pos: Sequence[float], vel: Sequence[float], ball: Sequence[float]
    ) -> np.ndarray:
        """The observation for the home side.

        Args:
            pos, vel: joint positions and velocities of the rods in play, slides then spins.
            ball: x, y, vx, vy in the world frame.
        """
        if self.mirrored:
            ball = [-b for b in ball]
        src = [*pos, *vel, *ball]
        if self._figurine_blocks:
            return self._with_figurines(src, pos, vel)
        return np.array(self._getter(src), dtype=np.float32)

    def _with_figurines(
        self, src: list[float], pos: Sequence[float], vel: Sequence[float]
    ) -> np.ndarray:
        out = np.zeros(len(self.names), dtype=np.float32)
        for i, t in enumerate(self._take):
            if t >= 0:
                out[i] = src[t]
        n = self._n
        for start, rod_idx, y_only, velocities in self._figurine_blocks:
            values, rates = [], []
            sign = self._sign
            for k, rod in rod_idx:
                s, a, sv, av = pos[k], pos[n + k], vel[k], vel[n + k]
                x, vx = sign * rod.figurine_swing(a)[0], sign * rod.figurine_vx(a, av)
                vy = sign * rod.direction * sv
                for y in rod.figurine_y(s):
                    values += [sign * y] if y_only else [x, sign * y]
                    rates += [vy] if y_only else [vx, vy]
            block = values + (rates if velocities else [])
            out[start : start + len(block)] = block
        return out


def mirrored_builder(builder: ObservationBuilder) -> ObservationBuilder:
    """The builder for the away side of a symmetric task: its rods become the 'own' ones."""

    def swap(name: str) -> str:
        team, role = name.split("_", 1)
        return f"{table.AWAY if team == table.HOME else table.HOME}_{role}"

    if {swap(r) for r in builder.own} != set(builder.opponent) or builder.extras:
        raise ValueError(
            "only a symmetric layout (the opponent plays the mirror of the "
            "controlled rods, no static extras) can be mirrored"
        )
    return ObservationBuilder(
        builder.rods_in_play,
        [swap(r) for r in builder.own],
        builder.own_joints,
        [swap(r) for r in builder.opponent],
        options=builder.options,
        mirrored=not builder.mirrored,
    )
