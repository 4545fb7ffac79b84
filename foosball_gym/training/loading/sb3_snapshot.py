"""Frozen copies of a Stable-Baselines3 policy, usable as an opponent or for evaluation.

A snapshot is saved as tensors and plain numbers and read with ``weights_only=True``; the
policy is rebuilt from the shapes of its weights (:func:`policy_from_state_dict`), so reading
one never unpickles an object.
"""

from __future__ import annotations

import copy
import inspect
import io
import pickle
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import torch as th
from gymnasium import spaces

from foosball_gym.training.run_dir.files import write_bytes
from foosball_gym.training.run_dir.storage import check_torch_file, refusal

SNAPSHOT_FORMAT = 1


def _layers(state: Mapping[str, Any], prefix: str) -> list[Any]:
    """The weights of the Linear layers of the ``nn.Sequential`` at ``prefix``, in order."""
    pattern = re.compile(rf"{re.escape(prefix)}\.(\d+)\.weight")
    found = sorted(
        (int(m.group(1)), value) for key, value in state.items() if (m := pattern.fullmatch(key))
    )
    return [value for _, value in found]


def _constant(_: float) -> float:
    return 0.0


def policy_from_state_dict(state: Mapping[str, Any]) -> Any:
    """The SB3 ``MlpPolicy`` (PPO's or SAC's) these weights belong to, holding them.

    Its layer sizes, its observation and action sizes and whether it explores by gSDE (a
    matrix of log standard deviations) are read off the weights; the activations are SB3's
    defaults, which is what
    :func:`~foosball_gym.training.sb3.model.build_model` uses. Actions are in [-1, 1], as in
    every environment of this package.

    Raises:
        ValueError: the weights are not of a policy that can be rebuilt this way.
    """
    if "action_net.weight" in state:
        from stable_baselines3.common.policies import ActorCriticPolicy

        pi = _layers(state, "mlp_extractor.policy_net")
        vf = _layers(state, "mlp_extractor.value_net")
        obs_size = (pi[0] if pi else state["action_net.weight"]).shape[1]
        act_size = state["action_net.weight"].shape[0]
        net_arch = {"pi": [w.shape[0] for w in pi], "vf": [w.shape[0] for w in vf]}
        cls: type[ActorCriticPolicy | SACPolicy] = ActorCriticPolicy
        extra: dict[str, Any] = {"use_sde": state["log_std"].ndim == 2}
    elif "actor.mu.weight" in state:
        from stable_baselines3.sac.policies import SACPolicy

        pi = _layers(state, "actor.latent_pi")
        qf = _layers(state, "critic.qf0")
        obs_size = (pi[0] if pi else state["actor.mu.weight"]).shape[1]
        act_size = state["actor.mu.weight"].shape[0]
        net_arch = {"pi": [w.shape[0] for w in pi], "qf": [w.shape[0] for w in qf[:-1]]}
        critics = {k.split(".")[1] for k in state if k.startswith("critic.qf")}
        # SAC's gSDE actor holds its log standard deviations as a matrix, not a layer.
        extra = {"n_critics": len(critics), "use_sde": "actor.log_std" in state}
        cls = SACPolicy
    else:
        raise ValueError("the weights are of neither a PPO nor a SAC MlpPolicy")
    policy = cls(
        spaces.Box(-np.inf, np.inf, (int(obs_size),), np.float32),
        spaces.Box(-1.0, 1.0, (int(act_size),), np.float32),
        _constant,
        net_arch=net_arch,
        **extra,
    )
    try:
        policy.load_state_dict(dict(state))
    except RuntimeError as err:
        raise ValueError(f"the weights do not fit an MlpPolicy: {err}") from None
    return policy


def _constructor_parameters(policy: Any) -> dict[str, Any]:
    """What rebuilds ``policy``: its constructor's arguments as it reports them, with what
    sb3-contrib's policies leave out (a RecurrentActorCriticPolicy its LSTM's) and less what
    the constructor does not take (ARSLinearPolicy reports its parent's ``net_arch``)."""
    parameters = policy._get_constructor_parameters()
    if getattr(policy, "lstm_actor", None) is not None:
        parameters.update(
            lstm_hidden_size=policy.lstm_actor.hidden_size,
            n_lstm_layers=policy.lstm_actor.num_layers,
            shared_lstm=policy.shared_lstm,
            enable_critic_lstm=policy.enable_critic_lstm,
            lstm_kwargs=policy.lstm_kwargs,
        )
    accepted = inspect.signature(type(policy).__init__).parameters
    if any(p.kind is p.VAR_KEYWORD for p in accepted.values()):
        return parameters
    return {k: v for k, v in parameters.items() if k in accepted}


def observation_normalisation(model: Any) -> tuple[np.ndarray, np.ndarray, float, float] | None:
    """The observation statistics of ``model``'s VecNormalize as they stand: ``(mean, var,
    clip_obs, epsilon)``; None where its environments are not normalised."""
    from stable_baselines3.common.vec_env import VecNormalize

    env = model.get_env()
    while env is not None and not isinstance(env, VecNormalize):
        env = getattr(env, "venv", None)
    if not isinstance(env, VecNormalize) or not env.norm_obs:
        return None
    assert not isinstance(env.obs_rms, dict)  # the environments observe a Box
    return env.obs_rms.mean, env.obs_rms.var, env.clip_obs, env.epsilon


class PolicySnapshot:
    """A frozen policy: raw observations in, actions in [-1, 1] out.

    It carries the observation normalisation the policy was trained with (if any), so it acts
    on the environment's raw observations. Called with one observation it returns one action;
    with a batch (N, obs_dim) it returns (N, act_dim) from a single forward pass.

    Args:
        policy: an SB3 ``BasePolicy``; it is deep-copied, so later training does not change it.
        obs_mean: the running mean of ``VecNormalize`` (None: no normalisation).
        obs_var: the running variance of ``VecNormalize`` (None: no normalisation).
        clip_obs: ``VecNormalize``'s clipping of normalised observations.
        epsilon: ``VecNormalize``'s epsilon under the square root.
        generation: a label (the self-play generation this snapshot was taken at).
        env_id: the environment it was trained on, where known (error messages name it).
        deterministic: act on the policy's mean (True), or sample from its distribution as the
            learner does while it trains (False; a self-play opponent's option).
    """

    def __init__(
        self,
        policy: Any,
        obs_mean: npt.ArrayLike | None = None,
        obs_var: npt.ArrayLike | None = None,
        clip_obs: float = 10.0,
        epsilon: float = 1e-8,
        generation: int = 0,
        env_id: str | None = None,
        deterministic: bool = True,
    ) -> None:
        if (obs_mean is None) != (obs_var is None):
            raise ValueError("obs_mean and obs_var are given together or not at all")
        # Rebuilt from its constructor arguments and weights (as SB3 saves policies): a deep
        # copy would trip over the tensors a policy keeps from its last forward pass.
        self.policy = type(policy)(**_constructor_parameters(policy))
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
        self.env_id = env_id
        self.deterministic = deterministic

    @property
    def observation_size(self) -> int:
        """The size of the observations the policy takes."""
        return int(np.prod(self.policy.observation_space.shape))

    @classmethod
    def of_model(
        cls, model: Any, generation: int = 0, deterministic: bool = True
    ) -> PolicySnapshot:
        """Snapshot ``model``'s policy with the normalisation of its (VecNormalize) env."""
        normalisation = observation_normalisation(model)
        if normalisation is not None:
            return cls(model.policy, *normalisation, generation, deterministic=deterministic)
        return cls(model.policy, generation=generation, deterministic=deterministic)

    def normalise(self, obs: np.ndarray) -> np.ndarray:
        if self.obs_mean is None:
            return obs.astype(np.float32)
        assert self.obs_var is not None  # __init__ takes both or neither
        z = (obs - self.obs_mean) / np.sqrt(self.obs_var + self.epsilon)
        return np.clip(z, -self.clip_obs, self.clip_obs).astype(np.float32)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float64)
        single = obs.ndim == 1
        batch = self.normalise(obs[None] if single else obs)
        with th.no_grad():
            actions = self._predict(batch)
        actions = np.clip(actions, -1.0, 1.0).astype(np.float32)
        return actions[0] if single else actions

    def _predict(self, batch: np.ndarray) -> np.ndarray:
        actions, _ = self.policy.predict(batch, deterministic=self.deterministic)
        return actions

    def parameters_equal(self, policy: Any) -> bool:
        """True when ``policy`` has exactly this snapshot's weights."""
        mine, theirs = self.policy.state_dict(), policy.state_dict()
        return mine.keys() == theirs.keys() and all(
            th.equal(mine[k].cpu(), theirs[k].cpu()) for k in mine
        )

    def save(self, path: str | Path) -> None:
        """Write the snapshot (weights, normalisation) atomically, as tensors and numbers."""
        path = Path(path)
        buffer = io.BytesIO()

        def tensor(value: np.ndarray | None) -> th.Tensor | None:
            return None if value is None else th.as_tensor(value, dtype=th.float64)

        th.save(
            {
                "format": SNAPSHOT_FORMAT,
                "policy": {k: v.detach().cpu() for k, v in self.policy.state_dict().items()},
                "obs_mean": tensor(self.obs_mean),
                "obs_var": tensor(self.obs_var),
                "clip_obs": self.clip_obs,
                "epsilon": self.epsilon,
                "generation": self.generation,
            },
            buffer,
        )
        write_bytes(path, buffer.getvalue())

    @classmethod
    def load(cls, path: str | Path, trust: bool = False) -> PolicySnapshot:
        """Read a snapshot :meth:`save` wrote.

        Args:
            trust: also read a snapshot of the older format, a pickled policy object, which
                runs whatever code the file holds; without it such a file is refused.

        Raises:
            UntrustedFileError: an older snapshot, and ``trust`` is False.
            ValueError: the file is not a snapshot.
        """
        path = Path(path)
        check_torch_file(path)
        try:
            data = th.load(path, map_location="cpu", weights_only=True)
        except pickle.UnpicklingError:
            if not trust:
                raise refusal(path, path.parent.parent) from None
            data = th.load(path, map_location="cpu", weights_only=False)
        except (RuntimeError, EOFError, OSError) as err:
            raise ValueError(f"cannot read the snapshot {path}: {err}") from None
        if not isinstance(data, dict) or "policy" not in data:
            raise ValueError(f"{path} is not a policy snapshot")
        policy = data["policy"]
        if isinstance(policy, Mapping):
            policy = policy_from_state_dict(policy)

        def array(value: Any) -> np.ndarray | None:
            return None if value is None else np.asarray(value, dtype=np.float64)

        return cls(
            policy,
            array(data["obs_mean"]),
            array(data["obs_var"]),
            data["clip_obs"],
            data["epsilon"],
            data["generation"],
        )
