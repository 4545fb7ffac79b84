"""A person at the simulated table: the keyboard drives one away rod against the policy.

The GUI looks down on the table with the home goal (the policy's) on the left and the away goal
(the person's) on the right, so the keys follow the screen:

==================  =====================================================================
keys                what the rod does
==================  =====================================================================
up / w (hold)       slides up the screen, at a fixed speed while held
down / s (hold)     slides down the screen
left / a / space    kicks: the figurines swing left, towards the policy's goal, and back
right / d (hold)    lifts the figurines: they swing right, towards the person's goal
==================  =====================================================================

From the person's own side (``view="away"``: the GUI looks along the table from behind their
goal, the policy's goal at the top of the screen) the keys follow that screen instead: left and
right (a, d) slide the rod, up (w, space) kicks towards the policy's goal, down (s) lifts.

The rod's targets change smoothly: holding a key moves the slide target at
:data:`SLIDE_SPEED`, and a kick holds the figurines forward for :data:`KICK_TIME` before they
swing back. :class:`HumanOpponent` turns the keys into the away side's action in [-1, 1] (as
the task scales it: the slide target over the rod's slide limit, the spin target over
``SPIN_LIMIT``) and plays the away rods the person does not drive with another policy (the
task's scripted team). It reads keys from any callable, :meth:`TableSim.keyboard_events` in
play, so the mapping is tested without a window.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from foosball_gym import table
from foosball_gym.policy_io.task import Layout, action_joints, check_action

Keys = Callable[[], tuple[frozenset[str], frozenset[str]]]

UP_KEYS = frozenset({"up", "w"})
DOWN_KEYS = frozenset({"down", "s"})
KICK_KEYS = frozenset({"left", "a", "space"})
LIFT_KEYS = frozenset({"right", "d"})

#: The key map, as printed when play starts.
KEY_MAP: tuple[tuple[str, str], ...] = (
    ("up / w", "slide the rod up the screen (hold)"),
    ("down / s", "slide the rod down the screen (hold)"),
    ("left / a / space", "kick: the figurines swing left, towards the policy's goal"),
    ("right / d", "lift the figurines, towards your goal (hold)"),
)
#: The key map in one line, for the GUI window.
KEY_HINT = "up/down slide   left/space kick   right lift"

#: The views of the GUI window a person can play from, and their keys: those
#: that slide the figurines towards world +y and towards -y, those that kick, those that lift.
VIEW_KEYS: dict[str, tuple[frozenset[str], frozenset[str], frozenset[str], frozenset[str]]] = {
    "top": (UP_KEYS, DOWN_KEYS, KICK_KEYS, LIFT_KEYS),
    # From behind the away goal the screen's right is +y and its top the policy's goal.
    "away": (
        frozenset({"right", "d"}),
        frozenset({"left", "a"}),
        frozenset({"up", "w", "space"}),
        frozenset({"down", "s"}),
    ),
}
KEY_MAPS: dict[str, tuple[tuple[str, str], ...]] = {
    "top": KEY_MAP,
    "away": (
        ("left / a", "slide the rod left (hold)"),
        ("right / d", "slide the rod right (hold)"),
        ("up / w / space", "kick: the figurines swing up the screen, towards the policy's goal"),
        ("down / s", "lift the figurines, towards your goal (hold)"),
    ),
}
KEY_HINTS = {"top": KEY_HINT, "away": "left/right slide   up/space kick   down lift"}

#: How fast holding up or down moves the rod's slide target (m/s).
SLIDE_SPEED = 1.0
#: How far a kick swings the figurines forward (rad), and for how long it holds them there (s).
KICK_ANGLE = 1.2
KICK_TIME = 0.15
#: How far lifting swings the figurines back (rad): their feet clear a ball passing under.
LIFT_ANGLE = 1.4


def key_map_text(view: str = "top") -> str:
    """The key map of ``view`` (one of :data:`VIEW_KEYS`), one key per line."""
    keys_of = KEY_MAPS[check_view(view)]
    width = max(len(keys) for keys, _ in keys_of)
    return "\n".join(f"  {keys:{width}s}  {what}" for keys, what in keys_of)


def check_view(view: str) -> str:
    """``view`` if a person can play from it.

    Raises:
        ValueError: another view; the message lists those allowed.
    """
    if view not in VIEW_KEYS:
        raise ValueError(f"a person plays from the view top or away, not {view!r}")
    return view


def two_player_envs() -> list[str]:
    """The registered environments with an away side a person can play."""
    from foosball_gym.registration import TASKS, make_task

    return [env_id for env_id in TASKS if make_task(env_id)[0].layout.opponent]


def human_rod(env_id: str, layout: Layout, name: str = "keeper") -> str:
    """The away rod a person plays in ``env_id``: ``name`` is its role (``"keeper"``) or its
    rod's name (``"away_keeper"``).

    Raises:
        ValueError: the task has no away side, or no such away rod; the message lists what
            is allowed.
    """
    if not layout.opponent:
        raise ValueError(
            f"{env_id} has no away side for a person to play; two-player environments: "
            + ", ".join(two_player_envs())
        )
    roles = [rod.removeprefix("away_") for rod in layout.opponent]
    role = name.removeprefix("away_")
    if role not in roles:
        raise ValueError(f"{env_id} has no away rod {name!r} to play; allowed: {', '.join(roles)}")
    return f"away_{role}"


class KeyboardRod:
    """The targets of one rod from the keys a person holds, updated once a control step.

    Args:
        rod: the rod's name.
        dt: the time (s) one :meth:`update` stands for: the table's control step.
        slide_speed, kick_angle, kick_time, lift_angle: see the module's constants.
        view: where the person sees the table from (:data:`VIEW_KEYS`): the keys follow
            that screen.

    Attributes:
        slide: the slide target (m), in the rod's joint frame.
        spin: the spin target (rad): positive swings the figurines forward (towards the goal
            the rod's team attacks).
    """

    def __init__(
        self,
        rod: str,
        dt: float,
        slide_speed: float = SLIDE_SPEED,
        kick_angle: float = KICK_ANGLE,
        kick_time: float = KICK_TIME,
        lift_angle: float = LIFT_ANGLE,
        view: str = "top",
    ) -> None:
        self.plus_keys, self.minus_keys, self.kick_keys, self.lift_keys = VIEW_KEYS[
            check_view(view)
        ]
        if not dt > 0:
            raise ValueError(f"dt must be positive, got {dt}")
        self.rod = table.rod(rod)
        self.dt = float(dt)
        self.slide_speed, self.kick_angle = slide_speed, kick_angle
        self.kick_time, self.lift_angle = kick_time, lift_angle
        self.slide = 0.0
        self.spin = 0.0
        self._kick_steps = 0  # control steps the kick under way holds the figurines forward

    def update(self, held: frozenset[str], pressed: frozenset[str]) -> tuple[float, float]:
        """One control step with these keys held now and pressed since the last step.

        Returns:
            The slide (m) and spin (rad) targets.
        """
        down = held | pressed  # a key tapped between two steps counts for one step
        towards = bool(down & self.plus_keys) - bool(down & self.minus_keys)
        # A figurine's world y is direction * (slide + offset).
        step = self.rod.direction * towards * self.slide_speed * self.dt
        limit = self.rod.slide_limit
        self.slide = min(limit, max(-limit, self.slide + step))
        if pressed & self.kick_keys:
            self._kick_steps = max(1, round(self.kick_time / self.dt))
        if self._kick_steps:
            self._kick_steps -= 1
            self.spin = self.kick_angle
        elif down & self.lift_keys:
            self.spin = -self.lift_angle
        else:
            self.spin = 0.0
        return self.slide, self.spin


class HumanOpponent:
    """The away side with one rod driven from the keyboard: an opponent policy (mirrored
    observation to action in [-1, 1]) for :meth:`SimulatedTable.set_opponent`.

    Args:
        keys: returns the keys held now and those pressed since the last call.
        layout: the task's rods.
        rod: the away rod the person drives (see :func:`human_rod`).
        dt: the table's control step (s); the policy is asked once a step.
        others: the policy of the away rods the person does not drive (None: held at 0).
        view: where the person sees the table from (see :class:`KeyboardRod`).
    """

    def __init__(
        self,
        keys: Keys,
        layout: Layout,
        rod: str,
        dt: float,
        others: Callable[[np.ndarray], Any] | None = None,
        view: str = "top",
    ) -> None:
        joints, scales, _ = action_joints(layout.opponent, layout.joints)
        if (rod, "slide") not in joints:
            raise ValueError(f"{rod} is not an away rod of this task: {', '.join(layout.opponent)}")
        self.keys = keys
        self.controls = KeyboardRod(rod, dt, view=view)
        self._n = len(joints)
        self._slide = joints.index((rod, "slide"))
        self._spin = joints.index((rod, "spin")) if (rod, "spin") in joints else None
        self._scales = scales
        # Where the person drives every away rod, nobody else is asked.
        self.others = others if len(layout.opponent) > 1 else None

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        if self.others is None:
            action = np.zeros(self._n)
        else:
            action = np.array(check_action(self.others(observation), self._n, "opponent action"))
        slide, spin = self.controls.update(*self.keys())
        action[self._slide] = slide / self._scales[self._slide]
        if self._spin is not None:
            action[self._spin] = spin / self._scales[self._spin]
        return action
