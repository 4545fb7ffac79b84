"""An SB3 ``MlpPolicy``'s Gaussian actor and critic as NumPy arrays: what plays the rollouts in
the workers (:mod:`~foosball_gym.training.sb3.worker_rollouts`) and the snapshots that act on
their mean (:mod:`~foosball_gym.training.sb3.numpy_snapshot`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from foosball_gym.training.sb3.mlp_layers import mlp_layers

_HALF_LOG_2PI = np.float32(0.5 * np.log(2 * np.pi))


@dataclass
class NumpyPolicy:
    """An SB3 ``MlpPolicy``'s Gaussian actor and its critic, as NumPy arrays."""

    pi: list[tuple[np.ndarray, np.ndarray, str]]
    vf: list[tuple[np.ndarray, np.ndarray, str]]
    log_std: np.ndarray
    low: np.ndarray
    high: np.ndarray

    @classmethod
    def of(cls, policy: Any, action_space: spaces.Space) -> NumpyPolicy:
        """The arrays of ``policy`` (an SB3 ``ActorCriticPolicy``), refused where this class
        would not compute what it does."""
        if not isinstance(action_space, spaces.Box):
            raise ValueError(f"worker_rollouts needs a Box action space, not {action_space}")
        space = policy.observation_space
        if not isinstance(space, spaces.Box) or len(space.shape) != 1:
            raise ValueError(f"worker_rollouts needs a flat Box observation space, not {space}")
        if policy.use_sde or policy.squash_output:
            raise ValueError("worker_rollouts plays a plain Gaussian policy: leave use_sde off")
        state = {name: p.detach().cpu().numpy() for name, p in policy.named_parameters()}
        pi = mlp_layers(policy.mlp_extractor.policy_net, "mlp_extractor.policy_net.")
        pi.append(("action_net.weight", "action_net.bias", "none"))
        vf = mlp_layers(policy.mlp_extractor.value_net, "mlp_extractor.value_net.")
        vf.append(("value_net.weight", "value_net.bias", "none"))
        used = {n for layer in pi + vf for n in layer[:2]} | {"log_std"}
        if set(state) != used:
            raise ValueError(
                f"worker_rollouts does not know the policy's parameters {sorted(set(state) - used)}"
            )

        def arrays(layers: list[tuple[str, str, str]]) -> list[tuple[np.ndarray, np.ndarray, str]]:
            return [(np.ascontiguousarray(state[w].T), state[b], act) for w, b, act in layers]

        return cls(
            arrays(pi),
            arrays(vf),
            state["log_std"],
            action_space.low.astype(np.float32),
            action_space.high.astype(np.float32),
        )

    @staticmethod
    def _forward(layers: list[tuple[np.ndarray, np.ndarray, str]], x: np.ndarray) -> np.ndarray:
        for weight, bias, act in layers:
            x = x @ weight + bias
            if act == "tanh":
                x = np.tanh(x)
            elif act == "relu":
                x = np.maximum(x, 0)
        return x

    def mean(self, obs: np.ndarray) -> np.ndarray:
        """The actions' mean (unclipped): what the policy plays deterministically."""
        return self._forward(self.pi, np.asarray(obs, np.float32))

    def value(self, obs: np.ndarray) -> np.ndarray:
        return self._forward(self.vf, np.asarray(obs, np.float32))[..., 0]

    def act(
        self, obs: np.ndarray, rngs: list[np.random.Generator], rows: slice, batch: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sampled actions (unclipped), the values and the actions' log-probabilities; the noise
        of each row of ``obs`` is drawn by its own generator.

        ``obs`` holds the ``rows`` of ``batch``, a float32 array of the run's size that the
        caller makes once and this fills: they are computed in a batch of that size, at those
        rows, because BLAS rounds a row's product differently in batches of other sizes, and a
        run should not depend on how its environments are split."""
        batch[rows] = obs
        mean = self._forward(self.pi, batch)[rows]
        values = self._forward(self.vf, batch)[rows, 0]
        size = mean.shape[-1]
        noise = np.stack([rng.standard_normal(size, dtype=np.float32) for rng in rngs])
        actions = mean + np.exp(self.log_std) * noise
        log_prob = -(0.5 * noise * noise + self.log_std + _HALF_LOG_2PI).sum(axis=-1)
        return actions, values, log_prob
