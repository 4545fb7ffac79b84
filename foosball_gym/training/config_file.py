"""Training hyperparameters kept in a YAML file, one run to a file: ``foosball train --config``.

The format is the package's own; RL Zoo's files for the same tasks are in
:mod:`foosball_gym.rl_zoo`.

A file maps :class:`~foosball_gym.training.config.TrainConfig` field names to values
(``n_envs: 8``, ``net_arch: [256, 128, 64]``), ``env_kwargs`` to a mapping of environment
options, and may name ``env_id``. ``builtin:NAME`` names a file shipped in
``foosball_gym/configs/NAME.yaml``: one per environment id, the from-scratch recipes, and
``paper-ppo``. Values given on the command line override
the file's; ``env_kwargs`` merge key by key.

Needs PyYAML (the ``train`` extra), imported only when a file is read.
"""

from __future__ import annotations

import copy
import re
import types
import typing
from dataclasses import fields
from importlib import resources
from pathlib import Path
from typing import Any

from foosball_gym.registration import check_env_id
from foosball_gym.training.config import TrainConfig

SHIPPED = "builtin:"
# PyYAML reads YAML 1.1, where 1e-4 (no dot) is a string; YAML 1.2, and every hyperparameter
# file written by hand, means a number.
_EXPONENT = re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$")
_MERGE = "tag:yaml.org,2002:merge"
_WRONG = object()  # what _typed returns for a value of another type than its field's

# What a value of each field type is spelled as, and how it is read (None where it is not).
_KINDS: dict[Any, tuple[str, Any]] = {
    int: ("a whole number", lambda v: v if type(v) is int else None),
    float: ("a number", lambda v: float(v) if type(v) in (int, float) else None),
    bool: ("true or false", lambda v: v if type(v) is bool else None),
    str: ("a string", lambda v: v if isinstance(v, str) else None),
    tuple[int, ...]: (
        "a list of whole numbers",
        lambda v: tuple(v) if isinstance(v, list) and all(type(n) is int for n in v) else None,
    ),
    dict[str, Any]: (
        "a mapping of option names to values",
        lambda v: dict(v) if isinstance(v, dict) and all(isinstance(k, str) for k in v) else None,
    ),
}


class ConfigFileError(ValueError):
    """A configuration file that cannot be used: the message names the file and, where one
    is to blame, the key, and says what is allowed."""

    def __init__(self, source: str, key: str | None, problem: str) -> None:
        # "n_envs must be at least 1" needs no "n_envs: " before it.
        if key is None or problem.startswith(f"{key} "):
            super().__init__(f"{source}: {problem}")
        else:
            super().__init__(f"{source}: {key}: {problem}")


def shipped_configs() -> list[str]:
    """The names of the shipped files (an environment id's settings, a recipe, or
    ``paper-ppo``, the paper's PPO settings): ``builtin:NAME`` reads one."""
    return sorted(p.stem for p in _shipped_folder().glob("*.yaml"))


def config_path(spec: str) -> Path:
    """The file ``spec`` names: a path, or ``builtin:NAME`` for a shipped one."""
    if spec.startswith(SHIPPED):
        path = _shipped_folder() / f"{spec[len(SHIPPED) :]}.yaml"
        if not path.is_file():
            shipped = ", ".join(SHIPPED + name for name in shipped_configs())
            raise ConfigFileError(spec, None, f"no shipped configuration; shipped: {shipped}")
        return path
    path = Path(spec)
    if not path.is_file():
        hint = f" (the shipped one is builtin:{spec})" if spec in shipped_configs() else ""
        raise ConfigFileError(spec, None, f"no such file{hint}")
    return path


def read_config_file(spec: str) -> dict[str, Any]:
    """The settings of the file ``spec`` names, each read as its TrainConfig field's type.

    Raises:
        ConfigFileError: the file is missing or not YAML, a key is no TrainConfig field, or a
            value is not of its field's type.
        ImportError: PyYAML is not installed.
    """
    path = config_path(spec)
    try:
        text = path.read_text()
    except OSError as err:
        raise ConfigFileError(spec, None, f"cannot be read: {err.strerror}") from None
    data = _parse(text, spec)
    if data is None:  # empty, or comments only
        data = {}
    if not isinstance(data, dict):
        raise ConfigFileError(spec, None, "must be a mapping of TrainConfig fields to values")
    hints = typing.get_type_hints(TrainConfig)
    names = [f.name for f in fields(TrainConfig)]
    unknown = [str(key) for key in data if key not in names]
    if unknown:
        raise ConfigFileError(
            spec,
            None,
            f"unknown key{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))}; "
            f"allowed: {', '.join(names)}",
        )
    typed = {}
    for key, value in data.items():
        typed[key] = _typed(value, hints[key])
        if typed[key] is _WRONG:
            raise ConfigFileError(spec, key, f"takes {_spelled(hints[key])}, got {value!r}")
    return typed


def load_train_config(
    spec: str,
    env_id: str | None = None,
    overrides: dict[str, Any] | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> TrainConfig:
    """The configuration of the file ``spec`` with the command line's values over it.

    Checked with :meth:`TrainConfig.check` (on a copy: the result is what was asked for, as
    :meth:`TrainConfig.check` would complete it in training); a check that fails for a value
    of the file names the file and the key.

    Args:
        spec: a path, or ``builtin:NAME``.
        env_id: the command line's environment id; the file's ``env_id`` where None. Where
            both are given they must agree.
        overrides: TrainConfig fields the command line set.
        env_kwargs: environment options the command line set, over the file's.

    Raises:
        ConfigFileError: see :func:`read_config_file`; or a value out of range, or the ids
            disagree.
        ValueError, TypeError: a value of the command line is out of range.
    """
    values = read_config_file(spec)
    overrides, env_kwargs = dict(overrides or {}), dict(env_kwargs or {})
    file_env_id = values.pop("env_id", None)
    if env_id and file_env_id and env_id != file_env_id:
        raise ConfigFileError(
            spec,
            "env_id",
            f"is {file_env_id!r}, but the command line asks for {env_id!r}; leave one out "
            "or make them agree",
        )
    if not (env_id or file_env_id):
        raise ConfigFileError(
            spec, None, "names no env_id; give the environment id on the command line"
        )
    file_env_kwargs = values.pop("env_kwargs", {})
    config = TrainConfig(
        env_id=env_id or file_env_id,
        env_kwargs={**file_env_kwargs, **env_kwargs},
        **{**values, **overrides},
    )
    try:
        copy.deepcopy(config).check()
    except (ValueError, TypeError) as err:
        own = {k: v for k, v in values.items() if k not in overrides}
        own_kwargs = {k: v for k, v in file_env_kwargs.items() if k not in env_kwargs}
        file_named_env = file_env_id is not None and env_id is None
        raise _blame(spec, config.env_id, file_named_env, own, own_kwargs, err) from None
    return config


def _blame(
    spec: str,
    env_id: str,
    file_named_env: bool,
    values: dict[str, Any],
    env_kwargs: dict[str, Any],
    err: Exception,
) -> Exception:
    """``err`` naming the file and the key where one value the file holds (and the command
    line leaves) fails the check on its own, as it failed with the rest; ``err`` itself where
    none does (a value of the command line, or two values together, whose message names both).

    A value can fail on its own for a reason the rest of the file answers (a ``batch_size``
    that the file's ``n_steps`` and ``n_envs`` hold): such a failure is not the file's error
    and must not hide it.
    """
    try:
        check_env_id(env_id)
    except ValueError as bad_id:
        return ConfigFileError(spec, "env_id", str(bad_id)) if file_named_env else err
    alone = [({key: value}, key) for key, value in values.items()]
    if env_kwargs:
        alone.append(({"env_kwargs": env_kwargs}, "env_kwargs"))
    for value, key in alone:
        try:
            TrainConfig(env_id=env_id, **value).check()
        except (ValueError, TypeError) as own:
            if str(own) == str(err):
                return ConfigFileError(spec, key, str(own))
    return err


def _shipped_folder() -> Path:
    return Path(str(resources.files("foosball_gym") / "configs"))


def _typed(value: Any, hint: Any) -> Any:
    """``value`` as a field of type ``hint`` holds it; ``_WRONG`` where it is not one."""
    allowed = typing.get_args(hint) if _is_union(hint) else (hint,)
    if value is None:
        return None if type(None) in allowed else _WRONG
    for kind in allowed:
        if kind is not type(None):
            read = _KINDS[kind][1](value)
            if read is not None:
                return read
    return _WRONG


def _spelled(hint: Any) -> str:
    allowed = typing.get_args(hint) if _is_union(hint) else (hint,)
    words = [_KINDS[kind][0] for kind in allowed if kind is not type(None)]
    if type(None) in allowed:
        words.append("null")
    return " or ".join(words)


def _is_union(hint: Any) -> bool:
    return typing.get_origin(hint) in (typing.Union, types.UnionType)


def _parse(text: str, spec: str) -> Any:
    try:
        import yaml
    except ImportError:
        raise ImportError("configuration files need PyYAML: pip install -e '.[train]'") from None

    class Loader(yaml.SafeLoader):
        """YAML 1.2's numbers, and no key given twice (PyYAML keeps the last, silently)."""

        def construct_mapping(self, node: Any, deep: bool = False) -> dict[Any, Any]:
            own = [k for k, _ in node.value if k.tag != _MERGE]
            mapping = super().construct_mapping(node, deep=deep)
            keys = [self.construct_object(k, deep=deep) for k in own]
            for i, key in enumerate(keys):
                if key in keys[:i]:
                    raise yaml.MarkedYAMLError(
                        problem=f"key {key!r} is given twice", problem_mark=own[i].start_mark
                    )
            return mapping

    Loader.add_implicit_resolver("tag:yaml.org,2002:float", _EXPONENT, list("-+0123456789."))
    try:
        return yaml.load(text, Loader=Loader)
    except yaml.YAMLError as err:
        # Told on one line, as the CLI reports errors: PyYAML's own message spans several.
        mark = getattr(err, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        parts = [getattr(err, "context", None), getattr(err, "problem", None)]
        problem = "; ".join(p for p in parts if p) or " ".join(str(err).split())
        raise ConfigFileError(spec, None, f"is not valid YAML: {where}{problem}") from None
