"""Self-play for Stable-Baselines3 (SPEC §4): the learner plays frozen past copies of itself.

Three pieces:

- :class:`OpponentActionWrapper` (per env): the vectorised env, not the env, chooses the
  opponent's action. The env's action becomes ``[learner action, opponent action]`` and its
  info carries the opponent's (mirrored) observation.
- :class:`SelfPlayVecEnv` (around the Dummy/SubprocVecEnv): before each step it evaluates the
  opponents for all envs in one batched forward pass per opponent, then steps the envs.
- :class:`SelfPlayCallback`: counts finished games, replaces the opponent by a snapshot of the
  learner when the learner wins at least ``threshold`` of the last ``window`` games (the
  paper's rule; the net score is an option, see
  :mod:`~foosball_gym.training.selfplay_rule`), optionally keeps a pool of the last
  ``pool_size`` snapshots sampled per episode, logs to the SB3 logger and saves every
  snapshot so a run can be resumed and its history inspected.
"""

from __future__ import annotations

import json
import time
from collections import deque
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from foosball_gym.training.files import NORM_FILE
from foosball_gym.training.selfplay_gate import ReplacementGate
from foosball_gym.training.selfplay_rule import ReplacementRule, history_record, restored_elo
from foosball_gym.training.snapshot import PolicySnapshot
from foosball_gym.training.storage import save_model

OPPONENT_OBS = "opponent_obs"
# In the info of a game's last step: the game was against the scripted anchor, not a snapshot.
AGAINST_ANCHOR = "against_scripted_anchor"
_ANCHOR = -1  # the pool index that stands for the anchor
GATE_LOG = "gate.jsonl"


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
        base = env.unwrapped
        if not getattr(base, "layout", None) or not base.layout.opponent:
            raise ValueError(f"{base.spec.id if base.spec else base} has no opponent to play")
        own = env.action_space
        self._n = own.shape[0]
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2 * self._n,), dtype=np.float32)
        self._queued = _QueuedAction(self._n)
        base.set_opponent(self._queued)

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        info[OPPONENT_OBS] = self.env.unwrapped.opponent_observation()
        return obs, info

    def step(self, action: np.ndarray):
        self._queued.action = np.asarray(action[self._n :], dtype=np.float32)
        obs, reward, terminated, truncated, info = self.env.step(action[: self._n])
        info[OPPONENT_OBS] = self.env.unwrapped.opponent_observation()
        return obs, reward, terminated, truncated, info


class SelfPlayVecEnv(VecEnvWrapper):
    """Plays the opponents of every env of a VecEnv built with :class:`OpponentActionWrapper`.

    Args:
        venv: the vectorised envs (each wrapped in ``OpponentActionWrapper``).
        opponent: the first opponent (a callable on a batch of observations).
        seed: seeds the choice of opponents from the pool.
        anchor: a fixed opponent acting on one observation (the scripted team), played in
            ``anchor_share`` of the games instead of the pool; the last step's info of such a
            game says so (``AGAINST_ANCHOR``), so that the replacement rule can leave it out.
        anchor_share: the share of games against ``anchor``, in [0, 1).
    """

    def __init__(
        self,
        venv: VecEnv,
        opponent: Any,
        seed: int | None = None,
        anchor: Any = None,
        anchor_share: float = 0.0,
    ) -> None:
        n = venv.action_space.shape[0] // 2
        learner_space = spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)
        super().__init__(venv, action_space=learner_space)
        if not 0.0 <= anchor_share < 1.0 or (anchor_share > 0.0 and anchor is None):
            raise ValueError(
                f"anchor_share must be in [0, 1), and above 0 only with an anchor; got "
                f"{anchor_share!r} with {'an' if anchor is not None else 'no'} anchor"
            )
        self.anchor, self.anchor_share = anchor, float(anchor_share)
        self.pool: list[Any] = [opponent]
        self._rng = np.random.default_rng(seed)
        self._assigned = np.zeros(self.num_envs, dtype=int)
        self._opp_obs: np.ndarray | None = None
        self.opponent_seconds = 0.0  # time spent in opponent inference, for benchmarks

    # -- pool ---------------------------------------------------------------

    def set_pool(self, pool: list[Any]) -> None:
        """Replace the opponents; envs draw from the new pool at their next episode."""
        if not pool:
            raise ValueError("the opponent pool must not be empty")
        self.pool = list(pool)
        self._assigned = np.minimum(self._assigned, len(self.pool) - 1)

    def _draw(self) -> int:
        if self.anchor_share and self._rng.random() < self.anchor_share:
            return _ANCHOR
        return int(self._rng.integers(len(self.pool)))

    # -- VecEnv -------------------------------------------------------------

    def reset(self) -> np.ndarray:
        obs = self.venv.reset()
        self._opp_obs = np.stack([info[OPPONENT_OBS] for info in self.venv.reset_infos])
        self._assigned = np.array([self._draw() for _ in range(self.num_envs)])
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        start = time.perf_counter()
        opp = np.zeros_like(actions, dtype=np.float32)
        for k in np.unique(self._assigned):
            idx = np.nonzero(self._assigned == k)[0]
            if k == _ANCHOR:
                opp[idx] = np.stack([self.anchor(o) for o in self._opp_obs[idx]])
            else:
                opp[idx] = self.pool[k](self._opp_obs[idx])
        self.opponent_seconds += time.perf_counter() - start
        self.venv.step_async(np.concatenate([actions, opp], axis=1))

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        for i, done in enumerate(dones):
            if done:
                if self._assigned[i] == _ANCHOR:
                    infos[i][AGAINST_ANCHOR] = True
                self._opp_obs[i] = self.venv.reset_infos[i][OPPONENT_OBS]
                self._assigned[i] = self._draw()
            else:
                self._opp_obs[i] = infos[i][OPPONENT_OBS]
        return obs, rewards, dones, infos


def game_result(info: dict[str, Any]) -> int:
    """+1 won, -1 lost, 0 drawn, from the info of a game's last step."""
    diff = info.get("goals_for", 0) - info.get("goals_against", 0)
    return int(np.sign(diff))


def find_selfplay_env(env: VecEnv) -> SelfPlayVecEnv:
    while env is not None and not isinstance(env, SelfPlayVecEnv):
        env = getattr(env, "venv", None)
    if env is None:
        raise ValueError("self-play needs the training env wrapped in SelfPlayVecEnv")
    return env


class SelfPlayCallback(BaseCallback):
    """Replace the opponent by the learner when the learner beats it (SPEC §4).

    Args:
        window: games the rule judges (100).
        threshold: the win rate at or above which (``rule="win_rate"``, the paper's), or the
            net score, (wins - losses) / games, above which (``rule="net_score"``) the
            opponent is replaced (0.2).
        pool_size: keep the last this many snapshots and draw each episode's opponent from them
            (1: always the latest).
        save_dir: where snapshots (``opponent_<generation>.pt``) and ``history.json`` go; None
            keeps nothing on disk.
        verbose: 1 prints each replacement.
        rule: ``"win_rate"``, ``"net_score"``, ``"winning"`` or ``"significant"`` (see
            :class:`~foosball_gym.training.selfplay_rule.ReplacementRule`).
        sampled: the opponents sample their actions from their policy, as the learner does,
            instead of acting on its mean. The rule then weighs like against like: a learner
            that explores loses to its own deterministic copy (measured: a clone of the
            scripted keeper, exploring, won 4 and lost 25 of 100 games against itself).
        gate: where given, a replacement the rule grants stands only if the learner's mean
            passes it (:class:`~foosball_gym.training.selfplay_gate.ReplacementGate`). Every
            verdict is appended to ``gate.jsonl`` and each generation that passed is also
            saved as a model, ``generation_<generation>.zip`` with its normalisation, which
            ``foosball eval`` and ``load_policy`` read like any model.

    TensorBoard gets the window's rates and ``selfplay/elo``, the learner's rating against its
    opponents (see :class:`~foosball_gym.training.selfplay_rule.ReplacementRule`). Games
    against a scripted anchor (:class:`SelfPlayVecEnv`) are left out of the rule and counted
    apart: ``selfplay/anchor_goals_for`` and ``_against``, the learner's goals per game over
    its last ``window`` games against the anchor.
    """

    def __init__(
        self,
        window: int = 100,
        threshold: float = 0.2,
        pool_size: int = 1,
        save_dir: str | Path | None = None,
        verbose: int = 0,
        rule: str = "win_rate",
        sampled: bool = False,
        gate: ReplacementGate | None = None,
    ) -> None:
        super().__init__(verbose)
        if pool_size < 1:
            raise ValueError(f"pool_size must be at least 1, got {pool_size}")
        self.judge = ReplacementRule(rule, threshold, window)
        self.pool_size = pool_size
        self.sampled = sampled
        self.gate = gate
        self.save_dir = None if save_dir is None else Path(save_dir)
        self.pool: list[PolicySnapshot] = []
        self.history: list[dict[str, Any]] = []
        self._env: SelfPlayVecEnv | None = None
        self._anchor_goals: deque[tuple[int, int]] = deque(maxlen=window)

    @property
    def generation(self) -> int:
        return self.pool[-1].generation if self.pool else 0

    @property
    def games(self) -> int:
        return self.judge.games

    def _on_training_start(self) -> None:
        self._env = find_selfplay_env(self.model.get_env())
        if (
            not self.pool
            and self.save_dir is not None
            and (self.save_dir / "history.json").exists()
        ):
            self._restore()
        if not self.pool:
            self._add_snapshot(score=None, elo=0.0)
        self._env.set_pool(self.pool)

    def _on_step(self) -> bool:
        for done, info in zip(self.locals["dones"], self.locals["infos"]):
            if done and info.get(AGAINST_ANCHOR):
                self._anchor_goals.append((info.get("goals_for", 0), info.get("goals_against", 0)))
            elif done:
                replaced = self.judge.record(game_result(info))
                if replaced is not None and self._gate_passes():
                    self._add_snapshot(*replaced)
                    self._env.set_pool(self.pool)
        rates = self.judge.rates()
        if rates:
            self.logger.record("selfplay/generation", self.generation)
            for key, value in rates.items():
                self.logger.record(key, value)
        if self._anchor_goals:
            games = len(self._anchor_goals)
            self.logger.record(
                "selfplay/anchor_goals_for", sum(g[0] for g in self._anchor_goals) / games
            )
            self.logger.record(
                "selfplay/anchor_goals_against", sum(g[1] for g in self._anchor_goals) / games
            )
        return True

    def _gate_passes(self) -> bool:
        if self.gate is None:
            return True
        learner = PolicySnapshot.of_model(self.model, deterministic=True)
        verdict = self.gate.judge(learner, self.pool[-1], self.num_timesteps)
        self.logger.record("selfplay/gate_passed", int(verdict.passed))
        if self.verbose:
            print(
                f"self-play gate at {self.num_timesteps} steps: {verdict.wins} won, "
                f"{verdict.draws} drawn, {verdict.losses} lost against generation "
                f"{self.generation}; against the scripted side goals "
                f"{verdict.goals_for}:{verdict.goals_against}, generation {self.generation}'s "
                f"{verdict.opponent_goals_for}:{verdict.opponent_goals_against}: "
                f"{'passed' if verdict.passed else 'refused'}"
            )
        if self.save_dir is not None:
            self.save_dir.mkdir(parents=True, exist_ok=True)
            with open(self.save_dir / GATE_LOG, "a") as log:
                log.write(json.dumps({"generation": self.generation, **verdict.record()}) + "\n")
        return verdict.passed

    def _on_training_end(self) -> None:
        if self.gate is not None:
            self.gate.close()

    def _add_snapshot(self, score: float | None, elo: float) -> None:
        generation = self.generation + 1 if self.pool else 0
        snap = PolicySnapshot.of_model(
            self.model, generation=generation, deterministic=not self.sampled
        )
        self.pool = (self.pool + [snap])[-self.pool_size :]
        self.history.append(
            history_record(generation, self.num_timesteps, self.games, self.judge, score, elo)
        )
        self.judge.opponent_elo = restored_elo(self.history, [p.generation for p in self.pool])
        if self.verbose and score is not None:
            print(
                f"self-play: opponent replaced by generation {generation} at "
                f"{self.num_timesteps} steps ({self.judge.rule} {score:+.2f}, Elo {elo:+.0f})"
            )
        if self.save_dir is not None:
            self.save_dir.mkdir(parents=True, exist_ok=True)
            snap.save(self.save_dir / f"opponent_{generation:04d}.pt")
            if self.gate is not None:
                name = f"generation_{generation:04d}"
                save_model(
                    self.model,
                    self.save_dir / f"{name}.zip",
                    self.save_dir / f"{name}_{NORM_FILE}",
                )
            tmp = self.save_dir / "history.json.tmp"
            tmp.write_text(json.dumps(self.history, indent=1))
            tmp.replace(self.save_dir / "history.json")

    def _restore(self) -> None:
        assert self.save_dir is not None
        self.history = json.loads((self.save_dir / "history.json").read_text())
        gens = [h["generation"] for h in self.history][-self.pool_size :]
        self.pool = [PolicySnapshot.load(self.save_dir / f"opponent_{g:04d}.pt") for g in gens]
        for snap in self.pool:
            snap.deterministic = not self.sampled
        self.judge.games = self.history[-1]["games"]
        self.judge.opponent_elo = restored_elo(self.history, gens)
