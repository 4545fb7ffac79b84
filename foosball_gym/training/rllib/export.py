"""Writing the learner's policy as plain tensors and their description (``policy.pt``,
``policy.json``), which :mod:`foosball_gym.training.loading.rllib_policy` reads without Ray."""

from __future__ import annotations

import io
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from foosball_gym.training.loading.rllib_policy import POLICY_FORMAT, actor_layers
from foosball_gym.training.run_dir.files import (
    POLICY_FILE,
    POLICY_INFO_FILE,
    RLLIB_BACKEND,
    atomic_write_text,
    write_bytes,
)
from foosball_gym.training.run_dir.physics import physics_record


def export_policy(
    module_state: Mapping[str, Any],
    directory: Path,
    *,
    env_id: str,
    env_kwargs: Mapping[str, Any],
    activation: str = "tanh",
    timesteps: int = 0,
    generation: int = 0,
) -> None:
    """Write the actor of an RLlib PPO module as ``policy.pt`` (tensors) and ``policy.json``.

    The last layer's outputs are the Gaussian's means followed by its log standard deviations;
    only the means are kept, since the exported policy acts deterministically.
    """
    import torch as th

    layers = actor_layers(module_state)
    act_size = int(layers[-1][0].shape[0]) // 2
    tensors: dict[str, Any] = {}
    for i, (weight, bias) in enumerate(layers):
        weight = th.as_tensor(np.asarray(weight), dtype=th.float32)
        bias = th.as_tensor(np.asarray(bias), dtype=th.float32)
        if i == len(layers) - 1:
            weight, bias = weight[:act_size], bias[:act_size]
        tensors[f"layers.{i}.weight"] = weight.clone()
        tensors[f"layers.{i}.bias"] = bias.clone()
    info = {
        "format": POLICY_FORMAT,
        "backend": RLLIB_BACKEND,
        "kind": "mlp",
        "observation_size": int(layers[0][0].shape[1]),
        "action_size": act_size,
        "hidden_sizes": [int(w.shape[0]) for w, _ in layers[:-1]],
        "activation": activation,
        "output": "identity, clipped to [-1, 1]",
        "obs_mean": None,
        "obs_std": None,
        "clip_obs": None,
        "env_id": env_id,
        "env_kwargs": dict(env_kwargs),
        "timesteps": int(timesteps),
        "generation": int(generation),
        "physics": physics_record(),
    }
    directory.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    th.save(tensors, buffer)
    write_bytes(directory / POLICY_FILE, buffer.getvalue())
    atomic_write_text(directory / POLICY_INFO_FILE, json.dumps(info, indent=2))
