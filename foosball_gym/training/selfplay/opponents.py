"""Self-play's opponents in Stable-Baselines3's vectorised envs (docs/self-play.md): the learner
plays frozen past copies of itself, chosen outside the env.

- :class:`OpponentActionWrapper` (per env): the vectorised env, not the env, chooses the
  opponent's action. The env's action becomes ``[learner action, opponent action]`` and its
  info carries the opponent's (mirrored) observation.
- :class:`SelfPlayVecEnv` (around the Dummy/SubprocVecEnv): before each step it evaluates the
  opponents for all envs in one batched forward pass per opponent, then steps the envs. Where
  the rollouts are played in the workers (``worker_rollouts``), each worker plays its share's
  opponents with a copy of it made from an :class:`OpponentPlan`.

Which snapshots make the pool is the choice of
:class:`~foosball_gym.training.selfplay.callback.SelfPlayCallback`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
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


@dataclass
class OpponentPlan:
    """What a share of the environments needs to play its opponents for a rollout: the pool
    and the anchors (picklable players), the anchors' share, the share's rows among the run's
    environments, and its state: each environment's next opponent observation, its assigned
    opponent and a seed for its draws."""

    pool: list[Any]
    anchors: list[Any]
    anchor_share: float
    rows: slice
    total: int
    opp_obs: np.ndarray
    assigned: np.ndarray
    seeds: list[list[int]]


@dataclass
class OpponentState:
    """A share's opponents as a rollout left them, and the seconds it spent choosing their
    actions."""

    opp_obs: np.ndarray
    assigned: np.ndarray
    seconds: float


class StillOpponent:
    """An opponent that holds its rods where they are (zeros), on a batch of observations:
    the first opponent, until a snapshot of the learner replaces it."""

    def __init__(self, size: int) -> None:
        self.size = size

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return np.zeros((len(obs), self.size), np.float32)


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
        # How many of the anchors, from the first, the games meet (LadderCurriculum raises it).
        self.anchors_in_play = len(self.anchors)
        self.anchor_share = float(anchor_share)
        self.whole_action = whole_action
        self.pool: list[Any] = [whole_action(opponent) if whole_action else opponent]
        self._rng = np.random.default_rng(seed)
        # A generator for each environment where a share plays (worker_rollouts): the draws
        # then do not depend on how the environments are split.
        self._rngs: list[np.random.Generator] | None = None
        # Where a share plays: its rows among the run's environments, and a batch of the
        # run's size that holds them (made once, the other rows left at zero).
        self._rows: tuple[slice, np.ndarray] | None = None
        self._assigned = np.zeros(self.num_envs, dtype=int)
        self._opp_obs: np.ndarray | None = None
        # Time spent choosing the opponents' actions, for benchmarks: where the shares play,
        # the sum of theirs, which ran side by side.
        self.opponent_seconds = 0.0

    # -- pool ---------------------------------------------------------------

    def set_pool(self, pool: list[Any]) -> None:
        """Replace the opponents; envs draw from the new pool at their next episode."""
        if not pool:
            raise ValueError("the opponent pool must not be empty")
        self.pool = [self.whole_action(p) for p in pool] if self.whole_action else list(pool)
        self._assigned = np.minimum(self._assigned, len(self.pool) - 1)

    def _draw(self, env: int) -> int:
        rng = self._rng if self._rngs is None else self._rngs[env]
        if self.anchor_share and rng.random() < self.anchor_share:
            # One anchor draws nothing more, as before there could be several.
            if self.anchors_in_play == 1:
                return -1
            return -1 - int(rng.integers(self.anchors_in_play))
        return int(rng.integers(len(self.pool)))

    # -- a share played in a worker ------------------------------------------

    def plan(self, rows: slice, pool: list[Any], seeds: list[list[int]]) -> OpponentPlan:
        """The plan of the environments ``rows`` for a rollout, their opponents played by
        ``pool`` (this env's pool as the worker can play it)."""
        assert self._opp_obs is not None  # reset() sets it before any rollout
        return OpponentPlan(
            pool,
            self.anchors[: self.anchors_in_play],
            self.anchor_share,
            rows,
            self.num_envs,
            self._opp_obs[rows].copy(),
            self._assigned[rows].copy(),
            seeds,
        )

    @classmethod
    def playing(cls, venv: VecEnv, plan: OpponentPlan) -> SelfPlayVecEnv:
        """``venv`` (a share's environments, mid-game) with the opponents of ``plan``."""
        env = cls(venv, plan.pool[0], anchor=plan.anchors or None, anchor_share=plan.anchor_share)
        env.pool = list(plan.pool)
        env._rngs = [np.random.default_rng(seed) for seed in plan.seeds]
        batch = np.zeros((plan.total, *plan.opp_obs.shape[1:]), plan.opp_obs.dtype)
        env._rows = (plan.rows, batch)
        env._opp_obs = plan.opp_obs.copy()
        env._assigned = plan.assigned.copy()
        return env

    def state(self) -> OpponentState:
        assert self._opp_obs is not None
        return OpponentState(self._opp_obs.copy(), self._assigned.copy(), self.opponent_seconds)

    def take(self, rows: slice, state: OpponentState) -> None:
        """The state a share's rollout left its environments ``rows`` in."""
        assert self._opp_obs is not None
        self._opp_obs[rows] = state.opp_obs
        self._assigned[rows] = state.assigned
        self.opponent_seconds += state.seconds

    # -- VecEnv -------------------------------------------------------------

    def reset(self) -> VecEnvObs:
        obs = self.venv.reset()
        self._opp_obs = np.stack([info[OPPONENT_OBS] for info in self.venv.reset_infos])
        self._assigned = np.array([self._draw(i) for i in range(self.num_envs)])
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
                opp[idx] = self._batched(self.pool[k], idx)
        self.opponent_seconds += time.perf_counter() - start
        self.venv.step_async(np.concatenate([actions, opp], axis=1))

    def _batched(self, player: Any, idx: np.ndarray) -> np.ndarray:
        """``player``'s actions for the environments ``idx``. Where a share plays, they are
        computed at the environments' rows of a batch of the run's size: BLAS rounds a row's
        product differently in batches of other sizes, and a run should not depend on how
        its environments are split."""
        assert self._opp_obs is not None
        if self._rows is None:
            return player(self._opp_obs[idx])
        rows, batch = self._rows
        batch[rows] = self._opp_obs
        return player(batch)[rows][idx]

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        assert self._opp_obs is not None  # reset() sets it before any step
        for i, done in enumerate(dones):
            if done:
                if self._assigned[i] < 0:
                    infos[i][AGAINST_ANCHOR] = True
                self._opp_obs[i] = self.venv.reset_infos[i][OPPONENT_OBS]
                self._assigned[i] = self._draw(i)
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
