"""A vectorised env whose environments are split over a few worker processes, one per core,
each stepping its share in turn.

SB3's ``SubprocVecEnv`` gives every environment a process of its own: with 16 environments on
2 cores, 16 processes take turns and each step is 16 messages each way. Here each worker holds
an :class:`~foosball_gym.training.sb3.in_process_vec_env.InProcessVecEnv` of its share (SB3's
``DummyVecEnv``: resets, final observations, seeds and ``env_method`` behave exactly as SB3's
own), and a step is one message
each way per worker. By default the training process is the first worker: it steps its own
share while the others step theirs. Seeded alike, it gives the same observations, rewards and
infos as a ``DummyVecEnv`` of the same environments.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import (
    CloudpickleWrapper,
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)

from foosball_gym.training.sb3.in_process_vec_env import InProcessVecEnv
from foosball_gym.training.sb3.worker_rollouts import RolloutPart, RolloutPlan, play_rollout


class _Failure:
    """An exception raised in a worker, sent to be raised again in the main process."""

    def __init__(self, err: Exception) -> None:
        self.err = err


def _answer(remote: Any) -> Any:
    answer = remote.recv()
    if isinstance(answer, _Failure):
        raise answer.err
    return answer


def _handle(envs: InProcessVecEnv, cmd: str, data: Any) -> Any:
    """A worker's answer to one command (``close`` answers nothing)."""
    if cmd == "step":
        envs.step_async(data)
        return (*envs.step_wait(), envs.reset_infos)
    if cmd == "rollout":
        return play_rollout(envs, data)
    if cmd == "reset":
        seeds, options = data
        for i, (seed, option) in enumerate(zip(seeds, options)):
            envs._seeds[i], envs._options[i] = seed, option
        return envs.reset(), envs.reset_infos
    if cmd == "close":
        envs.close()
        return None
    if cmd == "get_spaces":
        return envs.observation_space, envs.action_space, envs.render_mode
    if cmd == "env_method":
        name, args, kwargs, indices = data
        return envs.env_method(name, *args, indices=indices, **kwargs)
    if cmd == "get_attr":
        return envs.get_attr(data[0], indices=data[1])
    if cmd == "has_attr":
        return envs.has_attr(data)
    if cmd == "set_attr":
        envs.set_attr(data[0], data[1], indices=data[2])
        return None
    if cmd == "is_wrapped":
        return envs.env_is_wrapped(data[0], indices=data[1])
    if cmd == "render":
        return envs.get_images()
    raise NotImplementedError(f"unknown command {cmd!r}")


def _worker(remote: Any, parent_remote: Any, env_fns: CloudpickleWrapper) -> None:
    # Ctrl-C reaches every process of the terminal's group; the main process alone stops the
    # run, after writing a checkpoint, and a worker gone first would break its last steps.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    parent_remote.close()
    # The functions reach the worker by value, so nothing has registered the ids here.
    import foosball_gym.registration  # noqa: F401

    envs = InProcessVecEnv(env_fns.var)
    while True:
        try:
            cmd, data = remote.recv()
        except EOFError:
            break
        try:
            answer = _handle(envs, cmd, data)
        except Exception as err:  # noqa: BLE001  (the main process raises it)
            remote.send(_Failure(err))
            continue
        if cmd == "close":
            remote.close()
            break
        remote.send(answer)


class _Here:
    """The main process's own share, spoken to as a worker's pipe is: a command sent is run
    when its answer is asked for, so the share steps while the workers step theirs."""

    def __init__(self, env_fns: list[Callable[[], gym.Env]]) -> None:
        self.envs = InProcessVecEnv(env_fns)
        self.pending: list[tuple[str, Any]] = []

    def send(self, message: tuple[str, Any]) -> None:
        self.pending.append(message)

    def recv(self) -> Any:
        cmd, data = self.pending.pop(0)
        try:
            return _handle(self.envs, cmd, data)
        except Exception as err:  # noqa: BLE001  (raised by _answer, as a worker's)
            return _Failure(err)

    def close(self) -> None:
        pass


def default_workers(n_envs: int) -> int:
    """One worker per core this process may run on, and no more than there are environments."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # macOS and Windows
        cores = os.cpu_count() or 1
    return max(1, min(n_envs, cores))


class BatchedSubprocVecEnv(VecEnv):
    """``len(env_fns)`` environments in ``workers`` processes (default: one per core).

    Args:
        env_fns: one function per environment that builds it.
        workers: processes that step environments; the environments are split between them
            as evenly as they go, in order (the first worker holds the first share).
        start_method: as SB3's ``SubprocVecEnv``: forkserver where there is one, else spawn.
        here: the main process is the first worker (the default): it steps its share while
            the others step theirs, so one core's worth of environments needs no messages and
            the workers' wake-ups hide behind it; False gives every share a worker process.
    """

    def __init__(
        self,
        env_fns: list[Callable[[], gym.Env]],
        workers: int | None = None,
        start_method: str | None = None,
        here: bool = True,
    ) -> None:
        n_envs = len(env_fns)
        if n_envs < 1:
            raise ValueError("BatchedSubprocVecEnv needs at least one environment")
        workers = default_workers(n_envs) if workers is None else int(workers)
        if not 1 <= workers <= n_envs:
            raise ValueError(f"workers must lie in [1, {n_envs}] (the environments), got {workers}")
        self.waiting = False
        self.closed = False
        bounds = np.linspace(0, n_envs, workers + 1).round().astype(int)
        self._slices = [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]
        if start_method is None:
            methods = mp.get_all_start_methods()
            start_method = "forkserver" if "forkserver" in methods else "spawn"
        ctx = mp.get_context(start_method)
        away = self._slices[1:] if here else self._slices
        pipes = [ctx.Pipe() for _ in away]
        self.remotes: list[Any] = [parent for parent, _ in pipes]
        if here:
            self.remotes.insert(0, _Here(env_fns[self._slices[0]]))
        self.processes = []
        for (parent, child), share in zip(pipes, away):
            args = (child, parent, CloudpickleWrapper(env_fns[share]))
            # daemon: a worker must not outlive a main process that crashed.
            process = ctx.Process(target=_worker, args=args, daemon=True)  # type: ignore[attr-defined]
            process.start()
            self.processes.append(process)
            child.close()
        self.remotes[0].send(("get_spaces", None))
        observation_space, action_space, self.render_mode = _answer(self.remotes[0])
        super().__init__(n_envs, observation_space, action_space)

    @property
    def workers(self) -> int:
        return len(self.remotes)

    @property
    def shares(self) -> list[slice]:
        """The environments each worker holds, in order."""
        return self._slices

    def play_rollouts(self, plans: list[RolloutPlan]) -> list[RolloutPart]:
        """Each worker plays its share's rollout, all at once (one plan per share)."""
        for remote, plan in zip(self.remotes, plans, strict=True):
            remote.send(("rollout", plan))
        self.waiting = True
        parts = [_answer(remote) for remote in self.remotes]
        self.waiting = False
        return parts

    def step_async(self, actions: np.ndarray) -> None:
        for remote, share in zip(self.remotes, self._slices):
            remote.send(("step", actions[share]))
        self.waiting = True

    def step_wait(self) -> VecEnvStepReturn:
        results = [_answer(remote) for remote in self.remotes]
        self.waiting = False
        obs, rewards, dones, infos, reset_infos = zip(*results)
        self.reset_infos = [info for part in reset_infos for info in part]
        return (
            _concatenate(obs),
            np.concatenate(rewards),
            np.concatenate(dones),
            [info for part in infos for info in part],
        )

    def reset(self) -> VecEnvObs:
        for remote, share in zip(self.remotes, self._slices):
            remote.send(("reset", (self._seeds[share], self._options[share])))
        results = [_answer(remote) for remote in self.remotes]
        obs, reset_infos = zip(*results)
        self.reset_infos = [info for part in reset_infos for info in part]
        # Seeds and options are used once, as in SB3's own vectorised envs.
        self._reset_seeds()
        self._reset_options()
        return _concatenate(obs)

    def close(self) -> None:
        if self.closed:
            return
        if self.waiting:
            for remote in self.remotes:
                remote.recv()
        for remote in self.remotes:
            remote.send(("close", None))
        for remote in self.remotes:
            if isinstance(remote, _Here):
                remote.recv()
        for process in self.processes:
            process.join()
        for remote in self.remotes:
            remote.close()
        self.closed = True

    def get_images(self) -> Sequence[np.ndarray | None]:
        for remote in self.remotes:
            remote.send(("render", None))
        return [image for remote in self.remotes for image in _answer(remote)]

    def has_attr(self, attr_name: str) -> bool:
        for remote in self.remotes:
            remote.send(("has_attr", attr_name))
        return all([_answer(remote) for remote in self.remotes])

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return self._call("get_attr", lambda local: (attr_name, local), indices)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        self._call("set_attr", lambda local: (attr_name, value, local), indices)

    def env_method(
        self,
        method_name: str,
        *method_args: Any,
        indices: VecEnvIndices = None,
        **method_kwargs: Any,
    ) -> list[Any]:
        return self._call(
            "env_method", lambda local: (method_name, method_args, method_kwargs, local), indices
        )

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        return self._call("is_wrapped", lambda local: (wrapper_class, local), indices)

    def _call(self, cmd: str, data: Callable[[list[int]], Any], indices: VecEnvIndices) -> Any:
        """Send ``cmd`` to each worker holding one of ``indices``, with its own indices, and
        the answers in the order of ``indices``."""
        wanted = list(self._get_indices(indices))
        asked = []
        for remote, share in zip(self.remotes, self._slices):
            local = [i - share.start for i in wanted if share.start <= i < share.stop]
            if local:
                remote.send((cmd, data(local)))
                asked.append((remote, share, local))
        answers: dict[int, Any] = {}
        for remote, share, local in asked:
            answer = _answer(remote)
            if answer is None:  # set_attr
                continue
            answers.update({share.start + i: a for i, a in zip(local, answer)})
        return [answers[i] for i in wanted] if answers else None


def _concatenate(parts: Sequence[Any]) -> Any:
    first = parts[0]
    if isinstance(first, dict):
        return {key: np.concatenate([p[key] for p in parts]) for key in first}
    if isinstance(first, tuple):
        return tuple(np.concatenate([p[i] for p in parts]) for i in range(len(first)))
    return np.concatenate(parts)
