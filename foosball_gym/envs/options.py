"""The options every environment shares, declared once, and their checks, which build nothing.

:class:`EnvOptions` (:class:`GameOptions` with an opponent) is the shared options' typed
declaration, what an environment class takes as ``**shared: Unpack[EnvOptions]``;
:class:`SharedOptions` holds their values, its defaults those of every environment (an
environment changes a few in its class attribute ``defaults``). :func:`check_shared` checks
the shared options with a task as the environment would, without a simulator: what gymnasium's
``make``, training's start-up, ``foosball play``, ``foosball dataset`` and the simulated table
call (through :func:`foosball_gym.registration.check_env_options`).

Each option is checked by what uses it: a task's own options by the task, the observation's by
:func:`~foosball_gym.policy_io.observations.observation_options`, the reward weights by
:class:`~foosball_gym.envs.rewards.RewardWeights`, ``camera_noise`` by
:class:`~foosball_gym.camera.CameraNoise`, the physics by
:func:`~foosball_gym.sim.options.check_physics`, ``opponent`` by
:func:`~foosball_gym.game.resolve_opponent`, and the rest here.
"""

from __future__ import annotations

import dataclasses
import difflib
import inspect
import math
import re
import typing
import weakref
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Literal, TypedDict

import numpy as np
from typing_extensions import Unpack

from foosball_gym import table
from foosball_gym.camera import CameraNoise, check_image_side
from foosball_gym.envs.rewards import RewardWeights
from foosball_gym.envs.rod_errors import RodErrors
from foosball_gym.envs.safety_layer import check_safety_layer
from foosball_gym.game import Policy, resolve_opponent
from foosball_gym.policy_io.observations import check_flag, observation_options
from foosball_gym.policy_io.task import TaskInterface
from foosball_gym.sim.options import check_physics, check_randomisation
from foosball_gym.tasks.base import Task
from foosball_gym.tasks.serves import within

RENDER_MODES = ("human", "rgb_array")
RESIDUAL_LIMIT = 2.0
# A band as wide as the table: a wider one reaches no further.
SLIDE_AROUND_BALL_LIMIT = 2 * table.BALL_LIMIT_Y
# Further beside the ball than this, the foot misses it.
SLIDE_SKIP_LIMIT = table.FIGURINE_LEG_HALF_WIDTH + table.BALL_RADIUS


class EnvOptions(TypedDict, total=False):
    """The options every environment takes, with their types: an environment class's
    ``**shared: Unpack[EnvOptions]``. They are described on
    :class:`~foosball_gym.envs.base.FoosballEnv`; their defaults are :class:`SharedOptions`'."""

    goal_reward: float
    out_of_table_penalty: float
    ball_to_goal_weight: float
    figurine_to_ball_weight: float
    ball_aim_weight: float
    ball_lane_weight: float
    ball_threat_weight: float
    action_regularisation_weight: float
    shaping: Literal["difference", "potential"]
    gamma: float
    joint_velocities: bool
    observe_figurines: bool
    opponent_prismatic_only: bool
    stagnation_steps: int
    ball_friction_range: tuple[float, float] | None
    ball_restitution_range: tuple[float, float] | None
    ball_mass_range: tuple[float, float] | None
    drive_gain_range: tuple[float, float] | None
    rolling_resistance_range: tuple[float, float] | None
    drive_speed_range: tuple[float, float] | None
    drive_accel_range: tuple[float, float] | None
    slide_offset_range: tuple[float, float] | None
    angle_offset_range: tuple[float, float] | None
    rod_angle_noise: float
    estimated_state: bool
    camera_noise: dict[str, Any] | None
    safety_layer: bool | None
    residual: float | tuple[float, ...]
    slide_around_ball: float
    slide_skip: float
    render_mode: str | None
    render_width: int
    render_height: int
    physics_hz: int
    control_hz: int
    contact_travel: float
    rolling_resistance: float


class GameOptions(EnvOptions, total=False):
    """The options of an environment with an opponent: every environment's and the opponent."""

    opponent: Policy | str | None


@dataclass(frozen=True)
class SharedOptions:
    """The values of the options every environment takes (:class:`GameOptions`); as made,
    ``SharedOptions()``, their defaults, the simulator's those of :mod:`foosball_gym.table`.

    An environment class whose task wants other defaults says so in its ``defaults``, e.g.
    ``SharedOptions(stagnation_steps=60)``.
    """

    opponent: Policy | str | None = None
    goal_reward: float = 1000.0
    out_of_table_penalty: float = 1000.0
    ball_to_goal_weight: float = 0.0
    figurine_to_ball_weight: float = 0.0
    ball_aim_weight: float = 0.0
    ball_lane_weight: float = 0.0
    ball_threat_weight: float = 0.0
    action_regularisation_weight: float = 0.0
    shaping: Literal["difference", "potential"] = "difference"
    gamma: float = 0.99
    joint_velocities: bool = True
    observe_figurines: bool = False
    opponent_prismatic_only: bool = False
    stagnation_steps: int = 0
    ball_friction_range: tuple[float, float] | None = None
    ball_restitution_range: tuple[float, float] | None = None
    ball_mass_range: tuple[float, float] | None = None
    drive_gain_range: tuple[float, float] | None = None
    rolling_resistance_range: tuple[float, float] | None = None
    drive_speed_range: tuple[float, float] | None = None
    drive_accel_range: tuple[float, float] | None = None
    slide_offset_range: tuple[float, float] | None = None
    angle_offset_range: tuple[float, float] | None = None
    rod_angle_noise: float = 0.0
    estimated_state: bool = False
    camera_noise: dict[str, Any] | None = None
    safety_layer: bool | None = None
    residual: float | tuple[float, ...] = 0.0
    slide_around_ball: float = 0.0
    slide_skip: float = 0.0
    render_mode: str | None = None
    render_width: int = 320
    render_height: int = 180
    physics_hz: int = table.PHYSICS_HZ
    control_hz: int = table.CONTROL_HZ
    contact_travel: float = table.CONTACT_TRAVEL
    rolling_resistance: float = table.ROLLING_RESISTANCE


@dataclass(frozen=True)
class CheckedOptions:
    """An environment's options, checked, and what they make without a simulator: what the
    environment builds its world and its game from.

    Attributes:
        task: the task, built and checked from its own options.
        values: every shared option's value, as given or defaulted.
        interface: the task's observation builder and action mapping.
        weights: the reward weights.
        randomisation: each domain randomisation range that is on.
        rod_errors: the calibration offsets' and angle noise's ranges.
        camera_noise: the simulated camera's errors; None without ``estimated_state``.
        residual: the residual scale (0.0: off), or one for each entry of the action.
        safety_layer: whether the action's targets go through the safety layer.
        physics: ``(physics_hz, control_hz, contact_travel, rolling_resistance)``.
        render: ``(render_mode, render_width, render_height)``.
        stagnation_steps: the steps after which a still ball ends the game (0: never).
    """

    task: Task
    values: SharedOptions
    interface: TaskInterface
    weights: RewardWeights
    randomisation: dict[str, tuple[float, float]]
    rod_errors: RodErrors
    camera_noise: CameraNoise | None
    residual: float | tuple[float, ...]
    safety_layer: bool
    physics: tuple[int, int, float, float]
    render: tuple[str | None, int, int]
    stagnation_steps: int

    @property
    def observation_size(self) -> int:
        """The number of entries of an observation."""
        return len(self.interface.builder.names)

    @property
    def action_size(self) -> int:
        """The number of entries of an action."""
        return self.interface.n_actions

    @property
    def two_player(self) -> bool:
        """Whether the task has an opponent."""
        return bool(self.task.layout.opponent)


#: Every environment's defaults.
DEFAULTS = SharedOptions()


def check_shared(
    task: Task, defaults: SharedOptions = DEFAULTS, **given: Unpack[GameOptions]
) -> CheckedOptions:
    """The shared options ``given`` (the others at ``defaults``) checked for ``task`` as the
    environment checks them, building no simulator.

    Raises:
        ValueError: an option has a bad value; the message names it and what it allows.
        TypeError: ``given`` holds a name that is not a shared option.
    """
    o = dataclasses.replace(defaults, **given)
    layout = task.layout
    render = check_render(o.render_mode, o.render_width, o.render_height)
    stagnation_steps = check_stagnation(o.stagnation_steps)
    weights = RewardWeights(
        goal=o.goal_reward,
        out_of_table=o.out_of_table_penalty,
        ball_to_goal=o.ball_to_goal_weight,
        figurine_to_ball=o.figurine_to_ball_weight,
        ball_aim=o.ball_aim_weight,
        ball_lane=o.ball_lane_weight,
        ball_threat=o.ball_threat_weight,
        action_regularisation=o.action_regularisation_weight,
        shaping=o.shaping,
        gamma=o.gamma,
    )
    interface = TaskInterface.create(
        layout,
        task.extras,
        observation_options(
            bool(layout.opponent),
            joint_velocities=o.joint_velocities,
            observe_figurines=o.observe_figurines,
            opponent_prismatic_only=o.opponent_prismatic_only,
        ),
    )
    randomisation = check_randomisation(
        {
            "ball_friction_range": o.ball_friction_range,
            "ball_restitution_range": o.ball_restitution_range,
            "ball_mass_range": o.ball_mass_range,
            "drive_gain_range": o.drive_gain_range,
            "rolling_resistance_range": o.rolling_resistance_range,
            "drive_speed_range": o.drive_speed_range,
            "drive_accel_range": o.drive_accel_range,
        }
    )
    rod_errors = RodErrors(
        interface.action_joints,
        layout.rods,
        o.slide_offset_range,
        o.angle_offset_range,
        o.rod_angle_noise,
    )
    camera_noise = None
    if check_flag("estimated_state", o.estimated_state):
        camera_noise = CameraNoise.from_dict(o.camera_noise)
    elif o.camera_noise is not None:
        raise ValueError("camera_noise needs estimated_state=True")
    residual = check_residual(o.residual, interface.n_actions)
    slide_around_ball = check_slide_around_ball(o.slide_around_ball, residual)
    interface = dataclasses.replace(
        interface,
        slide_around_ball=slide_around_ball,
        slide_skip=check_slide_skip(o.slide_skip, slide_around_ball),
    )
    physics = check_physics(o.physics_hz, o.control_hz, o.contact_travel, o.rolling_resistance)
    safety_layer = check_safety_layer(o.safety_layer, camera_noise is not None)
    if o.opponent is not None:
        resolve_opponent(task, interface.builder.names, o.opponent)
    return CheckedOptions(
        task=task,
        values=o,
        interface=interface,
        weights=weights,
        randomisation=randomisation,
        rod_errors=rod_errors,
        camera_noise=camera_noise,
        residual=residual,
        safety_layer=safety_layer,
        physics=physics,
        render=render,
        stagnation_steps=stagnation_steps,
    )


def check_residual(value: Any, n_actions: int | None = None) -> float | tuple[float, ...]:
    """The residual scale: 0 (off) up to RESIDUAL_LIMIT, or one such scale for each of the
    ``n_actions`` entries of the action (all 0 is off, given as 0.0), or a ValueError saying
    what is allowed. ``n_actions`` None: a list of any length but 0."""
    count = "such numbers" if n_actions is None else f"{n_actions} such numbers"
    allowed = (
        f"residual must be a number in [0, {RESIDUAL_LIMIT}] (0: off), or a list of {count}, "
        "one for each entry of the action"
    )
    if isinstance(value, list | tuple | np.ndarray):
        scales = [_scale(v) for v in value]
        wrong_size = len(scales) != n_actions if n_actions is not None else not scales
        if wrong_size or any(math.isnan(v) for v in scales):
            raise ValueError(f"{allowed}; got {value!r}")
        return tuple(scales) if any(scales) else 0.0
    scale = _scale(value)
    if math.isnan(scale):
        raise ValueError(f"{allowed}; got {value!r}")
    return scale


def _scale(value: Any) -> float:
    """``value`` as a scale within [0, RESIDUAL_LIMIT], NaN where it is none."""
    try:
        scale = float(value)
    except (TypeError, ValueError):
        return math.nan
    if isinstance(value, bool) or not 0.0 <= scale <= RESIDUAL_LIMIT:
        return math.nan
    return scale


def check_slide_around_ball(value: Any, residual: float | tuple[float, ...]) -> float:
    """The band (m) around the ball that a slide action spans: 0 (off) up to
    SLIDE_AROUND_BALL_LIMIT, or a ValueError saying what is allowed."""
    band = within(value, SLIDE_AROUND_BALL_LIMIT)
    if math.isnan(band):
        raise ValueError(
            f"slide_around_ball must be a number of metres in [0, {SLIDE_AROUND_BALL_LIMIT:g}] "
            f"(0: off), got {value!r}"
        )
    if band and residual:
        raise ValueError(
            "slide_around_ball cannot go with residual: the residual corrects the scripted "
            "baseline's slides, which span the rod's travel"
        )
    return band


def check_slide_skip(value: Any, band: float) -> float:
    """How far (m) to its side of the ball a slide action other than 0 starts, ``band`` being
    the checked ``slide_around_ball``: 0 (off) up to SLIDE_SKIP_LIMIT, or a ValueError saying
    what is allowed, or that it needs the band."""
    skip = within(value, SLIDE_SKIP_LIMIT)
    if math.isnan(skip):
        raise ValueError(
            f"slide_skip must be a number of metres in [0, {SLIDE_SKIP_LIMIT:g}] (0: off; "
            f"{table.FIGURINE_LEG_FLAT_HALF_WIDTH:g}, the flat of the foot), got {value!r}"
        )
    if skip and not band:
        raise ValueError(
            "slide_skip needs slide_around_ball above 0: it moves the band's actions to either "
            "side of the ball"
        )
    return skip


def check_scripted_slides(slide_around_ball: float) -> None:
    """A ValueError where a scripted policy would play with ``slide_around_ball``: its slide
    actions span the rod's travel, and the band would read them around the ball."""
    if slide_around_ball:
        raise ValueError(
            f"the scripted policies slide over the rod's travel, not around the ball: they do "
            f"not play with slide_around_ball={slide_around_ball:g}"
        )


def check_render(mode: Any, width: Any, height: Any) -> tuple[str | None, int, int]:
    """The render options, or a ValueError naming the bad one and what it allows."""
    if mode is not None and mode not in RENDER_MODES:
        raise ValueError(
            f"unknown render_mode {mode!r}; allowed: None, {', '.join(map(repr, RENDER_MODES))}"
        )
    return mode, check_image_side("render_width", width), check_image_side("render_height", height)


def reset_options(options: Any, allowed: Iterable[str]) -> dict[str, Any]:
    """``reset``'s options as a dict (None: none), or a ValueError for anything that is not a
    mapping of names to values (a list of them was read as pairs, or as nothing)."""
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise ValueError(
            f"reset options must be a dict of option names to values, got "
            f"{type(options).__name__} {options!r}; allowed names: {', '.join(allowed)}"
        )
    return dict(options)


def check_stagnation(value: Any) -> int:
    """``stagnation_steps`` as an int, or a ValueError saying what it allows."""
    if not isinstance(value, (int, np.integer)) or value < 0:
        raise ValueError(f"stagnation_steps must be a non-negative integer, got {value!r}")
    return int(value)


# ---------------------------------------------------------------- what a class says


class OptionSignature:
    """An environment base class's ``__signature__``: for each subclass, what
    :func:`option_signature` makes of it (made when first asked for, as
    :func:`inspect.signature` asks); for the base class itself, None (its own)."""

    def __set_name__(self, owner: type, name: str) -> None:
        self._owner = owner
        self._made: weakref.WeakKeyDictionary[type, inspect.Signature] = weakref.WeakKeyDictionary()

    def __get__(self, obj: object, cls: Any = None) -> inspect.Signature | None:
        cls = type(obj) if cls is None else cls
        if cls is self._owner:
            return None
        if cls not in self._made:
            self._made[cls] = option_signature(cls.__init__, getattr(cls, "defaults", DEFAULTS))
        return self._made[cls]


def option_signature(init: Any, defaults: SharedOptions) -> inspect.Signature:
    """The signature of an environment class whose ``__init__`` is ``init``: its own keyword
    arguments, then each shared option its ``**shared: Unpack[...]`` takes (any other
    ``**shared``: :class:`GameOptions`), with its type and its default in ``defaults``. Unpack
    hides those from :func:`inspect.signature`; this lists every option, as
    :func:`option_defaults`, ``foosball envs`` and the tests read them."""
    own = inspect.signature(init, eval_str=True).parameters
    params = [p for p in own.values() if p.kind is p.KEYWORD_ONLY]
    unpacked = [p for p in own.values() if p.kind is p.VAR_KEYWORD]
    if unpacked:
        args = typing.get_args(unpacked[0].annotation)
        declaration = args[0] if args and typing.is_typeddict(args[0]) else GameOptions
        types = typing.get_type_hints(declaration)
        if "opponent" not in types:
            # A task without an opponent takes only False (observation_options says why not).
            types["opponent_prismatic_only"] = Literal[False]
        params += [
            inspect.Parameter(
                f.name,
                inspect.Parameter.KEYWORD_ONLY,
                default=getattr(defaults, f.name),
                annotation=types[f.name],
            )
            for f in dataclasses.fields(SharedOptions)
            if f.name in types
        ]
    return inspect.Signature(params, return_annotation=None)


def option_defaults(cls: type) -> dict[str, Any]:
    """Every option of an environment class with its default: its ``__init__``'s keyword
    arguments."""
    return {name: p.default for name, p in inspect.signature(cls).parameters.items()}


def check_option_names(cls: type, names: Iterable[str]) -> None:
    """Raise TypeError naming the options of ``names`` that ``cls`` does not take, and those it
    does (Python's own error for an unknown keyword names only the first bad one)."""
    allowed = inspect.signature(cls).parameters
    unknown = sorted(set(names) - set(allowed))
    if unknown:
        meant = [m for u in unknown for m in difflib.get_close_matches(u, list(allowed), n=1)]
        hint = f"did you mean {', '.join(map(repr, meant))}? " if meant else ""
        raise TypeError(
            f"{cls.__name__} has no option {', '.join(map(repr, unknown))}; {hint}"
            f"allowed: {', '.join(sorted(allowed))}"
        )


def option_grid(cls: type) -> dict[str, tuple[Any, ...]]:
    """Every option of ``cls`` that takes one of a few values, typed ``bool`` or
    ``Literal[...]``, with those values, its default first: what the tests iterate over."""
    grid = {}
    for name, p in inspect.signature(cls, eval_str=True).parameters.items():
        if p.annotation is bool:
            values: tuple[Any, ...] = (p.default, not p.default)
        elif typing.get_origin(p.annotation) is typing.Literal:
            values = (p.default, *(v for v in typing.get_args(p.annotation) if v != p.default))
        else:
            continue
        if len(values) > 1:
            grid[name] = values
    return grid


# An entry of a docstring's "## Arguments": "- `name`: text" or "- `a`, `b`: text", its text
# going on over the indented lines below.
_ENTRY = re.compile(r"^- ((?:`\w+`(?:, )?)+): (.*)$")


def argument_docs(cls: type) -> dict[str, str]:
    """Each option's entry in the "## Arguments" sections of the docstrings of ``cls`` and its
    bases, the class's own first: ``{name: text}``."""
    docs: dict[str, str] = {}
    for klass in cls.__mro__:
        for names, text in docstring_arguments(klass.__dict__.get("__doc__") or ""):
            for name in names:
                docs.setdefault(name, text)
    return docs


def docstring_arguments(doc: str) -> list[tuple[list[str], str]]:
    """The entries of a docstring's "## Arguments": ``[(names, text)]``, in order."""
    entries: list[tuple[list[str], list[str]]] = []
    inside, current = False, None
    for line in inspect.cleandoc(doc).splitlines():
        if line.startswith("## "):
            inside, current = line.strip() == "## Arguments", None
        elif inside and (match := _ENTRY.match(line)):
            current = (re.findall(r"`(\w+)`", match[1]), [match[2]])
            entries.append(current)
        elif current and line.startswith("  ") and line.strip():
            current[1].append(line.strip())
        else:  # a blank line, a heading or prose ends the entry
            current = None
    return [(names, " ".join(text)) for names, text in entries]


def type_name(annotation: Any) -> str:
    """An option's type as it is written: ``tuple[float, float] | None``, ``Literal[False]``."""
    if isinstance(annotation, type) and not typing.get_args(annotation):
        return annotation.__name__
    return re.sub(r"\b(?:typing|collections\.abc|numpy)\.", "", str(annotation))


def summary(text: str) -> str:
    """The first sentence of an argument's entry, without Markdown's backticks."""
    sentence = re.split(r"(?<=\.)\s", text, maxsplit=1)[0]
    return sentence.replace("`", "")
