"""Self-play's callback for Stable-Baselines3 (docs/self-play.md): counts the learner's games,
and replaces its opponent by a snapshot of it when the rule says the learner beat it
(:mod:`~foosball_gym.training.selfplay.rule`), optionally behind a gate
(:mod:`~foosball_gym.training.selfplay.gate`). It keeps the pool of the latest snapshots that
:class:`~foosball_gym.training.selfplay.opponents.SelfPlayVecEnv` draws from, logs to the SB3
logger and saves every snapshot, so a run can be resumed and its history inspected.
"""

from __future__ import annotations

import contextlib
import json
from collections import deque
from pathlib import Path

from stable_baselines3.common.callbacks import BaseCallback

from foosball_gym.training.loading.sb3_snapshot import PolicySnapshot
from foosball_gym.training.run_dir.files import append_text
from foosball_gym.training.run_dir.storage import save_model
from foosball_gym.training.selfplay.gate import ReplacementGate
from foosball_gym.training.selfplay.history import (
    GATE_LOG,
    STALL_LOG,
    SnapshotHistory,
    snapshot_file,
)
from foosball_gym.training.selfplay.opponents import (
    AGAINST_ANCHOR,
    SelfPlayVecEnv,
    find_selfplay_env,
)
from foosball_gym.training.selfplay.rule import ReplacementRule, game_result
from foosball_gym.training.signals import Interrupted, SignalStop

__all__ = ["GATE_LOG", "SelfPlayCallback"]


class SelfPlayCallback(BaseCallback):
    """Replace the opponent by the learner when the learner beats it (docs/self-play.md).

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
            :class:`~foosball_gym.training.selfplay.rule.ReplacementRule`).
        sampled: the opponents sample their actions from their policy, as the learner does,
            instead of acting on its mean. The rule then weighs like against like: a learner
            that explores loses to its own deterministic copy (measured: a clone of the
            scripted keeper, exploring, won 4 and lost 25 of 100 games against itself).
        gate: where given, a replacement the rule grants stands only if the learner's mean
            passes it (:class:`~foosball_gym.training.selfplay.gate.ReplacementGate`). Every
            verdict is appended to ``gate.jsonl`` and each generation that passed is also
            saved as a model, ``generation_<generation>.zip`` with its normalisation, which
            ``foosball eval`` and ``load_policy`` read like any model.
        stop: the run's signal stop: a signal during the gate's games ends them (and the
            run) where it lands, the replacement not judged.
        stall_games: after this many games without a new opponent the run has stalled; it
            says so (printed, ``selfplay/stalls`` in TensorBoard, a line in ``stalls.jsonl``)
            and judges by the ``fallback`` rule from then on (see
            :class:`~foosball_gym.training.selfplay.rule.ReplacementRule`; 0: never).
        fallback: the rule a stall switches to; None keeps the rule.

    TensorBoard gets the window's rates and ``selfplay/elo``, the learner's rating against its
    opponents (see :class:`~foosball_gym.training.selfplay.rule.ReplacementRule`). Games
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
        stop: SignalStop | None = None,
        stall_games: int = 0,
        fallback: str | None = None,
    ) -> None:
        super().__init__(verbose)
        self.stop = stop
        if pool_size < 1:
            raise ValueError(f"pool_size must be at least 1, got {pool_size}")
        self.judge = ReplacementRule(rule, threshold, window, stall_games, fallback)
        self.stalls = 0
        self.pool_size = pool_size
        self.sampled = sampled
        self.gate = gate
        self.save_dir = None if save_dir is None else Path(save_dir)
        self.pool: list[PolicySnapshot] = []
        self.history = SnapshotHistory(self.save_dir, self.judge, pool_size)
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
        if not self.pool and self.history.saved():
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
                self._report_stall()
                try:
                    passed = replaced is not None and self._gate_passes()
                except Interrupted:
                    return False
                if replaced is not None and passed:
                    self._add_snapshot(*replaced)
                    assert self._env is not None  # set as training starts
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

    def _report_stall(self) -> None:
        stall = self.judge.take_stall()
        if stall is None:
            return
        self.stalls += 1
        self.logger.record("selfplay/stalls", self.stalls)
        # Printed whatever the verbosity: a run that stopped climbing must not look busy.
        print(stall.message(self.generation, self.num_timesteps), flush=True)
        if self.save_dir is not None:
            self.save_dir.mkdir(parents=True, exist_ok=True)
            line = json.dumps(stall.record(self.generation, self.num_timesteps)) + "\n"
            append_text(self.save_dir / STALL_LOG, line)

    def _gate_passes(self) -> bool:
        if self.gate is None:
            return True
        learner = PolicySnapshot.of_model(self.model, deterministic=True)
        with self.stop.interruptible() if self.stop else contextlib.nullcontext():
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
            line = json.dumps({"generation": self.generation, **verdict.record()}) + "\n"
            append_text(self.save_dir / GATE_LOG, line)
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
        if self.verbose and score is not None:
            print(
                f"self-play: opponent replaced by generation {generation} at "
                f"{self.num_timesteps} steps ({self.judge.rule} {score:+.2f}, Elo {elo:+.0f})"
            )
        if self.save_dir is not None:
            self.save_dir.mkdir(parents=True, exist_ok=True)
            snap.save(snapshot_file(self.save_dir, generation))
            if self.gate is not None:
                save_model(self.model, self.save_dir / f"generation_{generation:04d}.zip")
        # After the snapshot's files: a history never names a snapshot that is not there.
        self.history.add(
            generation, self.num_timesteps, score, elo, [p.generation for p in self.pool]
        )

    def _restore(self) -> None:
        assert self.save_dir is not None
        gens = self.history.restore()
        self.pool = [PolicySnapshot.load(snapshot_file(self.save_dir, g)) for g in gens]
        for snap in self.pool:
            snap.deterministic = not self.sampled
