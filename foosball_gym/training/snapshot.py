"""Frozen copies of a Stable-Baselines3 policy, usable as an opponent or for evaluation."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np
import torch as th


class PolicySnapshot:
    """A frozen policy: raw observations in, deterministic actions in [-1, 1] out.

    It carries the observation normalisation the policy was trained with (if any), so it acts
    on the environment's raw observations. Called with one observation it returns one action;
    with a batch (N, obs_dim) it returns (N, act_dim) from a single forward pass.

    Args:
        policy: an SB3 ``BasePolicy``; it is deep-copied, so later training does not change it.
        obs_mean, obs_var: running statistics of ``VecNormalize`` (None: no normalisation).
        clip_obs, epsilon: ``VecNormalize``'s clipping and epsilon.
        generation: a label (the self-play generation this snapshot was taken at).
    """

    def __init__(
        self,
        policy: Any,
        obs_mean: np.ndarray | None = None,
        obs_var: np.ndarray | None = None,
        clip_obs: float = 10.0,
        epsilon: float = 1e-8,
        generation: int = 0,
    ) -> None:
        # Rebuilt from its constructor arguments and weights (as SB3 saves policies): a deep
        # copy would trip over the tensors a policy keeps from its last forward pass.
        self.policy = type(policy)(**policy._get_constructor_parameters())
        self.policy.load_state_dict(copy.deepcopy(policy.state_dict()))
        self.policy.to("cpu")
        self.policy.set_training_mode(False)
        for p in self.policy.parameters():
            p.requires_grad_(False)
        self.obs_mean = None if obs_mean is None else np.array(obs_mean, dtype=np.float64)
        self.obs_var = None if obs_var is None else np.array(obs_var, dtype=np.float64)
        self.clip_obs = float(clip_obs)
        self.epsilon = float(epsilon)
        self.generation = generation

    @classmethod
    def of_model(cls, model: Any, generation: int = 0) -> PolicySnapshot:
        """Snapshot ``model``'s policy with the normalisation of its (VecNormalize) env."""
        from stable_baselines3.common.vec_env import VecNormalize

        env = model.get_env()
        while env is not None and not isinstance(env, VecNormalize):
            env = getattr(env, "venv", None)
        if isinstance(env, VecNormalize) and env.norm_obs:
            return cls(
                model.policy,
                env.obs_rms.mean,
                env.obs_rms.var,
                env.clip_obs,
                env.epsilon,
                generation,
            )
        return cls(model.policy, generation=generation)

    def normalise(self, obs: np.ndarray) -> np.ndarray:
        if self.obs_mean is None:
            return obs.astype(np.float32)
        z = (obs - self.obs_mean) / np.sqrt(self.obs_var + self.epsilon)
        return np.clip(z, -self.clip_obs, self.clip_obs).astype(np.float32)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float64)
        single = obs.ndim == 1
        batch = self.normalise(obs[None] if single else obs)
        with th.no_grad():
            actions, _ = self.policy.predict(batch, deterministic=True)
        actions = np.clip(actions, -1.0, 1.0).astype(np.float32)
        return actions[0] if single else actions

    def parameters_equal(self, policy: Any) -> bool:
        """True when ``policy`` has exactly this snapshot's weights."""
        mine, theirs = self.policy.state_dict(), policy.state_dict()
        return mine.keys() == theirs.keys() and all(
            th.equal(mine[k].cpu(), theirs[k].cpu()) for k in mine
        )

    def save(self, path: str | Path) -> None:
        """Write the snapshot (weights, normalisation) atomically."""
        path = Path(path)
        tmp = path.with_suffix(path.suffix + ".tmp")
        th.save(
            {
                "policy": self.policy,
                "obs_mean": self.obs_mean,
                "obs_var": self.obs_var,
                "clip_obs": self.clip_obs,
                "epsilon": self.epsilon,
                "generation": self.generation,
            },
            tmp,
        )
        tmp.replace(path)

    @classmethod
    def load(cls, path: str | Path) -> PolicySnapshot:
        data = th.load(path, map_location="cpu", weights_only=False)
        return cls(
            data["policy"],
            data["obs_mean"],
            data["obs_var"],
            data["clip_obs"],
            data["epsilon"],
            data["generation"],
        )
