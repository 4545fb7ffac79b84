"""A PPO model's policy frozen in NumPy, acting on its mean: what a run's evaluations play.

An evaluation steps one environment at a time, so each step pays for one forward pass of a
batch of one: SB3's ``predict`` spends most of a step's time in PyTorch's overhead for that, where
the same small network in NumPy costs a few microseconds. The actions are the mean that
``predict(deterministic=True)`` gives, to float32 rounding, clipped to the action space.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.policies import ActorCriticPolicy

from foosball_gym.training.loading.sb3_snapshot import PolicySnapshot, observation_normalisation
from foosball_gym.training.sb3.numpy_policy import NumpyPolicy


class NumpySnapshot:
    """A callable from raw observations (one, or a batch) to the policy's mean actions in
    [-1, 1], normalised as the run's ``VecNormalize`` normalised them when it was made.

    Args:
        net: the policy's arrays.
        obs_mean: the running mean of ``VecNormalize`` (None: no normalisation).
        obs_var: its running variance.
        clip_obs: its clipping of normalised observations.
        epsilon: its epsilon under the square root.
    """

    def __init__(
        self,
        net: NumpyPolicy,
        obs_mean: np.ndarray | None = None,
        obs_var: np.ndarray | None = None,
        clip_obs: float = 10.0,
        epsilon: float = 1e-8,
    ) -> None:
        self.net = net
        self.observation_size = int(net.pi[0][0].shape[0])
        if (obs_mean is None) != (obs_var is None):
            raise ValueError("obs_mean and obs_var are given together or not at all")
        self._normalisation: tuple[np.ndarray, np.ndarray] | None = None
        if obs_mean is not None and obs_var is not None:
            self._normalisation = (
                np.array(obs_mean, dtype=np.float64),
                np.sqrt(np.array(obs_var, dtype=np.float64) + epsilon),
            )
        self._clip_obs = float(clip_obs)
        self._low = np.maximum(net.low, -1.0)
        self._high = np.minimum(net.high, 1.0)

    @classmethod
    def of_model(cls, model: Any) -> NumpySnapshot | PolicySnapshot:
        """Snapshot ``model``'s policy with its environment's normalisation: in NumPy where it
        is a plain Gaussian MLP actor-critic (PPO without gSDE), else as a
        :class:`PolicySnapshot` (SAC, CrossQ, gSDE)."""
        net = _numpy_net(model.policy, model.action_space)
        if net is None:
            return PolicySnapshot.of_model(model)
        normalisation = observation_normalisation(model)
        return cls(net) if normalisation is None else cls(net, *normalisation)

    @classmethod
    def of_snapshot(cls, snapshot: Any) -> Any:
        """``snapshot`` (a :class:`PolicySnapshot`) in NumPy where it acts on a plain Gaussian
        MLP's mean; anything else as it is."""
        if not isinstance(snapshot, PolicySnapshot) or not snapshot.deterministic:
            return snapshot
        policy = snapshot.policy
        net = _numpy_net(policy, spaces.Box(-1.0, 1.0, policy.action_space.shape))
        if net is None:
            return snapshot
        if snapshot.obs_mean is None:
            return cls(net)
        return cls(net, snapshot.obs_mean, snapshot.obs_var, snapshot.clip_obs, snapshot.epsilon)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float64)
        if self._normalisation is not None:
            mean, scale = self._normalisation
            obs = np.clip((obs - mean) / scale, -self._clip_obs, self._clip_obs)
        mean = self.net.mean(obs.astype(np.float32))
        return np.clip(mean, self._low, self._high).astype(np.float32)


def _numpy_net(policy: Any, action_space: spaces.Box) -> NumpyPolicy | None:
    """``policy``'s arrays where it is a plain Gaussian MLP actor-critic, else None."""
    if not isinstance(policy, ActorCriticPolicy):
        return None
    try:
        return NumpyPolicy.of(policy, action_space)
    except ValueError:
        return None
