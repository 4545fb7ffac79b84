"""Self-play's opponents in Stable-Baselines3's vectorised envs (docs/self-play.md): the learner
plays frozen past copies of itself, chosen outside the env.

- :class:`OpponentActionWrapper` (per env): the vectorised env, not the env, chooses the
  opponent's action. The env's action becomes ``[learner action, opponent action]`` and its
  info carries the opponent's (mirrored) observation.
- :class:`SelfPlayVecEnv` (around the Dummy/SubprocVecEnv): before each step it evaluates the
  opponents for all envs in one batched forward pass per opponent, then steps the envs.

Which snapshots make the pool is the choice of
:class:`~foosball_gym.training.selfplay.callback.SelfPlayCallback`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs

if TYPE_CHECKING:
    from foosball_gym.envs.base import FoosballEnv

OPPONENT_OBS = "opponent_obs"
# In the info of a game's last step: the game was against the scripted anchor, not a snapshot.
AGAINST_ANCHOR = "against_scripted_anchor"
# The pool indices -1, -2, ... stand for the anchors.


class _QueuedAction:
    """The opponent 'policy' of an env whose opponent is chosen outside it."""

    def __init__(self, size: int) -> None:
        self.action = np.zeros(size, dtype=np.float32)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return self.action


class OpponentActionWrapper(gym.Wrapper):
    """Takes the opponent's action together with the learner's.

    The action space is the learner's followed by the opponent's (same size); each step's and
    reset's info holds ``info["opponent_obs"]``, the observation the opponent acts on next.
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        base = cast("FoosballEnv", env.unwrapped)
        if not getattr(base, "layout", None) or not base.layout.opponent:
            raise ValueError(f"{base.spec.id if base.spec else base} has no opponent to play")
        own = env.action_space
        assert own.shape is not None  # the environments act in a Box
        self._n = own.shape[0]
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2 * self._n,), dtype=np.float32)
        self._queued = _QueuedAction(self._n)
        base.set_opponent(self._queued)

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        info[OPPONENT_OBS] = cast("FoosballEnv", self.env.unwrapped).opponent_observation()
        return obs, info

    def step(self, action: np.ndarray):
        self._queued.action = np.asarray(action[self._n :], dtype=np.float32)
        obs, reward, terminated, truncated, info = self.env.step(action[: self._n])
        info[OPPONENT_OBS] = cast("FoosballEnv", self.env.unwrapped).opponent_observation()
        return obs, reward, terminated, truncated, info


class SelfPlayVecEnv(VecEnvWrapper):
    """Plays the opponents of every env of a VecEnv built with :class:`OpponentActionWrapper`.

    Args:
        venv: the vectorised envs (each wrapped in ``OpponentActionWrapper``).
        opponent: the first opponent (a callable on a batch of observations).
        seed: seeds the choice of opponents from the pool.
        anchor: a fixed opponent acting on one observation (the scripted team), or a list of
            them (rungs of the scripted ladder), played in ``anchor_share`` of the games instead
            of the pool, one drawn at random for each such game; the last step's info of such a
            game says so (``AGAINST_ANCHOR``), so that the replacement rule can leave it out.
        anchor_share: the share of games against an anchor, in [0, 1).
        whole_action: where the learner's actions are corrections to the scripted baseline
            (the environment option ``residual``), what turns a snapshot of it into a player
            that gives the whole action
            (:func:`~foosball_gym.training.loading.loader.whole_action_policy`): the opponent's
            side of the environment takes whole actions. The anchors give them already.
    """

    def __init__(
        self,
        venv: VecEnv,
        opponent: Any,
        seed: int | None = None,
        anchor: Any = None,
        anchor_share: float = 0.0,
        whole_action: Callable[[Any], Any] | None = None,
    ) -> None:
        assert venv.action_space.shape is not None  # OpponentActionWrapper's Box
        n = venv.action_space.shape[0] // 2
        learner_space = spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)
        super().__init__(venv, action_space=learner_space)
        if not 0.0 <= anchor_share < 1.0 or (anchor_share > 0.0 and not _listed(anchor)):
            raise ValueError(
                f"anchor_share must be in [0, 1), and above 0 only with an anchor; got "
                f"{anchor_share!r} with {'an' if anchor is not None else 'no'} anchor"
            )
        self.anchors = _listed(anchor)
        self.anchor_share = float(anchor_share)
        self.whole_action = whole_action
        self.pool: list[Any] = [whole_action(opponent) if whole_action else opponent]
        self._rng = np.random.default_rng(seed)
        self._assigned = np.zeros(self.num_envs, dtype=int)
        self._opp_obs: np.ndarray | None = None
        self.opponent_seconds = 0.0  # time spent in opponent inference, for benchmarks

    # -- pool ---------------------------------------------------------------

    def set_pool(self, pool: list[Any]) -> None:
        """Replace the opponents; envs draw from the new pool at their next episode."""
        if not pool:
            raise ValueError("the opponent pool must not be empty")
        self.pool = [self.whole_action(p) for p in pool] if self.whole_action else list(pool)
        self._assigned = np.minimum(self._assigned, len(self.pool) - 1)

    def _draw(self) -> int:
        if self.anchor_share and self._rng.random() < self.anchor_share:
            # One anchor draws nothing more, as before there could be several.
            if len(self.anchors) == 1:
                return -1
            return -1 - int(self._rng.integers(len(self.anchors)))
        return int(self._rng.integers(len(self.pool)))

    # -- VecEnv -------------------------------------------------------------

    def reset(self) -> VecEnvObs:
        obs = self.venv.reset()
        self._opp_obs = np.stack([info[OPPONENT_OBS] for info in self.venv.reset_infos])
        self._assigned = np.array([self._draw() for _ in range(self.num_envs)])
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        assert self._opp_obs is not None  # reset() sets it before any step
        start = time.perf_counter()
        opp = np.zeros_like(actions, dtype=np.float32)
        for k in np.unique(self._assigned):
            idx = np.nonzero(self._assigned == k)[0]
            if k < 0:
                anchor = self.anchors[-1 - k]
                opp[idx] = np.stack([anchor(o) for o in self._opp_obs[idx]])
            else:
                opp[idx] = self.pool[k](self._opp_obs[idx])
        self.opponent_seconds += time.perf_counter() - start
        self.venv.step_async(np.concatenate([actions, opp], axis=1))

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        assert self._opp_obs is not None  # reset() sets it before any step
        for i, done in enumerate(dones):
            if done:
                if self._assigned[i] < 0:
                    infos[i][AGAINST_ANCHOR] = True
                self._opp_obs[i] = self.venv.reset_infos[i][OPPONENT_OBS]
                self._assigned[i] = self._draw()
            else:
                self._opp_obs[i] = infos[i][OPPONENT_OBS]
        return obs, rewards, dones, infos


def _listed(anchor: Any) -> list[Any]:
    if anchor is None:
        return []
    return list(anchor) if isinstance(anchor, list | tuple) else [anchor]


def find_selfplay_env(env: VecEnv | None) -> SelfPlayVecEnv:
    while env is not None and not isinstance(env, SelfPlayVecEnv):
        env = getattr(env, "venv", None)
    if env is None:
        raise ValueError("self-play needs the training env wrapped in SelfPlayVecEnv")
    return env
