"""Runs of RL Zoo (``python -m rl_zoo3.train``): where the model, its environment and its
normalisation are.

RL Zoo 2.x writes a run to ``<log>/<algo>/<env>_<n>/``::

    <env>.zip                       the final model
    best_model.zip                  the best evaluated one (with --eval-freq)
    rl_model_<steps>_steps.zip      checkpoints (with --save-freq)
    <env>/config.yml                the hyperparameters it trained with
    <env>/args.yml                  the command line's arguments: the env id, --env-kwargs
    <env>/vecnormalize.pkl          VecNormalize's statistics (with normalize), a pickle

The two YAML files are read with PyYAML's safe loader, taught the two Python tags they use
(``OrderedDict`` and tuples) and nothing else; the pickle only where trusted.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from foosball_gym.training.run_dir.files import LEGACY_NORM_FILE, NORM_FILE

ARGS_FILE = "args.yml"
HYPERPARAMS_FILE = "config.yml"
BEST_MODEL = "best_model.zip"
# What RL Zoo applies between the environment and the policy that this package does not:
# a model trained through one of them would be evaluated on other observations than it saw.
WRAPPERS = ("env_wrapper", "vec_env_wrapper", "frame_stack")


@dataclass
class ZooRun:
    """What :func:`find_zoo_run` found: the model to load and how to evaluate it.

    ``norm`` is the statistics file (``vecnormalize.pkl``), or None where the run trained
    without ``normalize``.
    """

    folder: Path
    model: Path
    env_id: str
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    norm: Path | None = None


def _params_dir(folder: Path) -> Path | None:
    """The run's ``<env>/`` folder (the one holding args.yml and config.yml), if it has one."""
    if not folder.is_dir():
        return None
    found = [
        d
        for d in sorted(folder.iterdir())
        if d.is_dir() and (d / ARGS_FILE).is_file() and (d / HYPERPARAMS_FILE).is_file()
    ]
    return found[0] if len(found) == 1 else None


def is_zoo_run(path: str | Path) -> bool:
    """Whether ``path`` is an RL Zoo run folder, or a model zip in one."""
    path = Path(path)
    return _params_dir(path if path.is_dir() else path.parent) is not None


def _read_yaml(path: Path) -> dict[str, Any]:
    import yaml

    class Loader(yaml.SafeLoader):
        """The safe loader, with RL Zoo's OrderedDict and tuples: data, never code."""

    def ordered(loader: yaml.SafeLoader, node: yaml.SequenceNode) -> dict[str, Any]:
        (pairs,) = loader.construct_sequence(node, deep=True)
        return {key: value for key, value in pairs}

    def as_tuple(loader: yaml.SafeLoader, node: yaml.SequenceNode) -> tuple[Any, ...]:
        return tuple(loader.construct_sequence(node, deep=True))

    Loader.add_constructor("tag:yaml.org,2002:python/object/apply:collections.OrderedDict", ordered)
    Loader.add_constructor("tag:yaml.org,2002:python/tuple", as_tuple)
    try:
        loaded = yaml.load(path.read_text(), Loader=Loader)  # noqa: S506 - a safe loader
    except (yaml.YAMLError, ValueError, TypeError) as err:
        first = " ".join(str(err).split())[:200]
        raise ValueError(f"cannot read {path} as RL Zoo writes it ({first})") from None
    if not isinstance(loaded, dict):
        raise ValueError(f"{path} is not a mapping of settings")
    return loaded


def find_zoo_run(path: str | Path) -> ZooRun:
    """The model, environment and normalisation of an RL Zoo run folder or of a zip in one.

    The folder stands for its final model, ``<env>.zip``. The environment's options are the
    hyperparameters' ``env_kwargs``, replaced by ``--env-kwargs`` where given, as RL Zoo's
    ``enjoy`` takes them. The statistics are the run's ``<env>/vecnormalize.pkl`` (for a
    checkpoint, ``rl_model_vecnormalize_<steps>_steps.pkl`` where SB3 saved one), as
    ``enjoy`` reads them.

    Raises:
        ValueError: not an RL Zoo run, its files cannot be read, there is no model, it trained
            with a wrapper this package does not apply, or it normalised observations and its
            statistics are missing.
    """
    path = Path(path)
    folder = path if path.is_dir() else path.parent
    params = _params_dir(folder)
    if params is None:
        raise ValueError(
            f"{path} is not an RL Zoo run (no <env>/{ARGS_FILE} and {HYPERPARAMS_FILE} in {folder})"
        )
    model = path if not path.is_dir() else folder / f"{params.name}.zip"
    if not model.is_file():
        zips = sorted(p.name for p in folder.glob("*.zip"))
        has = f"give one of {', '.join(zips)}" if zips else "it holds no model zip"
        raise ValueError(f"the RL Zoo run {folder} has no final model {model.name}: {has}")
    args, hyper = _read_yaml(params / ARGS_FILE), _read_yaml(params / HYPERPARAMS_FILE)
    for key in WRAPPERS:
        if hyper.get(key):
            raise ValueError(
                f"the RL Zoo run {folder} trained with {key} {hyper[key]!r}, which foosball_gym "
                "does not apply: evaluate it with python -m rl_zoo3.enjoy"
            )
    env_id = str(args.get("env") or params.name).rsplit(":", 1)[-1]
    env_kwargs = dict(hyper.get("env_kwargs") or {})
    if args.get("env_kwargs") is not None:
        env_kwargs = dict(args["env_kwargs"])
    norm = None
    if hyper.get("normalize"):
        candidates = [params / NORM_FILE, params / LEGACY_NORM_FILE]
        if model.stem.startswith("rl_model_"):
            steps = model.stem.removeprefix("rl_model_")
            candidates.insert(0, folder / f"rl_model_vecnormalize_{steps}.pkl")
        norm = next((c for c in candidates if c.is_file()), None)
        if norm is None:
            raise ValueError(
                f"the RL Zoo run {folder} trained with normalize, but its statistics "
                f"({params.name}/{LEGACY_NORM_FILE}) are missing: without them the model "
                "would see other observations than it trained on"
            )
    return ZooRun(folder, model, env_id, env_kwargs, norm)
