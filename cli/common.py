"""What the commands share: argument types, errors, and the policies named on the command line."""

from __future__ import annotations

import argparse
import ast
import difflib
import errno
import importlib
import inspect
import math
import os
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn


class CliError(Exception):
    """A bad argument or input found after parsing; reported like argparse's errors."""


class Parser(argparse.ArgumentParser):
    """argparse's parser for the command and its subcommands (``add_subparsers`` makes them
    of the class of their parent): no abbreviated options, errors in one line without the
    usage, and a suggestion where a name is misspelt.

    Abbreviations are off because they change meaning as options are added: ``--env`` was
    taken for ``--env-kwarg`` by ``foosball train``, ``--timestep`` for ``--timesteps``.

    ``hints`` maps an option the parser does not take to what to say of it, where a close
    spelling would mislead (``foosball train --env``: the id is its first argument).
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)
        self.hints: dict[str, str] = {}

    def error(self, message: str) -> NoReturn:
        # The usage would be 26 lines over the one that says what is wrong; --help has it.
        self.exit(2, f"{self.prog}: error: {message}\n")

    def parse_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> argparse.Namespace:
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:
            # Reported by the subcommand's parser, which knows the options meant.
            command = self._command_parser(parsed)
            command.error(command.unrecognized(extras))
        return parsed

    def unrecognized(self, extras: Sequence[str]) -> str:
        """The error for arguments this parser does not take, with the option each misspelt
        one may have meant."""
        options = [o for a in self._actions for o in a.option_strings if o.startswith("--")]
        notes = []
        for extra in extras:
            name = extra.partition("=")[0]
            if name in self.hints:
                notes.append(self.hints[name])
            elif name.startswith("-"):
                close = difflib.get_close_matches(name, options, n=1)
                if close:
                    notes.append(f"did you mean {close[0]}?")
        return f"unrecognized arguments: {' '.join(extras)}" + "".join(f"; {n}" for n in notes)

    def _command_parser(self, parsed: argparse.Namespace) -> Parser:
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                chosen = action.choices.get(str(getattr(parsed, action.dest, "")))
                if isinstance(chosen, Parser):
                    return chosen._command_parser(parsed)
        return self

    def _check_value(self, action: argparse.Action, value: Any) -> None:
        # argparse's own check, with the choice a misspelt value may have meant.
        choices = action.choices
        if choices is None or value in choices:
            return
        names = [str(c) for c in choices]
        close = difflib.get_close_matches(str(value), names, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise argparse.ArgumentError(
            action,
            f"invalid choice: {value!r}{hint} (choose from {', '.join(map(repr, names))})",
        )


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
    if out.get("render_mode") == "human" and not _has_display():
        raise CliError(
            "--env-kwarg render_mode=human needs a display and DISPLAY is not set; "
            "run under xvfb-run, or use render_mode=rgb_array"
        )
    return out


def _has_display() -> bool:
    # PyBullet's GUI is an X11 window on Linux; elsewhere the system provides one.
    return not sys.platform.startswith("linux") or bool(os.environ.get("DISPLAY"))


def add_env_arguments(parser: argparse.ArgumentParser) -> None:
    """``--env``, ``--env-kwarg`` and ``--trust-model``, for the commands that take a model or
    the scripted one."""
    parser.add_argument("--env", help="environment id, where the model does not say it")
    parser.add_argument(
        "--env-kwarg",
        action="append",
        metavar="KEY=VALUE",
        help="an environment option (repeatable)",
    )
    add_trust_argument(parser)


def add_trust_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--trust-model",
        action="store_true",
        help="also read model files stored with pickle (runs from before plain files, an RL "
        "Zoo run's vecnormalize.pkl), which can run any code: only for files from a source you "
        "trust",
    )


def check_writable(option: str, path: str) -> None:
    """Fail before long work, not after it, where ``option``'s file cannot be written."""
    target = Path(path)
    if target.is_dir():
        raise CliError(f"{option} {path} is a directory; give a file name")
    if not target.parent.is_dir():
        raise CliError(f"{option} {path}: there is no folder {target.parent}")
    try:
        if target.exists():
            # Opened to append and closed, it is neither changed nor emptied.
            with open(target, "ab"):
                pass
        else:
            _try_creating(target.parent, file=True)
    except OSError as err:
        raise CliError(f"{option} {path} cannot be written: {err.strerror}") from None


def check_directory(option: str, path: str | Path) -> None:
    """Fail where ``option``'s directory can be neither used nor created, without creating it."""
    target = Path(path)
    existing = target
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise CliError(f"{option} {path}: {existing} is a file, not a folder")
    try:
        _try_creating(existing, file=False)
    except OSError as err:
        raise CliError(f"{option} {path} cannot be written: {err.strerror}") from None


def _try_creating(folder: Path, file: bool) -> None:
    """Create a file (or a folder) of a name no one uses in ``folder``, and remove it: what
    the file system allows is asked by trying, since permissions do not say it all (a
    read-only mount, /proc, root's rights)."""
    if file:
        fd, name = tempfile.mkstemp(dir=folder, prefix=".foosball-probe-")
        os.close(fd)
        os.unlink(name)
    else:
        os.rmdir(tempfile.mkdtemp(dir=folder, prefix=".foosball-probe-"))


def storage_failure(option: str, run: Path, err: OSError) -> str:
    """What to tell of a run directory whose storage failed during training (full, read-only,
    not permitted), in one line: what could not be written, why, and how the run goes on.

    Raises:
        OSError: ``err`` is no failure of the storage (it names no file and is none of
            :data:`~foosball_gym.training.run_dir.files.STORAGE_ERRNOS`): a fault to report
            as it is.
    """
    from foosball_gym.training.run_dir.files import has_checkpoint, storage_error

    if err.filename is None and not storage_error(err):
        raise err
    where = err.filename or run
    line = f"{option} {run}: cannot write {where}: {err.strerror or err}"
    if err.errno in (errno.ENOSPC, errno.EDQUOT) and has_checkpoint(run):
        line += (
            "; once there is room, go on from its last checkpoint with: "
            f"foosball train --resume {run}"
        )
    return line


def whole_number(text: str) -> int:
    """A whole number, 0 or more, also written as ``1e5`` or ``100_000``: counts of steps are
    often written so."""
    try:
        return _whole(text, minimum=0)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def positive_int(text: str) -> int:
    """A whole number, at least 1, also written as ``1e5`` or ``100_000``."""
    try:
        return _whole(text, minimum=1)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def _whole(text: str, minimum: int) -> int:
    try:
        value = int(text)
    except ValueError:
        try:
            number = float(text)
        except ValueError:
            raise ValueError(f"expected a whole number, got {text!r}") from None
        if not number.is_integer():
            raise ValueError(f"expected a whole number, got {text!r}") from None
        value = int(number)
    if value < minimum:
        raise ValueError(f"must be {_least(minimum)}, got {value}")
    return value


def _least(minimum: int) -> str:
    return "0 or more" if minimum == 0 else f"at least {minimum}"


def seed(text: str) -> int:
    """A seed: a whole number, 0 or more (NumPy's generators take no negative ones)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {value}")
    return value


def seconds(text: str) -> float:
    """A duration in seconds: a finite number, 0 or more."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not 0 <= value < math.inf:
        raise argparse.ArgumentTypeError(f"must be a finite number, 0 or more, got {text!r}")
    return value


def positive_number(text: str) -> float:
    """A finite number above 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0 < value < math.inf:
        raise argparse.ArgumentTypeError(f"must be a finite number above 0, got {text!r}")
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


def is_scripted(spec: str | None) -> bool:
    """Whether a policy named on the command line is a scripted one: ``scripted`` or
    ``scripted:N``."""
    from foosball_gym.policies.ladder import is_scripted as named

    return named(spec)


def scripted_spec(text: str) -> str:
    """An argument naming a scripted team: ``scripted`` or ``scripted:N``."""
    from foosball_gym.policies.ladder import parse_scripted

    try:
        parse_scripted(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    return text


def scripted(
    env_id: str, env_kwargs: dict[str, Any], on_table: bool = False, spec: str = "scripted"
) -> Any:
    """The scripted baseline of an environment, or the rung of its scripted ladder ``spec``
    names (``scripted:N``); for a table's estimated state: ``on_table``."""
    from foosball_gym.policies.ladder import parse_scripted
    from foosball_gym.registration import scripted_policy

    try:
        return scripted_policy(env_id, env_kwargs, on_table, parse_scripted(spec))
    except (ValueError, TypeError) as err:
        raise CliError(str(err)) from None


def load_model(spec: str, trust: bool = False) -> Any:
    """A trained policy (:class:`~foosball_gym.training.loading.LoadedPolicy`) from a run
    directory, a model zip, an RL Zoo run or ``builtin:NAME``; pickled files only with
    ``trust``. Where a run has no final model, prints which of its models plays instead."""
    from foosball_gym.training import require_train_extra

    require_train_extra()
    from foosball_gym.training.loading import ModelLoadError, load_policy

    try:
        loaded = load_policy(spec, trust=trust)
    except ModelLoadError as err:
        raise CliError(str(err)) from None
    except RecursionError:
        raise CliError(f"{spec} cannot be loaded: a JSON file of it is nested too deep") from None
    except ValueError as err:
        # Python's own bound on integers (a 5,000-digit one in a run's config.json).
        if "integer string conversion" not in str(err):
            raise
        raise CliError(
            f"{spec} cannot be loaded: a JSON file of it holds an integer of more than "
            f"{sys.get_int_max_str_digits()} digits"
        ) from None
    if loaded.note:
        print(loaded.note)
    return loaded


def check_model_fits(loaded: Any, env_id: str, env_kwargs: dict[str, Any]) -> None:
    """Fail where a loaded model's observations are not those of the environment it is to play."""
    from foosball_gym.registration import check_env_id

    try:
        check_env_id(env_id)
        loaded.check_env(env_id, env_kwargs)
    except (ValueError, TypeError) as err:
        raise CliError(str(err)) from None
