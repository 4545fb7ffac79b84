"""Loading this package's model zips with Stable-Baselines3's own ``load``.

The zips hold no pickle (:mod:`foosball_gym.training.run_dir.storage`): SB3's pickled fields,
the spaces, the policy's class and the schedules among them, are left out, and SB3's ``load``
cannot rebuild a Gymnasium space from anything else (``ValueError: The space is of type
<class 'dict'>, not a Gymnasium space``). SB3 takes those fields from ``custom_objects``
instead, and :func:`sb3_objects` rebuilds them from the plain text SB3 writes beside each
pickle, so that::

    model = PPO.load(path, custom_objects=sb3_objects(path))

loads the model as SB3 saved it, weights and optimiser state included, without unpickling
anything (SAC's the same way). Its policy acts on normalised observations where the run
normalised them: :func:`sb3_normalize` wraps a vectorised environment in a ``VecNormalize``
holding the zip's statistics.
"""

from __future__ import annotations

import importlib
import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from foosball_gym.training.loading.sb3_policies import (
    SUPPORTED,
    _policy_kwargs,
    policy_class_name,
)
from foosball_gym.training.run_dir.files import CONFIG_FILE
from foosball_gym.training.run_dir.storage import read_model_zip, zip_statistics

_NUMBER = r"[-+]?(?:\d+\.?\d*(?:[eE][-+]?\d+)?|inf|nan)"
_CONSTANT = re.compile(rf"ConstantSchedule\(val=({_NUMBER})\)")
_LINEAR = re.compile(
    rf"LinearSchedule\(start=({_NUMBER}), end=({_NUMBER}), end_fraction=({_NUMBER})\)"
)


def sb3_objects(path: str | Path) -> dict[str, Any]:
    """What SB3's ``load`` needs in ``custom_objects`` to load the model zip ``path``: the
    fields this package leaves out of its zips as pickles, rebuilt from their plain text.

    The spaces, the policy's class and keyword arguments, and the learning rate and PPO's clip
    ranges are rebuilt as they were (a learning rate that decays over the run from the run's
    ``config.json``); SAC's ``train_freq``, which the zip does not tell, is SB3's default (one
    gradient step a step), the one this package trains with. What only a training in progress
    holds (its last observations, episode buffers, its buffers' classes) is left to SB3, which
    makes them afresh, as for a new ``learn``.

    Raises:
        ValueError: the zip is not a model of this package's kind, or a field cannot be rebuilt
            from its text (a custom policy, say); the message names it.
    """
    path = Path(path)
    data, _, _ = read_model_zip(path)
    objects: dict[str, Any] = {}
    for key, value in data.items():
        # Every field SB3 pickled (a zip from before keeps its pickles): none is unpickled.
        if isinstance(value, dict) and ":type:" in value:
            objects[key] = None  # made afresh by SB3 where needed
    for key in ("observation_space", "action_space"):
        objects[key] = _box(data.get(key), key, path)
    name = policy_class_name(data)
    if name not in SUPPORTED:
        raise ValueError(f"{path} does not name a policy SB3's load rebuilds here ({name})")
    module, cls = name.rsplit(".", 1)
    objects["policy_class"] = getattr(importlib.import_module(module), cls)
    described = data.get("policy_kwargs")
    if isinstance(described, dict) and ":type:" in described:
        objects["policy_kwargs"] = _policy_kwargs(data)
    if not isinstance(data.get("learning_rate"), int | float):
        objects["learning_rate"] = _learning_rate(data, path)
    objects["lr_schedule"] = _float_schedule(objects.get("learning_rate", data["learning_rate"]))
    for key in ("clip_range", "clip_range_vf"):
        if isinstance(data.get(key), dict):
            objects[key] = _float_schedule(_schedule(data[key], key, path))
    if isinstance(data.get("train_freq"), dict):
        from stable_baselines3.common.type_aliases import TrainFreq, TrainFrequencyUnit

        objects["train_freq"] = TrainFreq(1, TrainFrequencyUnit.STEP)
    return objects


def sb3_normalize(path: str | Path, venv: Any) -> Any:
    """``venv`` wrapped in a ``VecNormalize`` holding the model zip's normalisation statistics,
    not updated as it runs; ``venv`` itself where the model was trained without them.

    Raises:
        ValueError: the zip records no statistics (one from before they went into it, or from
            another tool), or a damaged record.
    """
    from stable_baselines3.common.vec_env import VecNormalize

    path = Path(path)
    recorded, stats = zip_statistics(path)
    if not recorded:
        raise ValueError(f"{path} records no normalisation statistics of its own")
    if stats is None:
        return venv
    wrapped = VecNormalize(
        venv,
        training=False,
        norm_obs=stats.norm_obs,
        norm_reward=False,
        clip_obs=stats.clip_obs,
        clip_reward=stats.clip_reward,
        gamma=stats.gamma,
        epsilon=stats.epsilon,
    )
    stats.apply(wrapped)
    return wrapped


def _box(described: Any, key: str, path: Path) -> Any:
    from gymnasium import spaces

    if not isinstance(described, dict) or "spaces.box.Box" not in str(described.get(":type:")):
        raise ValueError(f"{path}: its {key} is not a Box")
    try:
        shape = tuple(int(v) for v in described["_shape"])
        dtype = np.dtype(described["dtype"]).type
        low, high = (_array(described[k], shape) for k in ("low", "high"))
    except (KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{path}: its {key} cannot be read from its text ({err})") from None
    return spaces.Box(low.astype(dtype), high.astype(dtype), shape, dtype)


def _array(text: Any, shape: tuple[int, ...]) -> np.ndarray:
    """An array NumPy printed: ``"[ -10. -400.  inf]"``."""
    values = re.findall(_NUMBER, str(text))
    if len(values) != int(np.prod(shape)):
        raise ValueError(f"{len(values)} numbers in {text!r}, for the shape {shape}")
    return np.array(values, np.float64).reshape(shape)


def _schedule(described: Any, key: str, path: Path) -> Any:
    """A constant or a linear schedule from its text (FloatSchedule's ``value_schedule``)."""
    from stable_baselines3.common.utils import ConstantSchedule, LinearSchedule

    text = str(described.get("value_schedule", "")) if isinstance(described, dict) else ""
    if found := _CONSTANT.fullmatch(text):
        return ConstantSchedule(float(found.group(1)))
    if found := _LINEAR.fullmatch(text):
        return LinearSchedule(*(float(v) for v in found.groups()))
    raise ValueError(
        f"{path}: its {key} ({text or 'a function'}) cannot be rebuilt from its text; give it "
        f"in custom_objects"
    )


def _learning_rate(data: dict[str, Any], path: Path) -> Any:
    """The learning rate of a zip that pickled it (a schedule): from its text, else from the
    run's ``config.json`` (this package's ``lr_schedule: linear``, a function of its own)."""
    try:
        return _schedule(data.get("lr_schedule"), "learning rate", path)
    except ValueError:
        pass
    for config_path in (path.parent / CONFIG_FILE, path.parent.parent / CONFIG_FILE):
        if config_path.is_file():
            config = json.loads(config_path.read_text())
            if config.get("lr_schedule") == "linear":
                from stable_baselines3.common.utils import LinearSchedule

                return LinearSchedule(float(config["learning_rate"]), 0.0, 1.0)
            break
    raise ValueError(
        f"{path}: its learning rate cannot be rebuilt from its text, nor from a config.json "
        "beside it; give learning_rate in custom_objects"
    )


def _float_schedule(value: Any) -> Any:
    from stable_baselines3.common.utils import FloatSchedule

    return FloatSchedule(value)
