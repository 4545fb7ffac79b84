"""Play recorded as a Minari dataset, for imitation learning and offline reinforcement learning.

A dataset holds whole seeded episodes of one environment with its options: observations,
actions, rewards, ends and every step's info, and the environment's spec, so that
``dataset.recover_environment()`` makes the environment again. Needs the ``datasets`` extra
(Minari, with h5py and JAX, which its recorder uses).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import warnings
from collections.abc import Callable, Iterator, Mapping
from importlib.util import find_spec
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from foosball_gym.progress import Progress
from foosball_gym.registration import ENV_IDS, __version__, check_env_id, check_env_options
from foosball_gym.table import PHYSICS_REVISION

Policy = Callable[[np.ndarray], Any]

# Minari keeps its datasets where this variable says, or in ~/.minari/datasets.
DATASETS_PATH_VARIABLE = "MINARI_DATASETS_PATH"


def require_datasets_extra() -> None:
    """Raise ImportError naming the ``datasets`` extra where Minari or what it records with is
    missing."""
    missing = [name for name in ("minari", "h5py", "jax") if find_spec(name) is None]
    if missing:
        raise ImportError(
            f"recording a dataset needs Minari with h5py and JAX ({', '.join(missing)} "
            'missing); install them with: pip install -e ".[datasets]"'
        )


#: The longest part of a dataset id: a folder's name, well within a file system's 255 bytes.
MAX_ID_PART = 200


def check_dataset_id(dataset_id: str) -> None:
    """Raise ValueError where ``dataset_id`` is not of Minari's form ``NAMESPACE/NAME-vN`` (the
    namespace optional, and made of one or more folders)."""
    from minari.dataset.minari_dataset import DATASET_ID_RE

    match = DATASET_ID_RE.fullmatch(dataset_id) if isinstance(dataset_id, str) else None
    if match is None or match["version"] is None:
        raise ValueError(
            "a dataset id is NAMESPACE/NAME-vN: letters, digits, - and _, a namespace of two "
            f"characters or more (e.g. foosball/block/scripted-v0), got {dataset_id!r}"
        )
    # Each part is a folder's name, which a file system keeps to 255 bytes.
    longest = max(dataset_id.split("/"), key=len)
    if len(longest) > MAX_ID_PART:
        raise ValueError(
            f"each part of a dataset id (between the /) is a folder's name, of at most "
            f"{MAX_ID_PART} characters; {longest[:20]}... has {len(longest)}"
        )


def datasets_root(data_path: str | Path | None = None) -> Path:
    """Where datasets are kept: ``data_path``, else Minari's own place (the environment
    variable ``MINARI_DATASETS_PATH``, or ``~/.minari/datasets``)."""
    if data_path is not None:
        return Path(data_path).expanduser().absolute()
    variable = os.environ.get(DATASETS_PATH_VARIABLE)
    root = Path.home() / ".minari" / "datasets" if variable is None else Path(variable)
    return root.expanduser().absolute()


def dataset_path(dataset_id: str, data_path: str | Path | None = None) -> Path:
    """The folder of the dataset ``dataset_id`` under :func:`datasets_root`."""
    return datasets_root(data_path) / dataset_id


def record_dataset(
    policy: Policy,
    env_id: str,
    dataset_id: str,
    env_kwargs: Mapping[str, Any] | None = None,
    episodes: int = 100,
    seed: int = 0,
    *,
    policy_name: str = "policy",
    author: str | None = None,
    author_email: str | None = None,
    description: str | None = None,
    data_path: str | Path | None = None,
    overwrite: bool = False,
    progress: bool = False,
) -> Any:
    """Record ``episodes`` episodes of ``policy`` playing ``env_id``, seeded ``seed, seed + 1,
    ...``, as the Minari dataset ``dataset_id``, infos included.

    The action recorded is the one the rods are given: the policy's, clipped to the action
    space as the environment clips it. The dataset is written whole or not at all: it is
    recorded beside the datasets and moved into place once complete, so that a failure
    leaves nothing behind and, with ``overwrite``, the dataset it replaces intact.

    Args:
        policy: a callable from one observation to one action.
        env_id: the environment.
        dataset_id: the dataset's id, ``NAMESPACE/NAME-vN`` (see :func:`check_dataset_id`).
        env_kwargs: the environment's options, as keyword arguments of ``gymnasium.make``;
            they must be plain values (the dataset stores them in the environment's spec).
        episodes: how many episodes, 1 or more.
        seed: the first episode's seed, 0 or more.
        policy_name: what played, stored as the dataset's ``algorithm_name``.
        author: the dataset's author (None: not stored).
        author_email: the author's contact (None: not stored).
        description: what the dataset is (None: what played, where, with which seeds, and the
            package's version and physics revision).
        data_path: the folder of Minari's datasets to write into (None: Minari's own, see
            :func:`datasets_root`).
        overwrite: replace a dataset of the same id; without it such a dataset is an error.
        progress: show the episodes recorded on standard error, a bar on a terminal and a
            line now and then elsewhere (:class:`~foosball_gym.progress.Progress`).

    Returns:
        The dataset as ``minari.load_dataset`` gives it (a ``minari.MinariDataset``).

    Raises:
        ValueError: a bad id, episode count or seed, an environment that is not registered,
            an option with a bad value (TypeError: one the environment does not take) or that
            is not plain data (a callable ``opponent``), a policy that says it takes
            observations of another size, or a path that exists and is not a dataset; all
            before the first episode.
        FileExistsError: the dataset exists and ``overwrite`` is not given.
        ImportError: Minari is not installed (the ``datasets`` extra).
    """
    require_datasets_extra()
    import minari

    check_dataset_id(dataset_id)
    if isinstance(episodes, bool) or not isinstance(episodes, (int, np.integer)) or episodes < 1:
        raise ValueError(f"episodes must be a whole number, at least 1, got {episodes!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a whole number, 0 or more, got {seed!r}")
    check_env_id(env_id)
    if env_id in ENV_IDS:
        check_env_options(env_id, env_kwargs)  # before the first episode, building nothing
    root = datasets_root(data_path)
    target = root / dataset_id
    check_replaceable(target, dataset_id, overwrite)
    kwargs = dict(env_kwargs or {})
    if description is None:
        options = ", ".join(f"{k}={v!r}" for k, v in kwargs.items()) or "its default options"
        description = (
            f"{policy_name} playing {env_id} with {options}: {episodes} episodes seeded "
            f"{seed} to {seed + episodes - 1}; foosball_gym {__version__}, physics revision "
            f"{PHYSICS_REVISION}."
        )

    root.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=".recording-", dir=root))
    try:
        with _minari_root(staging):
            env = gym.make(env_id, **kwargs)
            try:
                _check_can_record(policy, env_id, env)
                collector = minari.DataCollector(env, record_infos=True)
            except BaseException:
                env.close()
                raise
            try:
                _play(collector, policy, episodes, seed, progress)
                with warnings.catch_warnings():
                    # Advice for datasets to be published; the fields left out are not known.
                    warnings.filterwarnings("ignore", message=r"`\w+` is set to None")
                    collector.create_dataset(
                        dataset_id,
                        algorithm_name=policy_name,
                        author=author,
                        author_email=author_email,
                        description=description,
                        requirements=[f"foosball_gym=={__version__}"],
                    )
            finally:
                collector.close()
        _move_into_place(staging, dataset_id, root)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    with _minari_root(root):
        return minari.load_dataset(dataset_id)


def check_replaceable(target: Path, dataset_id: str, overwrite: bool) -> None:
    """Raise where a dataset cannot be written to ``target``: FileExistsError where one is
    there and ``overwrite`` is not given, ValueError where something else is there."""
    if not target.exists():
        return
    if not (target / "data").is_dir():
        raise ValueError(
            f"{target} exists and is not a Minari dataset (it has no data folder): "
            f"not writing dataset {dataset_id} over it"
        )
    if not overwrite:
        raise FileExistsError(
            f"dataset {dataset_id} exists already at {target}; give another id or version, "
            "or replace it (overwrite=True)"
        )


def _check_can_record(policy: Policy, env_id: str, env: gym.Env) -> None:
    assert env.spec is not None  # made by gymnasium.make
    try:
        env.spec.to_json()
    except (TypeError, ValueError) as err:
        # Minari would only warn, and the dataset could not make its environment again.
        raise ValueError(
            f"the dataset keeps {env_id}'s options in its spec, as JSON, and one of them is "
            f"not plain data ({err}): give numbers, strings, lists and dicts"
        ) from None
    expected = getattr(policy, "observation_size", None)
    size = int(np.prod(env.observation_space.shape or ()))
    if expected is not None and expected != size:
        raise ValueError(
            f"the policy expects observations of size {expected}, but {env_id} gives {size}: "
            f"give one for {env_id}"
        )


def _play(collector: gym.Env, policy: Policy, episodes: int, seed: int, progress: bool) -> None:
    space = collector.action_space
    assert isinstance(space, gym.spaces.Box)  # every foosball environment's
    with Progress(episodes, "dataset", "episodes", enabled=progress) as count:
        for i in range(episodes):
            obs, _ = collector.reset(seed=seed + i)
            done = False
            while not done:
                action = np.asarray(policy(obs), dtype=space.dtype).reshape(space.shape)
                # What the environment plays: it clips as well, so the dataset holds the
                # action the rods were given, inside the action space.
                action = np.clip(action, space.low, space.high)
                obs, _, terminated, truncated, _ = collector.step(action)
                done = terminated or truncated
            count.update()


@contextlib.contextmanager
def _minari_root(path: Path) -> Iterator[None]:
    """Point Minari at ``path`` for a while: it reads its folder from the environment."""
    before = os.environ.get(DATASETS_PATH_VARIABLE)
    os.environ[DATASETS_PATH_VARIABLE] = str(path)
    try:
        yield
    finally:
        if before is None:
            del os.environ[DATASETS_PATH_VARIABLE]
        else:
            os.environ[DATASETS_PATH_VARIABLE] = before


def _move_into_place(staging: Path, dataset_id: str, root: Path) -> None:
    """Move the dataset recorded under ``staging`` to ``root``, replacing one of the same id
    only once the new one is there to take its place."""
    from minari.dataset.minari_dataset import parse_dataset_id
    from minari.namespace import create_namespace, list_local_namespaces

    namespace = parse_dataset_id(dataset_id)[0]
    with _minari_root(root):
        if namespace is not None and namespace not in list_local_namespaces():
            create_namespace(namespace)
    target = root / dataset_id
    target.parent.mkdir(parents=True, exist_ok=True)
    recorded, replaced = staging / dataset_id, staging / ".replaced"
    if target.exists():
        os.replace(target, replaced)
        try:
            os.replace(recorded, target)
        except BaseException:
            os.replace(replaced, target)
            raise
    else:
        os.replace(recorded, target)
