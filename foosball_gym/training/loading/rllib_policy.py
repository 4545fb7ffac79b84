"""Policies the RLlib backend trained, read without Ray: the exported policy of a run or
checkpoint (``policy.pt`` and ``policy.json``), and its self-play snapshots.

``policy.pt`` holds only tensors (``layers.<i>.weight`` and ``.bias`` of the actor's Linear
layers, read with ``torch.load(weights_only=True)``) and ``policy.json`` describes the
network: sizes, activation, environment. The action is the mean of the Gaussian the actor
outputs, clipped to [-1, 1].
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from foosball_gym.training.run_dir.files import CONFIG_FILE, POLICY_FILE, POLICY_INFO_FILE
from foosball_gym.training.run_dir.physics import warn_physics
from foosball_gym.training.run_dir.storage import check_torch_file
from foosball_gym.training.run_dir.tensors import load_tensors

POLICY_FORMAT = 1

_ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "tanh": np.tanh,
    "relu": lambda x: np.maximum(x, 0.0),
    "linear": lambda x: x,
}


def actor_layers(state: Mapping[str, Any]) -> list[tuple[Any, Any]]:
    """(weight, bias) of the Linear layers of an RLlib PPO module's actor, input first."""

    def linears(prefix: str) -> list[tuple[Any, Any]]:
        found = []
        for key in state:
            if key.startswith(prefix) and key.endswith(".weight"):
                index = int(key[len(prefix) :].split(".")[0])
                found.append((index, state[key], state[key[: -len("weight")] + "bias"]))
        return [(w, b) for _, w, b in sorted(found, key=lambda item: item[0])]

    encoder = linears("encoder.actor_encoder.net.mlp.")
    if not encoder:  # vf_share_layers=True names the one encoder so
        encoder = linears("encoder.encoder.net.mlp.")
    head = linears("pi.net.mlp.")
    if not head:
        raise ValueError("the module has no policy head (pi.net.mlp.*)")
    return encoder + head


class RllibPolicy:
    """An exported RLlib policy: raw observations in, deterministic actions in [-1, 1] out.

    Called with one observation it returns one action; with a batch (N, obs_dim), (N, act_dim).
    ``observation_size`` and ``env_id`` let :func:`~foosball_gym.evaluation.evaluate` check
    that it fits the environment.
    """

    def __init__(
        self,
        weights: list[tuple[np.ndarray, np.ndarray]],
        activation: str,
        *,
        obs_mean: np.ndarray | None = None,
        obs_std: np.ndarray | None = None,
        clip_obs: float | None = None,
        env_id: str | None = None,
        env_kwargs: Mapping[str, Any] | None = None,
        generation: int = 0,
    ) -> None:
        if activation not in _ACTIVATIONS:
            raise ValueError(
                f"unknown activation {activation!r}; allowed: {', '.join(_ACTIVATIONS)}"
            )
        if (obs_mean is None) != (obs_std is None):
            raise ValueError("obs_mean and obs_std are given together or not at all")
        self.weights = weights
        self.activation = activation
        self._act = _ACTIVATIONS[activation]
        self.obs_mean = obs_mean
        self.obs_std = obs_std
        self.clip_obs = clip_obs
        self.env_id = env_id
        self.env_kwargs = dict(env_kwargs or {})
        self.generation = generation

    @property
    def observation_size(self) -> int:
        return int(self.weights[0][0].shape[1])

    @property
    def action_size(self) -> int:
        return int(self.weights[-1][0].shape[0])

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        x = np.asarray(obs, dtype=np.float64)
        single = x.ndim == 1
        if single:
            x = x[None]
        if self.obs_mean is not None:
            assert self.obs_std is not None  # __init__ takes both or neither
            # RLlib's MeanStdFilter: (x - mean) / (std + 1e-8), then clipped.
            x = (x - self.obs_mean) / (self.obs_std + 1e-8)
            if self.clip_obs:
                x = np.clip(x, -self.clip_obs, self.clip_obs)
        x = x.astype(np.float32)
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(self.weights):
            x = x @ w.T + b
            if i < last:
                x = self._act(x)
        actions = np.clip(x, -1.0, 1.0).astype(np.float32)
        return actions[0] if single else actions


def is_rllib_run(path: str | Path) -> bool:
    """Whether ``path`` is a directory holding an exported RLlib policy (a run or checkpoint)."""
    path = Path(path)
    return (path / POLICY_INFO_FILE).is_file() and (path / POLICY_FILE).is_file()


def load_rllib_policy(run_dir: str | Path) -> RllibPolicy:
    """The policy of an ``--backend rllib`` run directory (or one of its checkpoints).

    Reads ``policy.json`` and ``policy.pt`` with ``torch.load(weights_only=True)``: nothing is
    unpickled, so no trust is needed. Warns with
    :class:`~foosball_gym.training.run_dir.physics.PhysicsMismatchWarning` where the run's
    ``config.json`` (beside it, or up to two levels up) records other physics than the current
    one, and with :class:`~foosball_gym.training.run_dir.physics.UnknownPhysicsWarning` where
    neither it nor ``policy.json`` records any.

    Raises:
        ValueError: no exported policy there, or its files do not agree with each other.
    """
    import torch as th

    run_dir = Path(run_dir)
    if not is_rllib_run(run_dir):
        raise ValueError(f"{run_dir} holds no RLlib policy ({POLICY_INFO_FILE}, {POLICY_FILE})")
    try:
        info = json.loads((run_dir / POLICY_INFO_FILE).read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{run_dir / POLICY_INFO_FILE} is not valid JSON: {err}") from None
    if info.get("format") != POLICY_FORMAT or info.get("kind") != "mlp":
        raise ValueError(
            f"{run_dir / POLICY_INFO_FILE} is of an unknown format {info.get('format')!r} "
            f"(this version reads {POLICY_FORMAT})"
        )
    check_torch_file(run_dir / POLICY_FILE)
    try:
        tensors = th.load(run_dir / POLICY_FILE, map_location="cpu", weights_only=True)
    except Exception as err:  # noqa: BLE001 - any unreadable file gets the same message
        raise ValueError(f"cannot read {run_dir / POLICY_FILE} as tensors: {err}") from None
    n_layers = len(info["hidden_sizes"]) + 1
    try:
        weights = [
            (
                tensors[f"layers.{i}.weight"].numpy().astype(np.float32),
                tensors[f"layers.{i}.bias"].numpy().astype(np.float32),
            )
            for i in range(n_layers)
        ]
    except (KeyError, AttributeError) as err:
        raise ValueError(f"{run_dir / POLICY_FILE} lacks the layer {err}") from None
    sizes = [info["observation_size"], *info["hidden_sizes"], info["action_size"]]
    for i, (w, b) in enumerate(weights):
        if w.shape != (sizes[i + 1], sizes[i]) or b.shape != (sizes[i + 1],):
            raise ValueError(
                f"{run_dir / POLICY_FILE}: layer {i} is {tuple(w.shape)}, but "
                f"{POLICY_INFO_FILE} describes {(sizes[i + 1], sizes[i])}"
            )

    def array(value: Any) -> np.ndarray | None:
        return None if value is None else np.asarray(value, dtype=np.float64)

    config = None
    # A checkpoint's run is two levels up (checkpoints/step_N/).
    for candidate in [d / CONFIG_FILE for d in (run_dir, *list(run_dir.parents)[:2])]:
        if candidate.is_file():
            config = json.loads(candidate.read_text())
            break
    if config is None and "physics" in info:
        config = {"physics": info["physics"]}
    warn_physics(config, f"the model {run_dir}")
    return RllibPolicy(
        weights,
        info["activation"],
        obs_mean=array(info.get("obs_mean")),
        obs_std=array(info.get("obs_std")),
        clip_obs=info.get("clip_obs"),
        env_id=info.get("env_id"),
        env_kwargs=info.get("env_kwargs") or {},
        generation=int(info.get("generation", 0)),
    )


def load_rllib_snapshot(path: str | Path, config: Mapping[str, Any]) -> RllibPolicy:
    """A self-play snapshot (``selfplay/opponent_<generation>.pt``, a module's full state) of
    the run whose ``config.json`` is ``config``, as a deterministic policy: the actor only,
    its Gaussian's means as the action, as the backend exports its policy."""
    state = load_tensors(Path(path))
    layers = actor_layers(state)
    act_size = int(np.asarray(layers[-1][0]).shape[0]) // 2
    weights = [
        (np.asarray(w, dtype=np.float32), np.asarray(b, dtype=np.float32)) for w, b in layers
    ]
    weights[-1] = (weights[-1][0][:act_size], weights[-1][1][:act_size])
    return RllibPolicy(
        weights,
        "tanh",  # what the backend records for every module it trains
        env_id=config.get("env_id"),
        env_kwargs=config.get("env_kwargs") or {},
    )
