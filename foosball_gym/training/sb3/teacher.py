"""Learning from a teacher while PPO trains (DAgger, for Stable-Baselines3 PPO).

Behaviour cloning before training (:mod:`~foosball_gym.training.sb3.pretrain`) starts the learner
where the scripted team is, so its first self-play generations are already as good as that team and
later ones have nothing easy left to beat. A teacher instead labels the states the learner itself
visits with the scripted action, and the policy's mean is pulled towards those labels after every
rollout, less and less until ``steps``: the learner starts from nothing and grows into a sound
player while it plays its own past copies (and, being fitted on its own states, learns to recover
from its own mistakes, which cloning demonstrations does not teach). The scripted teacher's kick is
a timed lift and swing that switches on the rod's spin; a mean fitted to it averages the wind-up and
the swing and stalls half-raised, so in keeper against keeper its taught means learnt to defend but
not to kick a resting ball (docs/results/keeper-vs-keeper.md). A trained model as the teacher gives
labels a policy can fit: its own mean is such a policy.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
from stable_baselines3.common.vec_env import VecNormalize

from foosball_gym.training.loading import load_policy

if TYPE_CHECKING:
    from foosball_gym.envs.base import FoosballEnv


class TeacherCallback(BaseCallback):
    """After each rollout, fit the policy's action mean to the teacher's actions on the
    rollout's observations, with a weight falling linearly from 1 to 0 at ``steps``.

    Args:
        env_id, env_kwargs: the learner's environment.
        steps: training steps after which the teacher stops.
        teacher: ``"scripted"`` (the environment's scripted baseline) or a model trained on
            ``env_id`` (a run directory, a ``.zip`` or ``builtin:NAME``), acting on its mean.
        learning_rate: the fitting's step size at weight 1 (scaled by the weight).
        epochs, batch_size: passes over each rollout, and their minibatch size.
    """

    def __init__(
        self,
        env_id: str,
        env_kwargs: dict[str, Any],
        steps: int,
        learning_rate: float = 1e-3,
        epochs: int = 4,
        batch_size: int = 256,
        seed: int = 0,
        teacher: str = "scripted",
    ) -> None:
        super().__init__()
        if steps < 1:
            raise ValueError(f"the teacher's steps must be at least 1, got {steps}")
        env = gym.make(env_id, **env_kwargs)
        self.teacher: Callable[[np.ndarray], Any]
        try:
            if teacher == "scripted":
                self.teacher = cast("FoosballEnv", env.unwrapped).scripted_policy()
            else:
                self.teacher = _model_teacher(teacher, env_id, env.observation_space.shape)
            # A model labels a whole rollout in one pass; the scripted policy one state a time.
            self._batched = teacher != "scripted"
        finally:
            env.close()
        self.steps = int(steps)
        self.learning_rate = float(learning_rate)
        self.epochs, self.batch_size = int(epochs), int(batch_size)
        self._gen = th.Generator().manual_seed(seed)
        self._optimizer: th.optim.Optimizer | None = None
        self.last_mse: float | None = None

    def weight(self, timesteps: int) -> float:
        """How much the teacher counts after ``timesteps`` steps of training."""
        return max(0.0, 1.0 - timesteps / self.steps)

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        weight = self.weight(self.num_timesteps)
        if weight <= 0.0:
            return
        assert isinstance(self.model, OnPolicyAlgorithm)  # the configuration allows PPO only
        policy = self.model.policy
        obs = self.model.rollout_buffer.observations
        obs = obs.reshape(-1, obs.shape[-1])
        norm = self.model.get_vec_normalize_env()
        raw = norm.unnormalize_obs(obs) if isinstance(norm, VecNormalize) and norm.norm_obs else obs
        assert isinstance(raw, np.ndarray)  # the environments observe a Box
        if self._batched:
            labels = np.asarray(self.teacher(raw), dtype=np.float32)
        else:
            labels = np.stack([np.asarray(self.teacher(o), dtype=np.float32) for o in raw])
        if self._optimizer is None:
            # The actor only: the value function is PPO's to fit.
            params = [
                *policy.mlp_extractor.policy_net.parameters(),
                *policy.action_net.parameters(),
            ]
            self._optimizer = th.optim.Adam(params, lr=self.learning_rate)
        for group in self._optimizer.param_groups:
            group["lr"] = self.learning_rate * weight
        device = policy.device
        obs_t = th.as_tensor(obs, dtype=th.float32, device=device)
        act_t = th.as_tensor(labels, dtype=th.float32, device=device)
        policy.set_training_mode(True)
        loss = th.tensor(0.0)
        for _ in range(self.epochs):
            for idx in th.randperm(len(obs_t), generator=self._gen).split(self.batch_size):
                features = policy.extract_features(obs_t[idx])
                assert isinstance(features, th.Tensor)  # actor and critic share the extractor
                latent_pi = policy.mlp_extractor.forward_actor(features)
                loss = th.mean((policy.action_net(latent_pi) - act_t[idx]) ** 2)
                self._optimizer.zero_grad()
                loss.backward()
                self._optimizer.step()
        policy.set_training_mode(False)
        self.last_mse = float(loss.item())
        self.logger.record("teacher/weight", weight)
        self.logger.record("teacher/action_mse", self.last_mse)


def _model_teacher(spec: str, env_id: str, shape: tuple[int, ...] | None) -> Any:
    """A trained model as the teacher; refused where it plays another environment or takes
    other observations than the learner's."""
    policy = load_policy(spec)
    if policy.recurrent:
        raise ValueError(
            f"teacher {spec} is a recurrent policy (RecurrentPPO): a teacher answers each "
            "observation alone, so give a feed-forward one"
        )
    if policy.env_id is not None and policy.env_id != env_id:
        raise ValueError(
            f"teacher {spec} was trained on {policy.env_id}, not on the learner's {env_id}"
        )
    if shape is not None and (policy.observation_size,) != tuple(shape):
        raise ValueError(
            f"teacher {spec} takes observations of size {policy.observation_size}, the "
            f"learner's environment gives size {shape[0]}: train both with the same options"
        )
    return policy
