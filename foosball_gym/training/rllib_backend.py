"""Self-play PPO on Ray RLlib: sampling spread over env runners, on one machine or a cluster.

The two-player task is played as its PettingZoo game (:mod:`foosball_gym.multiagent`) on
RLlib's multi-agent API. One module, ``learner``, plays ``home`` and is trained; ``away`` is
played by frozen snapshots of it, ``opponent_<generation>``, drawn per episode from a pool.
The pool follows :class:`~foosball_gym.training.selfplay.SelfPlayCallback`'s rule
(:mod:`~foosball_gym.training.selfplay_rule`): once the learner wins at least
``selfplay_threshold`` (20 %) of the last ``selfplay_window`` games (or, with
``selfplay_rule="net_score"``, its net score exceeds it), a snapshot of the learner joins the
pool, which keeps the last ``selfplay_pool`` of them.

A run directory looks like an SB3 run's (see :mod:`foosball_gym.training.files`)::

    config.json            the TrainConfig, with "backend": "rllib" and "num_workers"
    policy.pt, policy.json the learned home policy (see below): what `foosball eval` loads
    checkpoints/           step_<timesteps>/ (learner.pt, optimizer.pt, policy.pt/.json);
                           latest.json names the last
    selfplay/              opponent_<generation>.pt and history.json
    eval.csv, eval.png     the evaluation curve against the env's scripted opponent
    best/                  the policy of the best evaluation so far
    tb/                    TensorBoard scalars (where tensorboard is installed)

The policy is written without pickle: ``policy.pt`` holds only tensors (``layers.<i>.weight``
and ``.bias`` of the actor's Linear layers, read with ``torch.load(weights_only=True)``) and
``policy.json`` describes the network: sizes, activation, environment. The action is the
mean of the Gaussian the actor outputs, clipped to [-1, 1]. :func:`load_rllib_policy` reads
it; neither reading nor evaluating it needs Ray.

Differences from the SB3 backend: PPO only, two-player tasks only (self-play is the point);
observations are not normalised (RLlib's MeanStdFilter would feed the frozen opponents the
away side's running statistics, not those they were trained with), so ``normalize`` is
recorded as false; ``target_kl`` and ``pretrain_episodes`` are not supported; resuming keeps
the weights, the optimiser's state, the pool and the curve.

Needs the ``distributed`` extra: ``pip install -e ".[distributed]"``.
"""

from __future__ import annotations

import csv
import functools
import json
import math
import random
import shutil
import time
import warnings
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from foosball_gym.training.config import (
    PhysicsMismatchWarning,
    TrainConfig,
    physics_mismatch,
    physics_record,
)
from foosball_gym.training.files import (
    CHECKPOINT_DIR,
    CONFIG_FILE,
    LATEST_FILE,
    atomic_write_text,
    has_checkpoint,
)
from foosball_gym.training.selfplay_rule import ReplacementRule, history_record, restored_elo
from foosball_gym.training.signals import SignalStop

BACKEND = "rllib"
POLICY_FILE = "policy.pt"
POLICY_INFO_FILE = "policy.json"
POLICY_FORMAT = 1
LEARNER = "learner"
HOME, AWAY = "home", "away"
EVAL_SEED = 1_000_000
# What eval.csv holds, in the SB3 backend's order, so one reader serves both.
EVAL_FIELDS = (
    "timesteps",
    "wall_seconds",
    "success_rate",
    "ci_low",
    "ci_high",
    "mean_reward",
    "mean_length",
    "goals_for",
    "goals_against",
)
_ENV_NAME = "foosball_selfplay"
INSTALL = 'pip install -e ".[distributed]"'


def require_ray() -> None:
    """Raise ImportError naming the ``distributed`` extra where Ray RLlib or PyTorch is missing."""
    try:
        import pettingzoo  # noqa: F401
        import ray.rllib  # noqa: F401
        import torch  # noqa: F401
    except ImportError as err:
        raise ImportError(
            f"the rllib backend needs Ray RLlib, PettingZoo and PyTorch ({err.name} is "
            f"missing); install them with: {INSTALL} in a checkout, or "
            'pip install "foosball_gym[distributed]"'
        ) from err


def opponent_id(generation: int) -> str:
    return f"opponent_{generation:04d}"


# --------------------------------------------------------------------------- env runner side
# These run in the env runners' processes, which import this module by name: the package
# must be installed on every node of a cluster.


def make_game(env_config: Mapping[str, Any]) -> Any:
    """The RLlib multi-agent env of ``env_config["env_id"]`` (an RLlib env creator)."""
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    from foosball_gym.multiagent import parallel_env

    return ParallelPettingZooEnv(
        parallel_env(env_config["env_id"], **dict(env_config.get("env_kwargs", {})))
    )


def map_agent(agent_id: str, episode: Any, *, opponents: tuple[str, ...], **_: Any) -> str:
    """The learner plays home; away is an opponent drawn from the pool, once per episode."""
    if agent_id == HOME:
        return LEARNER
    return random.choice(opponents)


def game_result(info: Mapping[str, Any]) -> int:
    """+1 won, -1 lost, 0 drawn, from the last info of one side."""
    return int(np.sign(info.get("goals_for", 0) - info.get("goals_against", 0)))


def record_game(*, episode: Any, metrics_logger: Any, **_: Any) -> None:
    """Log the learner's result of each finished game, for the replacement rule."""
    info = episode.get_infos(-1).get(HOME)
    if info is not None:
        # A series, not a mean: the rule looks at the last `window` games one by one.
        metrics_logger.log_value("selfplay_games", game_result(info), reduce="item_series")


# --------------------------------------------------------------------------- policy file


def _actor_layers(state: Mapping[str, Any]) -> list[tuple[Any, Any]]:
    """(weight, bias) of the Linear layers of an RLlib PPO module's actor, input first."""

    def linears(prefix: str) -> list[tuple[Any, Any]]:
        found = []
        for key in state:
            if key.startswith(prefix) and key.endswith(".weight"):
                index = int(key[len(prefix) :].split(".")[0])
                found.append((index, state[key], state[key[: -len("weight")] + "bias"]))
        return [(w, b) for _, w, b in sorted(found, key=lambda item: item[0])]

    encoder = linears("encoder.actor_encoder.net.mlp.")
    if not encoder:  # vf_share_layers=True names the one encoder so
        encoder = linears("encoder.encoder.net.mlp.")
    head = linears("pi.net.mlp.")
    if not head:
        raise ValueError("the module has no policy head (pi.net.mlp.*)")
    return encoder + head


def export_policy(
    module_state: Mapping[str, Any],
    directory: Path,
    *,
    env_id: str,
    env_kwargs: Mapping[str, Any],
    activation: str = "tanh",
    timesteps: int = 0,
    generation: int = 0,
) -> None:
    """Write the actor of an RLlib PPO module as ``policy.pt`` (tensors) and ``policy.json``.

    The last layer's outputs are the Gaussian's means followed by its log standard deviations;
    only the means are kept, since the exported policy acts deterministically.
    """
    import torch as th

    layers = _actor_layers(module_state)
    act_size = int(layers[-1][0].shape[0]) // 2
    tensors: dict[str, Any] = {}
    for i, (weight, bias) in enumerate(layers):
        weight = th.as_tensor(np.asarray(weight), dtype=th.float32)
        bias = th.as_tensor(np.asarray(bias), dtype=th.float32)
        if i == len(layers) - 1:
            weight, bias = weight[:act_size], bias[:act_size]
        tensors[f"layers.{i}.weight"] = weight.clone()
        tensors[f"layers.{i}.bias"] = bias.clone()
    info = {
        "format": POLICY_FORMAT,
        "backend": BACKEND,
        "kind": "mlp",
        "observation_size": int(layers[0][0].shape[1]),
        "action_size": act_size,
        "hidden_sizes": [int(w.shape[0]) for w, _ in layers[:-1]],
        "activation": activation,
        "output": "identity, clipped to [-1, 1]",
        "obs_mean": None,
        "obs_std": None,
        "clip_obs": None,
        "env_id": env_id,
        "env_kwargs": dict(env_kwargs),
        "timesteps": int(timesteps),
        "generation": int(generation),
        "physics": physics_record(),
    }
    directory.mkdir(parents=True, exist_ok=True)
    tmp = directory / (POLICY_FILE + ".tmp")
    th.save(tensors, tmp)
    tmp.replace(directory / POLICY_FILE)
    atomic_write_text(directory / POLICY_INFO_FILE, json.dumps(info, indent=2))


_ACTIVATIONS = {
    "tanh": np.tanh,
    "relu": lambda x: np.maximum(x, 0.0),
    "linear": lambda x: x,
}


class RllibPolicy:
    """An exported RLlib policy: raw observations in, deterministic actions in [-1, 1] out.

    Called with one observation it returns one action; with a batch (N, obs_dim), (N, act_dim).
    ``observation_size`` and ``env_id`` let :func:`~foosball_gym.evaluation.evaluate` check
    that it fits the environment.
    """

    def __init__(
        self,
        weights: list[tuple[np.ndarray, np.ndarray]],
        activation: str,
        *,
        obs_mean: np.ndarray | None = None,
        obs_std: np.ndarray | None = None,
        clip_obs: float | None = None,
        env_id: str | None = None,
        env_kwargs: Mapping[str, Any] | None = None,
        generation: int = 0,
    ) -> None:
        if activation not in _ACTIVATIONS:
            raise ValueError(
                f"unknown activation {activation!r}; allowed: {', '.join(_ACTIVATIONS)}"
            )
        self.weights = weights
        self.activation = activation
        self._act = _ACTIVATIONS[activation]
        self.obs_mean = obs_mean
        self.obs_std = obs_std
        self.clip_obs = clip_obs
        self.env_id = env_id
        self.env_kwargs = dict(env_kwargs or {})
        self.generation = generation

    @property
    def observation_size(self) -> int:
        return int(self.weights[0][0].shape[1])

    @property
    def action_size(self) -> int:
        return int(self.weights[-1][0].shape[0])

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        x = np.asarray(obs, dtype=np.float64)
        single = x.ndim == 1
        if single:
            x = x[None]
        if self.obs_mean is not None:
            # RLlib's MeanStdFilter: (x - mean) / (std + 1e-8), then clipped.
            x = (x - self.obs_mean) / (self.obs_std + 1e-8)
            if self.clip_obs:
                x = np.clip(x, -self.clip_obs, self.clip_obs)
        x = x.astype(np.float32)
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(self.weights):
            x = x @ w.T + b
            if i < last:
                x = self._act(x)
        actions = np.clip(x, -1.0, 1.0).astype(np.float32)
        return actions[0] if single else actions


def is_rllib_run(path: str | Path) -> bool:
    """Whether ``path`` is a directory holding an exported RLlib policy (a run or checkpoint)."""
    path = Path(path)
    return (path / POLICY_INFO_FILE).is_file() and (path / POLICY_FILE).is_file()


def load_rllib_policy(run_dir: str | Path) -> RllibPolicy:
    """The policy of an ``--backend rllib`` run directory (or one of its checkpoints).

    Reads ``policy.json`` and ``policy.pt`` with ``torch.load(weights_only=True)``: nothing is
    unpickled, so no trust is needed. Warns with
    :class:`~foosball_gym.training.config.PhysicsMismatchWarning` where the run's
    ``config.json`` (beside it, or up to two levels up) records other physics than the current one.

    Raises:
        ValueError: no exported policy there, or its files do not agree with each other.
    """
    import torch as th

    run_dir = Path(run_dir)
    if not is_rllib_run(run_dir):
        raise ValueError(f"{run_dir} holds no RLlib policy ({POLICY_INFO_FILE}, {POLICY_FILE})")
    try:
        info = json.loads((run_dir / POLICY_INFO_FILE).read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{run_dir / POLICY_INFO_FILE} is not valid JSON: {err}") from None
    if info.get("format") != POLICY_FORMAT or info.get("kind") != "mlp":
        raise ValueError(
            f"{run_dir / POLICY_INFO_FILE} is of an unknown format {info.get('format')!r} "
            f"(this version reads {POLICY_FORMAT})"
        )
    try:
        tensors = th.load(run_dir / POLICY_FILE, map_location="cpu", weights_only=True)
    except Exception as err:  # noqa: BLE001 - any unreadable file gets the same message
        raise ValueError(f"cannot read {run_dir / POLICY_FILE} as tensors: {err}") from None
    n_layers = len(info["hidden_sizes"]) + 1
    try:
        weights = [
            (
                tensors[f"layers.{i}.weight"].numpy().astype(np.float32),
                tensors[f"layers.{i}.bias"].numpy().astype(np.float32),
            )
            for i in range(n_layers)
        ]
    except (KeyError, AttributeError) as err:
        raise ValueError(f"{run_dir / POLICY_FILE} lacks the layer {err}") from None
    sizes = [info["observation_size"], *info["hidden_sizes"], info["action_size"]]
    for i, (w, b) in enumerate(weights):
        if w.shape != (sizes[i + 1], sizes[i]) or b.shape != (sizes[i + 1],):
            raise ValueError(
                f"{run_dir / POLICY_FILE}: layer {i} is {tuple(w.shape)}, but "
                f"{POLICY_INFO_FILE} describes {(sizes[i + 1], sizes[i])}"
            )

    def array(value: Any) -> np.ndarray | None:
        return None if value is None else np.asarray(value, dtype=np.float64)

    config = None
    # A checkpoint's run is two levels up (checkpoints/step_N/).
    for candidate in [d / CONFIG_FILE for d in (run_dir, *list(run_dir.parents)[:2])]:
        if candidate.is_file():
            config = json.loads(candidate.read_text())
            break
    if config is None and "physics" in info:
        config = {"physics": info["physics"]}
    mismatch = physics_mismatch(config, f"the model {run_dir}")
    if mismatch:
        warnings.warn(mismatch, PhysicsMismatchWarning, stacklevel=2)
    return RllibPolicy(
        weights,
        info["activation"],
        obs_mean=array(info.get("obs_mean")),
        obs_std=array(info.get("obs_std")),
        clip_obs=info.get("clip_obs"),
        env_id=info.get("env_id"),
        env_kwargs=info.get("env_kwargs") or {},
        generation=int(info.get("generation", 0)),
    )


def load_rllib_snapshot(path: str | Path, config: Mapping[str, Any]) -> RllibPolicy:
    """A self-play snapshot (``selfplay/opponent_<generation>.pt``, a module's full state) of
    the run whose ``config.json`` is ``config``, as a deterministic policy: the actor only,
    its Gaussian's means as the action, like :func:`export_policy` writes it."""
    state = _load_tensors(Path(path))
    layers = _actor_layers(state)
    act_size = int(np.asarray(layers[-1][0]).shape[0]) // 2
    weights = [
        (np.asarray(w, dtype=np.float32), np.asarray(b, dtype=np.float32)) for w, b in layers
    ]
    weights[-1] = (weights[-1][0][:act_size], weights[-1][1][:act_size])
    return RllibPolicy(
        weights,
        "tanh",  # what export_policy records for every module this backend trains
        env_id=config.get("env_id"),
        env_kwargs=config.get("env_kwargs") or {},
    )


# --------------------------------------------------------------------------- tensors on disk


def _to_tensors(value: Any) -> Any:
    """``value`` with its numpy arrays as tensors, so ``torch.load(weights_only=True)`` reads it."""
    import torch as th

    if isinstance(value, Mapping):
        return {k: _to_tensors(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_to_tensors(v) for v in value]
    if isinstance(value, np.ndarray):
        return th.from_numpy(np.ascontiguousarray(value)).clone()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, th.Tensor):
        return value.detach().cpu().clone()
    return value


def _to_arrays(value: Any) -> Any:
    import torch as th

    if isinstance(value, Mapping):
        return {k: _to_arrays(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_to_arrays(v) for v in value]
    if isinstance(value, th.Tensor):
        return value.numpy()
    return value


def _save_tensors(value: Any, path: Path) -> None:
    import torch as th

    tmp = path.with_name(path.name + ".tmp")
    th.save(_to_tensors(value), tmp)
    tmp.replace(path)


def _load_tensors(path: Path) -> Any:
    import torch as th

    return _to_arrays(th.load(path, map_location="cpu", weights_only=True))


# --------------------------------------------------------------------------- training


@dataclass
class RllibTrainResult:
    """What a call of :func:`train_rllib` did (the fields of the SB3 backend's TrainResult).

    ``signal`` is the signal (SIGINT, SIGTERM) that stopped the run before its budget, after a
    checkpoint was written; None where it ran to the end.
    """

    out: Path
    timesteps: int
    seconds: float
    reached: dict[str, float] | None
    signal: int | None = None
    generation: int = 0
    games: int = 0


def check_rllib_config(config: TrainConfig, num_workers: int) -> None:
    """Raise ValueError for what the rllib backend cannot train (after ``config.check()``)."""
    config.check()
    if config.algo != "ppo":
        raise ValueError(f"the rllib backend trains PPO only, not {config.algo!r}")
    if not config.self_play:
        raise ValueError(
            f"the rllib backend trains two-player tasks by self-play; {config.env_id} "
            "with self_play off is trained with --backend sb3"
        )
    if config.pretrain_episodes:
        raise ValueError("the rllib backend does not pretrain; leave pretrain_episodes at 0")
    if config.teacher_steps:
        raise ValueError(
            "the rllib backend has no scripted teacher; leave teacher_steps at 0, or train "
            "with --backend sb3"
        )
    if config.selfplay_scripted_share:
        raise ValueError(
            "the rllib backend plays snapshots only; leave selfplay_scripted_share at 0, or "
            "train with --backend sb3"
        )
    if config.selfplay_sampled:
        raise ValueError(
            "the rllib backend's snapshots act on their policy's mean; leave selfplay_sampled "
            "off, or train with --backend sb3"
        )
    if config.selfplay_gate:
        raise ValueError(
            "the rllib backend has no gate on its replacements; leave selfplay_gate at 0, or "
            "train with --backend sb3"
        )
    if config.video_every is not None:
        raise ValueError(
            "the rllib backend writes no clips; leave video_every out, or record the run "
            "afterwards with foosball eval RUN --video FILE"
        )
    if not isinstance(num_workers, int) or num_workers < 0:
        raise ValueError(f"num_workers must be 0 or more, got {num_workers!r}")


def _build_config(
    config: TrainConfig,
    num_workers: int,
    opponents: tuple[str, ...],
    lr_start: float,
    remaining: int,
) -> Any:
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    envs_per_runner = max(1, config.n_envs // max(num_workers, 1))
    lr: Any = lr_start
    if config.lr_schedule == "linear":
        # RLlib interpolates between (env steps, value) points of this run's own count.
        lr = [[0, lr_start], [max(remaining, 1), 0.0]]
    return (
        PPOConfig()
        .environment(
            _ENV_NAME,
            env_config={"env_id": config.env_id, "env_kwargs": dict(config.env_kwargs)},
            # The env checks its actions; RLlib's own check samples random ones.
            disable_env_checking=True,
        )
        .env_runners(
            num_env_runners=num_workers,
            num_envs_per_env_runner=envs_per_runner,
            rollout_fragment_length="auto",
            num_cpus_per_env_runner=1,
        )
        .multi_agent(
            policies={LEARNER, *opponents},
            policy_mapping_fn=functools.partial(map_agent, opponents=opponents),
            policies_to_train=[LEARNER],
        )
        .rl_module(
            model_config=DefaultModelConfig(
                fcnet_hiddens=list(config.net_arch),
                fcnet_activation="tanh",
                vf_share_layers=False,
            ),
            rl_module_spec=MultiRLModuleSpec(
                rl_module_specs={m: RLModuleSpec() for m in (LEARNER, *opponents)}
            ),
        )
        .training(
            lr=lr,
            gamma=config.gamma,
            lambda_=config.gae_lambda,
            clip_param=config.clip_range,
            num_epochs=config.n_epochs,
            minibatch_size=config.batch_size,
            train_batch_size_per_learner=config.n_steps * config.n_envs,
            # As SB3's PPO: no KL penalty, no clipping of the value loss (goals are worth
            # 1000, far past RLlib's default clip of 10), half-weighted value loss, gradient
            # norm clipped at 0.5.
            use_kl_loss=False,
            vf_clip_param=math.inf,
            vf_loss_coeff=0.5,
            entropy_coeff=0.0,
            grad_clip=0.5,
            grad_clip_by="global_norm",
        )
        .callbacks(on_episode_end=record_game)
        .debugging(seed=config.seed, log_level="ERROR")
        .reporting(metrics_num_episodes_for_smoothing=config.selfplay_window)
    )


# Ray itself retries an unreachable head for many minutes before it gives up.
CONNECT_TIMEOUT_S = 10.0


def _check_reachable(address: str) -> None:
    """Raise ConnectionError where ``HOST:PORT`` takes no connection within the timeout."""
    import socket

    if address == "auto" or address.startswith("ray://"):
        return
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"--address must be HOST:PORT or auto, got {address!r}")
    try:
        with socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S):
            pass
    except OSError as err:
        raise ConnectionError(
            f"no Ray head answers at {address} within {CONNECT_TIMEOUT_S:.0f} s ({err})"
        ) from None


def _start_ray(address: str | None, num_workers: int) -> bool:
    """Connect to (or start) Ray; True where this call started it and must shut it down."""
    import ray

    if ray.is_initialized():
        return False
    if address:
        _check_reachable(address)
        ray.init(address=address, include_dashboard=False, log_to_driver=False)
    else:
        # One CPU per env runner, on top of the driver (which runs the learner).
        ray.init(
            address="local",
            num_cpus=max(num_workers, 1),
            include_dashboard=False,
            log_to_driver=False,
        )
    return True


class _Tensorboard:
    """TensorBoard scalars where tensorboard is installed; nothing otherwise."""

    def __init__(self, directory: Path) -> None:
        try:
            from torch.utils.tensorboard import SummaryWriter
        except ImportError:
            self._writer = None
            return
        directory.mkdir(parents=True, exist_ok=True)
        self._writer = SummaryWriter(str(directory))

    def scalars(self, values: Mapping[str, float | None], step: int) -> None:
        if self._writer is None:
            return
        for key, value in values.items():
            if value is not None and np.isfinite(value):
                self._writer.add_scalar(key, float(value), step)
        self._writer.flush()

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()


def _save_config(config: TrainConfig, num_workers: int, path: Path) -> None:
    data = {
        **asdict(config),
        "normalize": False,
        "backend": BACKEND,
        "num_workers": num_workers,
        "physics": physics_record(),
    }
    atomic_write_text(path, json.dumps(data, indent=2))


def read_backend(run_dir: str | Path) -> str:
    """The backend that trained the run in ``run_dir`` ("sb3" where config.json names none)."""
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        return "sb3"
    return json.loads(path.read_text()).get("backend", "sb3")


class _SelfPlay:
    """The pool of frozen opponents and the replacement rule, on the driver."""

    def __init__(self, config: TrainConfig, save_dir: Path) -> None:
        self.rule = ReplacementRule(
            config.selfplay_rule, config.selfplay_threshold, config.selfplay_window
        )
        self.pool_size = config.selfplay_pool
        self.save_dir = save_dir
        self.history: list[dict[str, Any]] = []
        self.pool: list[int] = []  # generations

    @property
    def generation(self) -> int:
        return self.pool[-1] if self.pool else 0

    @property
    def games(self) -> int:
        return self.rule.games

    @property
    def module_ids(self) -> tuple[str, ...]:
        return tuple(opponent_id(g) for g in self.pool)

    def restore(self) -> dict[str, Any]:
        """The pool's weights by module id, from ``history.json`` and the snapshots."""
        self.history = json.loads((self.save_dir / "history.json").read_text())
        self.pool = [h["generation"] for h in self.history][-self.pool_size :]
        self.rule.games = self.history[-1]["games"]
        self.rule.opponent_elo = restored_elo(self.history, self.pool)
        return {
            opponent_id(g): _load_tensors(self.save_dir / f"{opponent_id(g)}.pt") for g in self.pool
        }

    def add(self, state: Mapping[str, Any], timesteps: int, score: float | None, elo: float) -> int:
        """Record a snapshot of the learner's ``state``; returns its generation."""
        generation = self.generation + 1 if self.pool else 0
        self.save_dir.mkdir(parents=True, exist_ok=True)
        _save_tensors(state, self.save_dir / f"{opponent_id(generation)}.pt")
        self.pool = (self.pool + [generation])[-self.pool_size :]
        self.history.append(
            history_record(generation, timesteps, self.games, self.rule, score, elo)
        )
        self.rule.opponent_elo = restored_elo(self.history, self.pool)
        atomic_write_text(self.save_dir / "history.json", json.dumps(self.history, indent=1))
        return generation

    def judge(self, games: list[int]) -> tuple[float, float] | None:
        """Count ``games``; the rule's score and the learner's rating where they earn a new
        snapshot, or None.

        The games after the one that earns it are dropped, not counted towards the next
        opponent: they were played against the pool as it was.
        """
        for result in games:
            replaced = self.rule.record(int(result))
            if replaced is not None:
                return replaced
        return None

    def rates(self) -> dict[str, float | None]:
        rates = self.rule.rates()
        return {"selfplay/generation": self.generation, **rates} if rates else {}


def _learner_state(algo: Any) -> dict[str, Any]:
    """The learner module's full state (actor and critic) as numpy arrays."""
    weights = algo.learner_group.get_weights(module_ids=[LEARNER])[LEARNER]
    return {k: np.asarray(v) for k, v in weights.items()}


def _set_modules(algo: Any, states: Mapping[str, Any]) -> None:
    """Give modules (learner, opponents) these weights, on the learner and every env runner."""
    algo.set_state({"learner_group": {"learner": {"rl_module": dict(states)}}})


def _evaluate_row(
    config: TrainConfig, policy: RllibPolicy, timesteps: int, wall: float
) -> dict[str, Any]:
    from foosball_gym.evaluation import evaluate

    res = evaluate(
        policy, config.env_id, config.env_kwargs, episodes=config.eval_episodes, seed=EVAL_SEED
    )
    return {
        "timesteps": int(timesteps),
        "wall_seconds": round(wall, 2),
        "success_rate": res.success_rate,
        "ci_low": round(res.ci_low, 4),
        "ci_high": round(res.ci_high, 4),
        "mean_reward": round(res.mean_reward, 3),
        "mean_length": res.mean_length,
        "goals_for": res.goals_for,
        "goals_against": res.goals_against,
    }


def _append_row(csv_path: Path, row: Mapping[str, Any]) -> None:
    new = not csv_path.exists()
    with csv_path.open("a", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=EVAL_FIELDS)
        if new:
            writer.writeheader()
        writer.writerow(row)


def _plot(csv_path: Path, png_path: Path, title: str) -> None:
    try:
        from foosball_gym.training.curve import plot_curve
    except ImportError:  # the plot needs the train extra; the CSV is the record
        return
    plot_curve(csv_path, png_path, title)


def _read_rows(csv_path: Path) -> list[dict[str, float]]:
    if not csv_path.exists():
        return []
    with csv_path.open() as f:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def train_rllib(
    config: TrainConfig,
    out: str | Path,
    *,
    num_workers: int = 2,
    address: str | None = None,
    resume: bool = False,
    verbose: int = 1,
) -> RllibTrainResult:
    """Train (or, with ``resume``, continue) self-play PPO on Ray RLlib in run directory ``out``.

    The configuration is the SB3 backend's: ``n_steps * n_envs`` env steps per update, spread
    over the env runners (``n_envs // num_workers`` envs each, at least one), minibatches of
    ``batch_size``, ``n_epochs`` passes, ``net_arch`` for both actor and critic (tanh).
    Checkpoints every ``checkpoint_freq`` steps, an evaluation every ``eval_freq`` steps,
    both checked after each RLlib iteration (one update).

    Args:
        config: the run's configuration (ignored with ``resume``: the run's own is read).
        out: the run directory.
        num_workers: Ray env runners sampling in parallel, one CPU each; 0 samples in this
            process.
        address: the Ray cluster: ``HOST:PORT`` of its head, ``"auto"`` (the one this machine
            belongs to), or None to start a local Ray with ``max(num_workers, 1)`` CPUs. An
            already initialised Ray is used as it is.
        resume: continue from the last checkpoint in ``out``.
        verbose: 1 prints each replacement of the opponent.

    Raises:
        ImportError: Ray RLlib is missing (the message names the extra).
        ValueError: the configuration cannot be trained here, or ``out`` holds a run already
            (without ``resume``) or another backend's run.
    """
    require_ray()
    import ray
    import torch as th
    from ray.tune.registry import register_env

    out = Path(out)
    if resume:
        if read_backend(out) != BACKEND:
            raise ValueError(f"{out} is a run of the {read_backend(out)} backend, not rllib's")
        config = TrainConfig.load(out / CONFIG_FILE)
        mismatch = physics_mismatch(json.loads((out / CONFIG_FILE).read_text()), f"the run {out}")
        if mismatch:
            warnings.warn(
                f"{mismatch} Resuming continues it on the current physics.",
                PhysicsMismatchWarning,
                stacklevel=2,
            )
    check_rllib_config(config, num_workers)
    config.normalize = False
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out} is a file, not a run directory")
    continuing = resume and has_checkpoint(out)
    if not resume and has_checkpoint(out):
        raise ValueError(
            f"{out} already holds a run; use --resume to continue it or choose another --out"
        )
    out.mkdir(parents=True, exist_ok=True)
    th.set_num_threads(config.torch_threads)

    selfplay = _SelfPlay(config, out / "selfplay")
    done_steps, wall_offset = 0, 0.0
    pointer: dict[str, Any] | None = None
    restored: dict[str, Any] = {}
    if continuing:
        pointer = json.loads((out / CHECKPOINT_DIR / LATEST_FILE).read_text())
        done_steps = int(pointer["timesteps"])
        restored = selfplay.restore()
        rows = _read_rows(out / "eval.csv")
        wall_offset = rows[-1]["wall_seconds"] if rows else 0.0
    else:
        for name in ("eval.csv", "eval.png", "best", "selfplay", CHECKPOINT_DIR):
            stale = out / name
            if stale.is_dir():
                shutil.rmtree(stale)
            elif stale.exists():
                stale.unlink()
    remaining = max(config.timesteps - done_steps, 0)
    lr_start = config.learning_rate
    if config.lr_schedule == "linear":
        lr_start *= remaining / config.timesteps

    started = _start_ray(address, num_workers)
    algo = None
    board = _Tensorboard(out / "tb" / BACKEND)
    try:
        register_env(_ENV_NAME, make_game)
        opponents = selfplay.module_ids if continuing else (opponent_id(0),)
        algo = _build_config(config, num_workers, opponents, lr_start, remaining).build_algo()
        if continuing:
            step_dir = out / CHECKPOINT_DIR / pointer["checkpoint"]
            _set_modules(algo, {LEARNER: _load_tensors(step_dir / "learner.pt"), **restored})
            optimizer = step_dir / "optimizer.pt"
            if optimizer.exists():
                algo.learner_group.set_state({"learner": _load_tensors(optimizer)})
        else:
            state = _learner_state(algo)
            if config.log_std_init:
                head = _actor_layers(state)[-1][1]  # the bias: means, then log std
                head[head.shape[0] // 2 :] = config.log_std_init
                _set_modules(algo, {LEARNER: state})
            selfplay.add(state, 0, None, 0.0)
            _set_modules(algo, {opponent_id(0): state})
            _save_config(config, num_workers, out / CONFIG_FILE)

        stop = SignalStop()
        steps = done_steps
        start = time.perf_counter()
        next_eval = (steps // config.eval_freq + 1) * config.eval_freq
        next_checkpoint = (steps // config.checkpoint_freq + 1) * config.checkpoint_freq
        best_file = out / "best" / "best.json"
        best = json.loads(best_file.read_text())["success_rate"] if best_file.exists() else -1.0
        reached = None
        last_eval = done_steps if continuing else -1

        def export(directory: Path, state: Mapping[str, Any]) -> None:
            export_policy(
                state,
                directory,
                env_id=config.env_id,
                env_kwargs=config.env_kwargs,
                timesteps=steps,
                generation=selfplay.generation,
            )

        def checkpoint() -> None:
            name = f"step_{steps:010d}"
            step_dir = out / CHECKPOINT_DIR / name
            step_dir.mkdir(parents=True, exist_ok=True)
            state = _learner_state(algo)
            _save_tensors(state, step_dir / "learner.pt")
            _save_tensors(
                algo.learner_group.get_state(components="learner/optimizer")["learner"],
                step_dir / "optimizer.pt",
            )
            export(step_dir, state)
            atomic_write_text(
                out / CHECKPOINT_DIR / LATEST_FILE,
                json.dumps({"checkpoint": name, "timesteps": steps, "backend": BACKEND}),
            )

        def run_eval() -> dict[str, Any]:
            nonlocal best, last_eval
            export(out / "best" / "candidate", _learner_state(algo))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", PhysicsMismatchWarning)
                policy = load_rllib_policy(out / "best" / "candidate")
            wall = wall_offset + time.perf_counter() - start
            row = _evaluate_row(config, policy, steps, wall)
            _append_row(out / "eval.csv", row)
            _plot(out / "eval.csv", out / "eval.png", config.env_id)
            board.scalars(
                {"eval/success_rate": row["success_rate"], "eval/mean_reward": row["mean_reward"]},
                steps,
            )
            candidate = out / "best" / "candidate"
            if row["success_rate"] >= best:
                best = row["success_rate"]
                for name in (POLICY_FILE, POLICY_INFO_FILE):
                    (candidate / name).replace(out / "best" / name)
                atomic_write_text(best_file, json.dumps(row))
            shutil.rmtree(candidate, ignore_errors=True)
            last_eval = steps
            return row

        with stop.installed():
            while steps < config.timesteps and stop.signum is None:
                result = algo.train()
                runners = result.get("env_runners", {})
                steps = done_steps + int(result.get("num_env_steps_sampled_lifetime", 0))
                games = runners.get("selfplay_games")
                games = [] if games is None or np.isscalar(games) else list(games)
                replaced = selfplay.judge(games)
                if replaced is not None:
                    score, elo = replaced
                    state = _learner_state(algo)
                    generation = selfplay.add(state, steps, score, elo)
                    new_id = opponent_id(generation)
                    _add_opponent(algo, new_id, selfplay.module_ids)
                    _set_modules(algo, {new_id: state})
                    if verbose:
                        print(
                            f"self-play: opponent replaced by generation {generation} at "
                            f"{steps} steps ({config.selfplay_rule} {score:+.2f}, "
                            f"Elo {elo:+.0f})"
                        )
                learner_stats = result.get("learners", {}).get(LEARNER, {})
                board.scalars(
                    {
                        "rollout/ep_len_mean": runners.get("episode_len_mean"),
                        "train/policy_loss": learner_stats.get("policy_loss"),
                        "train/value_loss": learner_stats.get("vf_loss"),
                        "train/entropy": learner_stats.get("entropy"),
                        **selfplay.rates(),
                    },
                    steps,
                )
                if steps >= next_checkpoint:
                    next_checkpoint = (steps // config.checkpoint_freq + 1) * config.checkpoint_freq
                    checkpoint()
                if steps >= next_eval:
                    next_eval = (steps // config.eval_freq + 1) * config.eval_freq
                    row = run_eval()
                    target = config.target_success
                    if target is not None and row["success_rate"] >= target:
                        reached = row
                        break
        seconds = time.perf_counter() - start
        checkpoint()
        if stop.signum is not None:
            return RllibTrainResult(
                out, steps, seconds, None, stop.signum, selfplay.generation, selfplay.games
            )
        if reached is None and last_eval < steps:
            run_eval()  # a last point for the curve at the final timestep
        export(out, _learner_state(algo))
    finally:
        board.close()
        if algo is not None:
            algo.stop()
        if started:
            ray.shutdown()
    return RllibTrainResult(out, steps, seconds, reached, None, selfplay.generation, selfplay.games)


def _add_opponent(algo: Any, module_id: str, pool: tuple[str, ...]) -> None:
    """Add ``module_id`` to the learner and every env runner, draw away from ``pool`` from now
    on, and remove the modules that left the pool."""
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    mapping = functools.partial(map_agent, opponents=pool)
    algo.add_module(
        module_id=module_id,
        module_spec=RLModuleSpec.from_module(algo.get_module(LEARNER)),
        new_agent_to_module_mapping_fn=mapping,
        new_should_module_be_updated=[LEARNER],
    )
    present = set(algo.config.policies) - {LEARNER}
    for old in sorted(present - set(pool)):
        algo.remove_module(
            module_id=old,
            new_agent_to_module_mapping_fn=mapping,
            new_should_module_be_updated=[LEARNER],
        )
