"""The environments' options: the checks of those only the environment uses, and what an
environment class's signature and docstring say about its options.

Every option is checked once, by what uses it: a task's own options by the task, the
observation's by :func:`~foosball_gym.policy_io.observations.observation_options`, the reward
weights by :class:`~foosball_gym.envs.rewards.RewardWeights`, ``camera_noise`` by
:class:`~foosball_gym.camera.CameraNoise`, the physics by the simulator
(:func:`~foosball_gym.physics_options.check_physics`), ``opponent`` by the game, and the rest
here.
"""

from __future__ import annotations

import difflib
import inspect
import math
import re
import typing
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from foosball_gym.camera import check_image_side

RENDER_MODES = ("human", "rgb_array")
RESIDUAL_LIMIT = 2.0


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


def summary(text: str) -> str:
    """The first sentence of an argument's entry, without Markdown's backticks."""
    sentence = re.split(r"(?<=\.)\s", text, maxsplit=1)[0]
    return sentence.replace("`", "")
