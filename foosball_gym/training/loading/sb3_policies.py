"""Rebuilding the policy of any Stable-Baselines3 or sb3-contrib model zip without unpickling.

SB3 pickles the policy's class and its ``policy_kwargs`` into the zip's ``data`` entry, and
beside each pickle writes what it can as text: the class's module and its ``__init__``'s
name, and each keyword argument as JSON, or as ``str()`` where it is not JSON (a class shows
as ``"<class 'torch.nn.modules.activation.ReLU'>"``). That text names the class among those
below and the activation among torch's; the policy is built from them and given the zip's
weights, which must fit it exactly. Whatever the text cannot name (a custom feature
extractor, say) is refused, not guessed.
"""

from __future__ import annotations

import importlib
import inspect
import re
from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

# The policies of the algorithms that act on continuous actions (every foosball_gym
# environment's), by module and class, with the algorithms that train them.
SUPPORTED = {
    "stable_baselines3.common.policies.ActorCriticPolicy": "PPO, A2C, TRPO",
    "stable_baselines3.sac.policies.SACPolicy": "SAC",
    "stable_baselines3.td3.policies.TD3Policy": "TD3, DDPG",
    "sb3_contrib.tqc.policies.TQCPolicy": "TQC",
    "sb3_contrib.crossq.policies.CrossQPolicy": "CrossQ",
    "sb3_contrib.ars.policies.ARSPolicy": "ARS",
    "sb3_contrib.ars.policies.ARSLinearPolicy": "ARS",
    "sb3_contrib.common.recurrent.policies.RecurrentActorCriticPolicy": "RecurrentPPO",
}
RECURRENT = "sb3_contrib.common.recurrent.policies.RecurrentActorCriticPolicy"
ALGORITHMS = "PPO, A2C, SAC, TD3, DDPG, TQC, ARS, TRPO, CrossQ and RecurrentPPO"

_CLASS = re.compile(r"<class '([\w.]+)'>")
_INIT = re.compile(r"<function ([\w.]+)\.__init__ at ")
_ACTIVATIONS = "torch.nn.modules.activation."
# The defaults, so leaving them out changes nothing.
_DEFAULT_EXTRACTOR = "stable_baselines3.common.torch_layers.FlattenExtractor"
# Only training uses the optimiser; another's settings (RMSprop's alpha) would not fit the
# default Adam the policy builds.
_TRAINING_ONLY = ("optimizer_class", "optimizer_kwargs")


def supported_line() -> str:
    """What loads, in a sentence for error messages."""
    return (
        f"foosball_gym loads the MlpPolicy of {ALGORITHMS} (DQN and QR-DQN act on discrete "
        "actions, which no foosball_gym environment takes)"
    )


def policy_class_name(data: Mapping[str, Any]) -> str | None:
    """``module.Class`` of the policy a zip's ``data`` describes; None where it does not say."""
    described = data.get("policy_class")
    if not isinstance(described, Mapping):
        return None
    module = described.get("__module__")
    found = _INIT.match(str(described.get("__init__", "")))
    if not isinstance(module, str) or found is None:
        return None
    return f"{module}.{found.group(1)}"


def is_recurrent(data: Mapping[str, Any]) -> bool:
    """Whether the zip's policy keeps a state between steps (RecurrentPPO's LSTM)."""
    return policy_class_name(data) == RECURRENT


def _vector_space(data: Mapping[str, Any], key: str) -> int:
    """The size of the zip's observation or action space; ValueError where it is not a vector
    Box (what every foosball_gym environment has)."""
    described = data.get(key)
    kind = str(described.get(":type:", "")) if isinstance(described, Mapping) else ""
    shape = described.get("_shape") if isinstance(described, Mapping) else None
    what = "observations" if key == "observation_space" else "actions"
    if "spaces.box.Box" not in kind or not isinstance(shape, list) or len(shape) != 1:
        found = _CLASS.match(kind)
        name = found.group(1).rsplit(".", 1)[-1] if found else "unknown"
        if what == "actions" and name in ("Discrete", "MultiDiscrete", "MultiBinary"):
            raise ValueError(f"it acts on {name} actions: {supported_line()}")
        raise ValueError(
            f"its {what} are of the space {name} {shape or ''}, not a vector (Box) as every "
            "foosball_gym environment's"
        )
    return int(shape[0])


def _policy_kwargs(data: Mapping[str, Any]) -> dict[str, Any]:
    """The ``policy_kwargs`` the model was built with, from their text: JSON values as they
    are, torch's activations by name; ValueError for anything else that is not JSON."""
    described = data.get("policy_kwargs") or {}
    if not isinstance(described, Mapping):
        raise ValueError(f"its policy_kwargs are not readable ({described!r})")
    pickled = ":type:" in described  # then the values that were not JSON are str()
    kwargs: dict[str, Any] = {}
    for key, value in described.items():
        if key.startswith(":") or key in _TRAINING_ONLY:
            continue
        found = _CLASS.fullmatch(value) if pickled and isinstance(value, str) else None
        if found is None:
            if pickled and isinstance(value, str) and value.startswith("<"):
                raise ValueError(
                    f"its policy_kwargs {key}={value} cannot be rebuilt without running code "
                    "from the file"
                )
            kwargs[key] = value
        elif key == "features_extractor_class" and found.group(1) == _DEFAULT_EXTRACTOR:
            continue
        elif key == "activation_fn" and found.group(1).startswith(_ACTIVATIONS):
            import torch.nn

            activation = getattr(torch.nn, found.group(1)[len(_ACTIVATIONS) :], None)
            if not (isinstance(activation, type) and issubclass(activation, torch.nn.Module)):
                raise ValueError(f"its activation {found.group(1)} is not one of torch's")
            kwargs[key] = activation
        else:
            raise ValueError(
                f"its policy_kwargs {key}={found.group(1)} names a class that foosball_gym "
                "does not rebuild (it rebuilds torch's activations and the default feature "
                "extractor)"
            )
    return kwargs


def _constant(_: float) -> float:
    return 0.0


def policy_from_zip(data: Mapping[str, Any], state: Mapping[str, Any]) -> Any:
    """The policy of a Stable-Baselines3 or sb3-contrib model zip, holding its weights.

    Args:
        data: the zip's ``data`` entry, read as JSON (its pickles are not evaluated).
        state: the policy's weights (the zip's ``policy.pth``).

    Raises:
        ValueError: the zip does not say its policy, the policy is not one of
            :data:`SUPPORTED`, or its settings or weights cannot be rebuilt; the message says
            which, in one line.
    """
    name = policy_class_name(data)
    if name is None:
        raise ValueError("its data entry does not say which policy it holds")
    if name not in SUPPORTED:
        raise ValueError(f"it holds the policy {name.rsplit('.', 1)[-1]}: {supported_line()}")
    obs_size = _vector_space(data, "observation_space")
    act_size = _vector_space(data, "action_space")
    kwargs = _policy_kwargs(data)
    module, cls_name = name.rsplit(".", 1)
    try:
        cls = getattr(importlib.import_module(module), cls_name)
    except ImportError as err:
        raise ValueError(
            f'its {cls_name} needs {err.name}, which is not installed: pip install -e ".[train]"'
        ) from None
    parameters = inspect.signature(cls.__init__).parameters
    if "use_sde" in parameters and "use_sde" not in kwargs and "use_sde" in data:
        kwargs["use_sde"] = bool(data["use_sde"])  # the on-policy algorithms pass it apart
    if "lr_schedule" in parameters:
        kwargs["lr_schedule"] = _constant
    unknown = sorted(set(kwargs) - set(parameters))
    if unknown and not any(p.kind is p.VAR_KEYWORD for p in parameters.values()):
        raise ValueError(f"its policy_kwargs {', '.join(unknown)} are not {cls_name}'s")
    try:
        policy = cls(
            spaces.Box(-np.inf, np.inf, (obs_size,), np.float32),
            spaces.Box(-1.0, 1.0, (act_size,), np.float32),
            **kwargs,
        )
        policy.load_state_dict(dict(state))
    except (RuntimeError, TypeError, ValueError) as err:
        why = " ".join(str(err).split())[:300] or type(err).__name__
        raise ValueError(f"its weights do not fit the {cls_name} it describes ({why})") from None
    return policy
