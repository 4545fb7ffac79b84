"""PPO's rollouts played where the environments are, a whole rollout per message.

SB3's ``collect_rollouts`` runs the policy in the training process once a step and sends the
actions out: with the environments split over one process per core, each step is a message
each way per worker, and the workers wait while the policy runs. PPO holds its policy still
for a whole rollout, so each process that steps a share of the environments (the batched vec
env's workers and the training process's own share) can play its share to the end with a copy
of the policy's weights, in parallel: one message each way per worker and rollout.

Kept from SB3's loop: the policy itself (its weights in NumPy, float32), actions drawn from its
Gaussian and clipped to the action space for the environments, the buffer's unclipped actions,
values and log-probabilities, rewards of truncated episodes bootstrapped with the value of their
last observation, VecNormalize's own code for the observations and rewards (a copy of the
run's, in each share), its statistics taking in every observation and return of the rollout,
and every callback called once a step, in order, with that step's locals as SB3 names them
(``new_obs``, ``rewards``, ``dones``, ``infos``, ``actions``, ``clipped_actions``, ``values``,
``log_probs``).

What differs: the exploration noise is NumPy's, each environment's drawn by a generator of its
own seeded by the run's seed, the step and the environment's index, not PyTorch's; within a
rollout the observations and rewards are normalised with the statistics as they stood at its
start, which take in the rollout's observations and returns once its callbacks have run (SB3
updates them every step); and the callbacks run once the rollout is played, so a stop asked for
mid-rollout comes after the environments have played it. Neither the noise nor the
normalisation depends on how the environments are split, so a seeded run trains the same policy
with its environments batched over the cores or all in one process.

In self-play each share also plays its environments' opponents (a copy of the run's
:class:`~foosball_gym.training.selfplay.opponents.SelfPlayVecEnv`, the snapshots in NumPy where
they act on their mean), and each environment draws its next opponent with a generator of its
own. A new opponent the self-play callback picks plays from the next rollout on.
"""

from __future__ import annotations

import pickle
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch as th
from stable_baselines3.common.utils import obs_as_tensor
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecNormalize

from foosball_gym.policy_io.around_ball import AroundBallPlayer
from foosball_gym.training.sb3.numpy_policy import NumpyPolicy
from foosball_gym.training.sb3.numpy_snapshot import NumpySnapshot
from foosball_gym.training.selfplay.opponents import OpponentPlan, OpponentState, SelfPlayVecEnv


@dataclass
class RolloutPlan:
    """What a share needs to play a rollout: the policy, the steps, the discount, its part of
    the last observations (normalised), a seed for each environment's noise, and the run's
    VecNormalize (pickled, without its environments) with the share's running returns."""

    policy: NumpyPolicy
    n_steps: int
    gamma: float
    last_obs: np.ndarray
    seeds: list[list[int]]  # one per environment of the share
    rows: slice  # the share's environments among the run's
    total: int  # the run's environments
    normalisation: bytes | None
    returns: np.ndarray | None
    opponents: OpponentPlan | None = None  # self-play's, for the share


@dataclass
class SeenStatistics:
    """What a share's copy of VecNormalize saw in a rollout, for the run's own."""

    raw_obs: np.ndarray  # the environments' observations, a leading step axis
    raw_returns: np.ndarray  # the running returns as the statistics took them
    returns: np.ndarray  # the running returns at the end
    last_raw_reward: np.ndarray

    @property
    def last_raw_obs(self) -> np.ndarray:
        return self.raw_obs[-1]


@dataclass
class RolloutPart:
    """A share's rollout, arrays with a leading step axis."""

    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    values: np.ndarray
    log_probs: np.ndarray
    dones: np.ndarray
    infos: list[list[dict[str, Any]]]
    last_obs: np.ndarray
    reset_infos: list[dict[str, Any]]
    seen: SeenStatistics | None
    opponents: OpponentState | None = None


def play_rollout(envs: DummyVecEnv, plan: RolloutPlan) -> RolloutPart:
    """Play ``plan`` on ``envs`` (a share of the run's environments, unnormalised)."""
    norm: VecNormalize | None = None
    selfplay = None if plan.opponents is None else SelfPlayVecEnv.playing(envs, plan.opponents)
    stepped: VecEnv = envs if selfplay is None else selfplay
    if plan.normalisation is not None:
        norm = pickle.loads(plan.normalisation)
        norm.set_venv(stepped)
        learning, norm.training = norm.training, False  # the start's statistics throughout
        running = np.array(plan.returns, dtype=np.float64)
        stepped = norm
    rngs = [np.random.default_rng(seed) for seed in plan.seeds]
    policy, n, k = plan.policy, plan.n_steps, envs.num_envs
    obs: Any = plan.last_obs
    observations = np.empty((n, *obs.shape), np.float32)
    actions = np.empty((n, k, policy.low.shape[0]), np.float32)
    rewards = np.empty((n, k), np.float32)
    values = np.empty((n, k), np.float32)
    log_probs = np.empty((n, k), np.float32)
    dones = np.empty((n, k), bool)
    raw_obs = np.empty((n, *obs.shape), np.float64)
    raw_returns = np.empty((n, k), np.float64)
    batch = np.zeros((plan.total, *obs.shape[1:]), np.float32)  # the policy's, made once
    infos = []
    for t in range(n):
        observations[t] = obs
        actions[t], values[t], log_probs[t] = policy.act(obs, rngs, plan.rows, batch)
        obs, reward, dones[t], info = stepped.step(np.clip(actions[t], policy.low, policy.high))
        if norm is not None:
            # VecNormalize's running returns, which it keeps only while it learns.
            raw_obs[t] = norm.old_obs
            if learning:
                running = running * norm.gamma + norm.old_reward
            raw_returns[t] = running
            running[dones[t]] = 0
        for i in np.flatnonzero(dones[t]):
            if info[i].get("terminal_observation") is not None and info[i].get(
                "TimeLimit.truncated", False
            ):
                reward[i] += plan.gamma * policy.value(info[i]["terminal_observation"])
        rewards[t] = reward
        infos.append(info)
    seen = None
    if norm is not None:
        seen = SeenStatistics(raw_obs, raw_returns, running, norm.old_reward)
    part = (observations, actions, rewards, values, log_probs, dones, infos, np.asarray(obs))
    opponents = None if selfplay is None else selfplay.state()
    return RolloutPart(*part, list(envs.reset_infos), seen, opponents)


class WorkerRollouts:
    """Mixed into an SB3 PPO: :meth:`collect_rollouts` has each share of the environments play
    the whole rollout (the module's docstring). The training env is the run's vec env (batched
    or in this process), with or without VecNormalize around it."""

    def collect_rollouts(
        self, env: VecEnv, callback: Any, rollout_buffer: Any, n_rollout_steps: int
    ) -> bool:
        model: Any = self
        norm = env if isinstance(env, VecNormalize) else None
        inner: Any = norm.venv if norm is not None else env
        selfplay = inner if isinstance(inner, SelfPlayVecEnv) else None
        if selfplay is not None:
            inner = selfplay.venv
        if not hasattr(inner, "play_rollouts"):
            raise ValueError(
                "worker_rollouts plays the rollouts in the run's own environments (vec_env "
                f"batched or dummy), not in a {type(inner).__name__}"
            )
        model.policy.set_training_mode(False)
        rollout_buffer.reset()
        callback.on_rollout_start()
        policy = NumpyPolicy.of(model.policy, model.action_space)
        shared = None
        if norm is not None:
            shared = pickle.dumps(norm)
        pool = [] if selfplay is None else self._playable_pool(selfplay.pool)

        def seeds(share: slice, *stream: int) -> list[list[int]]:
            run = [model.seed or 0, model.num_timesteps]
            return [[*run, i, *stream] for i in range(share.start, share.stop)]

        plans = [
            RolloutPlan(
                policy,
                n_rollout_steps,
                model.gamma,
                model._last_obs[share],
                seeds(share),
                share,
                env.num_envs,
                shared,
                None if norm is None else norm.returns[share],
                None if selfplay is None else selfplay.plan(share, pool, seeds(share, 1)),
            )
            for share in inner.shares
        ]
        parts: list[RolloutPart] = inner.play_rollouts(plans)
        if selfplay is not None:
            for share, part in zip(inner.shares, parts, strict=True):
                assert part.opponents is not None  # a share given opponents returns them
                selfplay.take(share, part.opponents)

        def joined(name: str, axis: int = 1) -> np.ndarray:
            return _joined(parts, name, axis)

        dones, last_obs = joined("dones"), joined("last_obs", axis=0)
        observations, actions = joined("observations"), joined("actions")
        rewards, values, log_probs = joined("rewards"), joined("values"), joined("log_probs")
        inner.reset_infos = [info for p in parts for info in p.reset_infos]
        space = model.action_space
        stopped = False
        for t in range(n_rollout_steps):
            model.num_timesteps += env.num_envs
            infos = [info for p in parts for info in p.infos[t]]
            new_obs = observations[t + 1] if t + 1 < n_rollout_steps else last_obs
            callback.update_locals(
                {
                    "new_obs": new_obs,
                    "rewards": rewards[t],
                    "dones": dones[t],
                    "infos": infos,
                    "actions": actions[t],
                    "clipped_actions": np.clip(actions[t], space.low, space.high),
                    "values": values[t],
                    "log_probs": log_probs[t],
                    "n_steps": t,
                }
            )
            if not callback.on_step():
                stopped = True
                break
            model._update_info_buffer(infos, dones[t])
        # After the callbacks, which saw the statistics the rollout was normalised with.
        if norm is not None:
            _take_statistics(norm, [p.seen for p in parts if p.seen is not None])
        if stopped:
            return False

        rollout_buffer.observations[:] = observations
        rollout_buffer.actions[:] = actions
        rollout_buffer.rewards[:] = rewards
        rollout_buffer.values[:] = values
        rollout_buffer.log_probs[:] = log_probs
        rollout_buffer.episode_starts[0] = model._last_episode_starts
        rollout_buffer.episode_starts[1:] = dones[:-1]
        rollout_buffer.pos, rollout_buffer.full = n_rollout_steps, True
        model._last_obs = last_obs
        model._last_episode_starts = dones[-1]
        with th.no_grad():
            values = model.policy.predict_values(obs_as_tensor(model._last_obs, model.device))
        rollout_buffer.compute_returns_and_advantage(last_values=values, dones=dones[-1])
        callback.update_locals({"values": values, "dones": dones[-1]})
        callback.on_rollout_end()
        return True

    def _excluded_save_params(self) -> list[str]:
        # The pool's NumPy copies are remade from the snapshots; a saved model holds no copy.
        return [*super()._excluded_save_params(), "_numpy_pool"]  # type: ignore[misc]

    def _playable_pool(self, pool: list[Any]) -> list[Any]:
        """Self-play's pool as a worker plays it: each snapshot acting on its mean in NumPy
        (inside its conversion where it slides around the ball), made once a snapshot, the
        others (sampling snapshots, the anchors) as they are."""
        made: dict[int, tuple[Any, Any]] = getattr(self, "_numpy_pool", {})
        made = {id(p): made[id(p)] for p in pool if id(p) in made}
        for player in pool:
            if id(player) in made:
                continue
            if isinstance(player, AroundBallPlayer):
                copy = player.around(NumpySnapshot.of_snapshot(player.player))
            else:
                copy = NumpySnapshot.of_snapshot(player)
            made[id(player)] = (player, copy)
        self._numpy_pool = made
        return [made[id(p)][1] for p in pool]


def _take_statistics(norm: VecNormalize, seen: list[SeenStatistics]) -> None:
    """Give the run's VecNormalize what the shares' copies saw: the statistics of every
    observation and running return of the rollout, the returns and the last step's raw
    observation and reward."""

    def joined(name: str, axis: int = 1) -> np.ndarray:
        return _joined(seen, name, axis)

    if norm.training:
        if norm.norm_obs:
            raw = joined("raw_obs")
            norm.obs_rms.update(raw.reshape(-1, *raw.shape[2:]))
        norm.ret_rms.update(joined("raw_returns").reshape(-1))
    norm.returns = joined("returns", axis=0)
    norm.old_obs = joined("last_raw_obs", axis=0)
    norm.old_reward = joined("last_raw_reward", axis=0)


def _joined(parts: list[Any], name: str, axis: int) -> np.ndarray:
    """The shares' arrays ``name`` joined along the environments' axis, in the shares' order."""
    return np.concatenate([getattr(part, name) for part in parts], axis=axis)
