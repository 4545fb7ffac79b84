"""A frozen recurrent policy (sb3-contrib's RecurrentPPO): its LSTM state carried from one
call to the next, and started afresh by :meth:`RecurrentSnapshot.reset` at each episode.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from foosball_gym.training.loading.sb3_snapshot import PolicySnapshot


class RecurrentSnapshot(PolicySnapshot):
    """A :class:`PolicySnapshot` of a ``RecurrentActorCriticPolicy``, which remembers.

    Each call steps the LSTM on from the state the call before left; :meth:`reset` forgets it,
    and must be called where an episode starts, as RecurrentPPO starts each episode from a
    zero state in training. :func:`~foosball_gym.evaluation.evaluate` calls it. Called with
    a batch, each row is one episode's stream, and every call after a reset takes as many.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._state: tuple[np.ndarray, ...] | None = None

    def reset(self) -> None:
        """Start the next call's episode afresh: from a zero state, as in training."""
        self._state = None

    def _predict(self, batch: np.ndarray) -> np.ndarray:
        n = len(batch)
        if self._state is not None and self._state[0].shape[1] != n:
            raise ValueError(
                f"a recurrent policy stepping {self._state[0].shape[1]} episodes was given "
                f"{n} observations: reset() it where episodes start"
            )
        starts = np.full(n, self._state is None)
        actions, self._state = self.policy.predict(
            batch, state=self._state, episode_start=starts, deterministic=self.deterministic
        )
        return actions
