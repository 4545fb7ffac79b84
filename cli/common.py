"""What the commands share: argument types, errors, and the policies named on the command line."""

from __future__ import annotations

import argparse
import ast
import importlib
import inspect
from collections.abc import Callable, Sequence
from typing import Any


class CliError(Exception):
    """A bad argument or input found after parsing; reported like argparse's errors."""


class LibraryDefault:
    """An option's default that is a library function's own, so it is written down only there.

    Left as the parsed value when the option is not given, it tells the command to leave the
    argument out (see :func:`given`). ``--help`` shows it through ``%(default)s``, reading the
    function's signature only then: the function's module may need an extra to import.

    Args:
        function: ``"module:name"`` of the function.
        parameter: the parameter whose default this is.
        show: how the command line spells the value.
    """

    def __init__(self, function: str, parameter: str, show: Callable[[Any], str] = str) -> None:
        self.function, self.parameter, self.show = function, parameter, show

    def value(self) -> Any:
        module, _, name = self.function.partition(":")
        function = getattr(importlib.import_module(module), name)
        return inspect.signature(function).parameters[self.parameter].default

    def __str__(self) -> str:
        try:
            return self.show(self.value())
        except ImportError:
            return f"{self.function.partition(':')[2]}'s default"


def given(args: argparse.Namespace, *names: str) -> dict[str, Any]:
    """The options among ``names`` the user gave, to pass on as keyword arguments."""
    values = {name: getattr(args, name) for name in names}
    return {k: v for k, v in values.items() if not isinstance(v, LibraryDefault)}


def parse_env_kwargs(items: Sequence[str] | None) -> dict[str, Any]:
    """``["KEY=VALUE", ...]`` to a dict; values are Python literals where they parse as one."""
    out: dict[str, Any] = {}
    for item in items or ():
        key, sep, raw = item.partition("=")
        if not sep or not key.isidentifier():
            raise CliError(f"--env-kwarg takes KEY=VALUE (e.g. ball_start=incoming), got {item!r}")
        try:
            out[key] = ast.literal_eval(raw)
        except (ValueError, SyntaxError):
            out[key] = raw
    return out


def add_env_arguments(parser: argparse.ArgumentParser) -> None:
    """``--env`` and ``--env-kwarg``, for the commands that take a model or the scripted one."""
    parser.add_argument("--env", help="environment id, where the model does not say it")
    parser.add_argument(
        "--env-kwarg",
        action="append",
        metavar="KEY=VALUE",
        help="an environment option (repeatable)",
    )


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _pair(text: str, names: tuple[str, str], example: str) -> tuple[int, int]:
    spelled = "x".join(n.upper() for n in names)
    try:
        first, second = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected {spelled}, e.g. {example}, got {text!r}"
        ) from None
    if first < 1 or second < 1:
        raise argparse.ArgumentTypeError(
            f"{names[0]} and {names[1]} must be positive, got {text!r}"
        )
    return first, second


def size(text: str) -> tuple[int, int]:
    """An image size: ``"640x360"`` to ``(640, 360)``."""
    return _pair(text, ("width", "height"), "640x360")


def grid(text: str) -> tuple[int, int]:
    """A chessboard's inner corners: ``"9x6"`` to ``(9, 6)``."""
    return _pair(text, ("columns", "rows"), "9x6")


def show_size(value: Sequence[int]) -> str:
    return "x".join(str(v) for v in value)


def scripted(env_id: str, env_kwargs: dict[str, Any]) -> Any:
    """The scripted baseline of an environment."""
    from foosball_gym.catalog import scripted_policy

    try:
        return scripted_policy(env_id, env_kwargs)
    except (ValueError, TypeError) as err:
        raise CliError(str(err)) from None


def load_model(spec: str) -> Any:
    """A trained policy (:class:`~foosball_gym.training.models.LoadedPolicy`) from a run
    directory, a model zip or ``builtin:NAME``."""
    from foosball_gym.training import require_train_extra

    require_train_extra()
    from foosball_gym.training.models import ModelLoadError, load_policy

    try:
        return load_policy(spec)
    except ModelLoadError as err:
        raise CliError(str(err)) from None
