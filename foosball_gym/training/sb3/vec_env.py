"""The vectorised training envs of a run: Dummy or Subproc, with self-play's opponents and
VecNormalize as the configuration asks."""

from __future__ import annotations

import signal
from collections.abc import Callable
from functools import partial
from typing import Any

from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

import foosball_gym.registration  # noqa: F401  (the package registers the ids)
from foosball_gym.policy_io.task import residual_scale
from foosball_gym.training.config import VEC_ENV_KINDS, TrainConfig
from foosball_gym.training.held_rods import HeldRodsWrapper
from foosball_gym.training.loading.loader import whole_action_policy
from foosball_gym.training.sb3.batched_vec_env import BatchedSubprocVecEnv, default_workers
from foosball_gym.training.sb3.in_process_vec_env import InProcessVecEnv
from foosball_gym.training.selfplay.opponents import (
    OpponentActionWrapper,
    SelfPlayVecEnv,
    StillOpponent,
)


def _ignoring_sigint(env_fn: Callable[[], Any]) -> Callable[[], Any]:
    def make() -> Any:
        # Ctrl-C reaches every process of the terminal's group; the main process alone stops
        # the run, after writing a checkpoint, and a worker gone first would break its last
        # steps.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        # This function reaches the worker by value, so nothing has registered the ids there.
        import foosball_gym.registration  # noqa: F401, F811

        return env_fn()

    return make


def subproc_vec_env(env_fns: list[Callable[[], Any]], **kwargs: Any) -> SubprocVecEnv:
    """``SubprocVecEnv`` whose workers ignore SIGINT."""
    return SubprocVecEnv([_ignoring_sigint(fn) for fn in env_fns], **kwargs)


def batched_vec_env(env_fns: list[Callable[[], Any]], **kwargs: Any) -> Any:
    """``BatchedSubprocVecEnv`` over one worker per core; with a single worker's share (one
    environment, or one core), an :class:`InProcessVecEnv` in this process, which steps alike
    without the messages."""
    if kwargs.get("workers", default_workers(len(env_fns))) == 1:
        return InProcessVecEnv(env_fns)
    return BatchedSubprocVecEnv(env_fns, **kwargs)


VEC_ENVS = dict(
    zip(VEC_ENV_KINDS, (InProcessVecEnv, subproc_vec_env, batched_vec_env), strict=True)
)


def _wrap(env: Any, rods_held_share: float, self_play: bool) -> Any:
    if rods_held_share:
        env = HeldRodsWrapper(env, rods_held_share)
    return OpponentActionWrapper(env) if self_play else env


def make_env(config: TrainConfig, seed_offset: int = 0) -> Any:
    """The vectorised training envs (with self-play and normalisation wrappers as configured)."""
    wrapper = None
    if config.self_play or config.rods_held_share:
        wrapper = partial(
            _wrap, rods_held_share=config.rods_held_share, self_play=bool(config.self_play)
        )
    venv = make_vec_env(
        config.env_id,
        n_envs=config.n_envs,
        seed=config.seed + seed_offset,
        env_kwargs=config.env_kwargs,
        wrapper_class=wrapper,
        # SB3 calls vec_env_cls(env_fns, **kwargs), so a function like subproc_vec_env does,
        # though it types the argument as one of its two classes.
        vec_env_cls=VEC_ENVS[config.vec_env],  # type: ignore[arg-type]
    )
    if config.self_play:
        # The first opponent is replaced by a snapshot of the learner as training starts.
        assert venv.action_space.shape is not None  # OpponentActionWrapper's Box
        n = venv.action_space.shape[0] // 2
        anchor = None
        if config.selfplay_scripted_share:
            levels = config.selfplay_scripted_levels or (None,)
            anchor = [venv.env_method("scripted_opponent", n, indices=[0])[0] for n in levels]
        whole_action = None
        if residual_scale(config.env_kwargs.get("residual")) or config.env_kwargs.get(
            "slide_around_ball"
        ):
            # Snapshots of a residual learner give corrections, and those of a learner with
            # slide_around_ball slide around the ball; the opponent's side of the env takes
            # whole actions over the rods' travel.
            def whole_action(snapshot: Any) -> Any:
                return whole_action_policy(snapshot, config.env_id, config.env_kwargs)[0]

        venv = SelfPlayVecEnv(
            venv,
            StillOpponent(n),
            config.seed,
            anchor=anchor,
            anchor_share=config.selfplay_scripted_share,
            whole_action=whole_action,
        )
    if config.normalize or config.normalize_reward:
        venv = VecNormalize(
            venv, norm_obs=config.normalize, norm_reward=config.normalize_reward, gamma=config.gamma
        )
    return venv
