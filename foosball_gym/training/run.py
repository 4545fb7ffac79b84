"""A training run: configuration, environments, model, callbacks, checkpoints, resume.

A run directory holds::

    config.json            the resolved configuration (what --resume reads back), and under
                           "physics" the physics the run was trained on (see physics_record)
    model.zip              the final model (SB3)
    vecnormalize.pkl       observation-normalisation statistics, if used
    checkpoints/           periodic checkpoints, written atomically; latest.json names the last
    eval.csv, eval.png     the evaluation curve: success rate and reward against timesteps
    best/                  the model of the best evaluation so far
    tb/                    TensorBoard logs
    selfplay/              opponent snapshots and history.json (self-play runs)
"""

from __future__ import annotations

import csv
import json
import time
import warnings
from dataclasses import asdict, dataclass, field, fields
from importlib import metadata
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

import foosball_gym  # noqa: F401  (registers the ids)
from foosball_gym.table import PHYSICS_REVISION
from foosball_gym.training.evaluation import evaluate
from foosball_gym.training.pretrain import clone, collect
from foosball_gym.training.selfplay import OpponentActionWrapper, SelfPlayCallback, SelfPlayVecEnv
from foosball_gym.training.snapshot import PolicySnapshot

ALGOS = {"ppo": PPO, "sac": SAC}
VEC_ENVS = {"dummy": DummyVecEnv, "subproc": SubprocVecEnv}
LR_SCHEDULES = ("constant", "linear")
CONFIG_FILE = "config.json"
MODEL_FILE = "model.zip"
NORM_FILE = "vecnormalize.pkl"
BEST_DIR = "best"
# Runs from before config.json recorded its physics were all trained on the first revision.
LEGACY_PHYSICS_REVISION = 1


class PhysicsMismatchWarning(UserWarning):
    """A model or run was trained on another revision of the simulated physics than this one."""


def physics_record() -> dict[str, Any]:
    """The physics this installation simulates, as a run's ``config.json`` records it.

    ``revision`` is :data:`foosball_gym.table.PHYSICS_REVISION`, the one that decides whether
    a model meets the physics it was trained on; the package and PyBullet versions are there
    to trace a difference the revision does not explain.
    """
    try:
        pybullet = metadata.version("pybullet")
    except metadata.PackageNotFoundError:
        pybullet = None
    return {
        "revision": PHYSICS_REVISION,
        "package_version": foosball_gym.__version__,
        "pybullet": pybullet,
    }


def recorded_physics_revision(config: dict[str, Any] | None) -> int:
    """The physics revision a run's ``config.json`` (as a dict, or None) says it trained on."""
    physics = (config or {}).get("physics")
    if isinstance(physics, dict) and physics.get("revision") is not None:
        return int(physics["revision"])
    return LEGACY_PHYSICS_REVISION


def physics_mismatch(config: dict[str, Any] | None, name: str) -> str | None:
    """Why ``name``, trained as ``config`` records, may not behave as it did in training; None
    where it was trained on the current physics."""
    recorded = recorded_physics_revision(config)
    if recorded == PHYSICS_REVISION:
        return None
    if "physics" in (config or {}):
        trained = f"{name} was trained on physics revision {recorded}"
    else:
        trained = (
            f"{name} records no physics revision, so it was trained on revision {recorded} "
            "(the record was introduced after that revision)"
        )
    return (
        f"{trained}, but foosball_gym {foosball_gym.__version__} simulates physics revision "
        f"{PHYSICS_REVISION}: its results may differ from those it reached in training. "
        "Retraining it on the current physics is advised."
    )


@dataclass
class TrainConfig:
    """Everything a run needs; the defaults are the paper's PPO settings sized for a CPU.

    The paper used 8192 GPU environments with a horizon of 16; here 8 environments in one
    process with a horizon of 128 give updates of 1024 samples, in minibatches of 256.
    """

    env_id: str
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    algo: str = "ppo"
    timesteps: int = 500_000
    n_envs: int = 8
    seed: int = 0
    self_play: bool | None = None  # None: on for two-player environments
    normalize: bool = True  # observations, by running mean and variance
    normalize_reward: bool = False  # scale rewards by the running spread of returns
    vec_env: str = "dummy"
    net_arch: tuple[int, ...] = (256, 128, 64)
    learning_rate: float = 1e-3
    gamma: float = 0.99
    n_steps: int = 128
    batch_size: int = 256
    n_epochs: int = 8
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    log_std_init: float = 0.0  # initial log std of PPO's Gaussian actions (SB3's default)
    lr_schedule: str = "constant"  # or "linear": decay to 0 over the run
    target_kl: float | None = None  # stop an update's epochs once the policy moved this far
    # Behaviour-clone the scripted baseline from this many episodes before learning (0: off).
    pretrain_episodes: int = 0
    selfplay_window: int = 100
    selfplay_threshold: float = 0.2
    selfplay_pool: int = 1
    eval_freq: int = 10_000
    eval_episodes: int = 50
    checkpoint_freq: int = 50_000
    target_success: float | None = None  # stop once an evaluation reaches this success rate
    torch_threads: int = 1

    def check(self) -> None:
        """Raise ValueError with what is allowed for anything out of range."""
        if self.env_id not in gym.registry:
            known = ", ".join(foosball_gym.ENV_IDS)
            raise ValueError(f"unknown environment {self.env_id!r}; registered: {known}")
        if self.algo not in ALGOS:
            raise ValueError(f"unknown algorithm {self.algo!r}; allowed: {', '.join(ALGOS)}")
        if self.vec_env not in VEC_ENVS:
            raise ValueError(f"unknown vec_env {self.vec_env!r}; allowed: {', '.join(VEC_ENVS)}")
        for name in (
            "timesteps",
            "n_envs",
            "n_steps",
            "batch_size",
            "n_epochs",
            "eval_freq",
            "eval_episodes",
            "checkpoint_freq",
            "selfplay_window",
            "selfplay_pool",
            "torch_threads",
        ):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if self.lr_schedule not in LR_SCHEDULES:
            raise ValueError(
                f"unknown lr_schedule {self.lr_schedule!r}; allowed: {', '.join(LR_SCHEDULES)}"
            )
        if self.target_kl is not None and not self.target_kl > 0:
            raise ValueError(f"target_kl must be positive, got {self.target_kl}")
        if self.target_success is not None and not 0 < self.target_success <= 1:
            raise ValueError(f"target_success must lie in (0, 1], got {self.target_success}")
        env = gym.make(self.env_id, **self.env_kwargs)  # raises on a bad env option
        two_player = bool(env.unwrapped.layout.opponent)
        env.close()
        if self.self_play and not two_player:
            raise ValueError(f"{self.env_id} has no opponent; self-play needs a two-player task")
        if self.self_play is None:
            self.self_play = two_player

    def save(self, path: Path) -> None:
        """Write the configuration with the record of the physics it is about to train on.

        The record is not a field: it describes the physics of this installation, not a choice,
        so a configuration loaded from an older run and saved for a new one gets the current
        record. :meth:`load` ignores it.
        """
        data = {**asdict(self), "physics": physics_record()}
        _atomic_write_text(path, json.dumps(data, indent=2))

    @classmethod
    def load(cls, path: Path) -> TrainConfig:
        data = json.loads(Path(path).read_text())
        names = {f.name for f in fields(cls)}
        config = cls(**{k: v for k, v in data.items() if k in names})
        config.net_arch = tuple(config.net_arch)
        return config


def _atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)


def make_env(config: TrainConfig, seed_offset: int = 0) -> Any:
    """The vectorised training envs (with self-play and normalisation wrappers as configured)."""
    wrapper = OpponentActionWrapper if config.self_play else None
    venv = make_vec_env(
        config.env_id,
        n_envs=config.n_envs,
        seed=config.seed + seed_offset,
        env_kwargs=config.env_kwargs,
        wrapper_class=wrapper,
        vec_env_cls=VEC_ENVS[config.vec_env],
    )
    if config.self_play:
        # The first opponent is replaced by a snapshot of the learner as training starts.
        n = venv.action_space.shape[0] // 2
        venv = SelfPlayVecEnv(venv, lambda obs: np.zeros((len(obs), n), np.float32), config.seed)
    if config.normalize or config.normalize_reward:
        venv = VecNormalize(
            venv, norm_obs=config.normalize, norm_reward=config.normalize_reward, gamma=config.gamma
        )
    return venv


def build_model(config: TrainConfig, venv: Any, tb_dir: Path | None) -> Any:
    policy_kwargs = {"net_arch": list(config.net_arch)}
    lr = config.learning_rate
    common = {
        # SB3 calls a schedule with the progress remaining, from 1 down to 0.
        "learning_rate": (lambda remaining: lr * remaining)
        if config.lr_schedule == "linear"
        else lr,
        "gamma": config.gamma,
        "seed": config.seed,
        "device": "cpu",
        "verbose": 0,
        "tensorboard_log": None if tb_dir is None else str(tb_dir),
    }
    if config.algo == "ppo":
        policy_kwargs["log_std_init"] = config.log_std_init
        return PPO(
            "MlpPolicy",
            venv,
            n_steps=config.n_steps,
            batch_size=config.batch_size,
            n_epochs=config.n_epochs,
            gae_lambda=config.gae_lambda,
            clip_range=config.clip_range,
            target_kl=config.target_kl,
            policy_kwargs=policy_kwargs,
            **common,
        )
    return SAC(
        "MlpPolicy", venv, batch_size=config.batch_size, policy_kwargs=policy_kwargs, **common
    )


class EvalCurveCallback(BaseCallback):
    """Every ``eval_freq`` steps: evaluate on seeded episodes, append to eval.csv, plot, and
    keep the best model so far in ``best/`` (PPO's success rate can fall back after a peak)."""

    FIELDS = (
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

    def __init__(self, config: TrainConfig, out: Path, wall_offset: float = 0.0) -> None:
        super().__init__()
        self.config = config
        self.csv = out / "eval.csv"
        self.png = out / "eval.png"
        self.best_dir = out / BEST_DIR
        best_file = self.best_dir / "best.json"
        self.best = (
            json.loads(best_file.read_text())["success_rate"] if best_file.exists() else -1.0
        )
        self.wall_offset = wall_offset
        self._start = time.perf_counter()
        self._next = 0
        self.reached: dict[str, float] | None = None

    def _on_training_start(self) -> None:
        self._start = time.perf_counter()
        self._next = (self.num_timesteps // self.config.eval_freq + 1) * self.config.eval_freq

    def _on_step(self) -> bool:
        if self.num_timesteps < self._next:
            return True
        self._next += self.config.eval_freq
        return self.run_eval()

    def run_eval(self) -> bool:
        policy = PolicySnapshot.of_model(self.model)
        res = evaluate(
            policy,
            self.config.env_id,
            self.config.env_kwargs,
            episodes=self.config.eval_episodes,
            seed=1_000_000,
        )
        row = {
            "timesteps": self.num_timesteps,
            "wall_seconds": round(self.wall_offset + time.perf_counter() - self._start, 2),
            "success_rate": res.success_rate,
            "ci_low": round(res.ci_low, 4),
            "ci_high": round(res.ci_high, 4),
            "mean_reward": round(res.mean_reward, 3),
            "mean_length": res.mean_length,
            "goals_for": res.goals_for,
            "goals_against": res.goals_against,
        }
        new = not self.csv.exists()
        with self.csv.open("a", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=self.FIELDS)
            if new:
                writer.writeheader()
            writer.writerow(row)
        self.logger.record("eval/success_rate", res.success_rate)
        self.logger.record("eval/mean_reward", res.mean_reward)
        plot_curve(self.csv, self.png, self.config.env_id)
        if res.success_rate >= self.best:
            self.best = res.success_rate
            self.best_dir.mkdir(exist_ok=True)
            save_model(self.model, self.best_dir / MODEL_FILE, self.best_dir / NORM_FILE)
            _atomic_write_text(self.best_dir / "best.json", json.dumps(row))
        target = self.config.target_success
        if target is not None and res.success_rate >= target:
            self.reached = row
            return False
        return True


def read_curve(csv_path: Path) -> list[dict[str, float]]:
    with Path(csv_path).open() as f:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def plot_curve(csv_path: Path, png_path: Path, title: str) -> None:
    """Success rate (with its 95 % interval) and mean reward against timesteps, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = read_curve(csv_path)
    t = [r["timesteps"] for r in rows]
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(6, 5), sharex=True)
    ax1.plot(t, [100 * r["success_rate"] for r in rows], marker="o", ms=3)
    ax1.fill_between(
        t, [100 * r["ci_low"] for r in rows], [100 * r["ci_high"] for r in rows], alpha=0.2
    )
    ax1.set_ylabel("success rate (%)")
    ax1.set_ylim(-2, 102)
    ax1.grid(alpha=0.3)
    ax1.set_title(title)
    ax2.plot(t, [r["mean_reward"] for r in rows], color="tab:orange", marker="o", ms=3)
    ax2.set_ylabel("mean episode reward")
    ax2.set_xlabel("timesteps")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    tmp = png_path.with_name(png_path.name + ".tmp.png")
    fig.savefig(tmp, dpi=100)
    plt.close(fig)
    tmp.replace(png_path)


class CheckpointCallback(BaseCallback):
    """Every ``every`` steps write model, normalisation and a pointer to them, atomically."""

    def __init__(self, out: Path, every: int) -> None:
        super().__init__()
        self.dir = out / "checkpoints"
        self.every = every
        self._next = 0

    def _on_training_start(self) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        self._next = (self.num_timesteps // self.every + 1) * self.every

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            self._next += self.every
            self.write()
        return True

    def write(self) -> None:
        name = f"model_{self.num_timesteps:010d}"
        save_model(self.model, self.dir / f"{name}.zip", self.dir / f"{name}_{NORM_FILE}")
        pointer = {"model": f"{name}.zip", "timesteps": int(self.num_timesteps)}
        if self.model.get_vec_normalize_env() is not None:
            pointer["vecnormalize"] = f"{name}_{NORM_FILE}"
        _atomic_write_text(self.dir / "latest.json", json.dumps(pointer))


def save_model(model: Any, path: Path, norm_path: Path) -> None:
    """Save the model (and its VecNormalize statistics) through a temporary file each."""
    tmp = path.with_name(path.stem + ".tmp.zip")
    model.save(tmp)
    tmp.replace(path)
    norm = model.get_vec_normalize_env()
    if norm is not None:
        tmp_norm = norm_path.with_name(norm_path.name + ".tmp")
        norm.save(tmp_norm)
        tmp_norm.replace(norm_path)


@dataclass
class TrainResult:
    out: Path
    timesteps: int
    seconds: float
    reached: dict[str, float] | None


def train(
    config: TrainConfig,
    out: str | Path,
    progress_bar: bool = False,
    resume: bool = False,
    callbacks: list[BaseCallback] | None = None,
) -> TrainResult:
    """Train (or, with ``resume``, continue) the run in directory ``out``.

    Args:
        config: the run's configuration (ignored with ``resume``: the run's own is read).
        out: the run directory.
        progress_bar: show SB3's progress bar.
        resume: continue from the last checkpoint in ``out``.
        callbacks: extra SB3 callbacks, run after the run's own.
    """
    out = Path(out)
    th.set_num_threads(config.torch_threads)
    if resume:
        config = TrainConfig.load(out / CONFIG_FILE)
        mismatch = physics_mismatch(json.loads((out / CONFIG_FILE).read_text()), f"the run {out}")
        if mismatch:
            # config.json keeps the old revision, so the resumed model goes on warning as well.
            warnings.warn(
                f"{mismatch} Resuming continues it on revision {PHYSICS_REVISION}.",
                PhysicsMismatchWarning,
                stacklevel=2,
            )
    config.check()
    out.mkdir(parents=True, exist_ok=True)
    if not resume:
        if (out / CONFIG_FILE).exists():
            raise ValueError(
                f"{out} already holds a run; use --resume to continue it or choose another --out"
            )
        config.save(out / CONFIG_FILE)

    venv = make_env(config)
    done_steps, wall_offset = 0, 0.0
    if resume:
        model, done_steps = _load_checkpoint(config, out, venv)
        if (out / "eval.csv").exists():
            rows = read_curve(out / "eval.csv")
            wall_offset = rows[-1]["wall_seconds"] if rows else 0.0
    else:
        model = build_model(config, venv, out / "tb")
        if config.pretrain_episodes:
            demos = collect(
                config.env_id,
                config.env_kwargs,
                config.pretrain_episodes,
                config.gamma,
                seed=config.seed,
            )
            fit = clone(model, demos, seed=config.seed)
            record = {
                "episodes": config.pretrain_episodes,
                "samples": len(demos.actions),
                "scripted_success_rate": demos.success_rate,
                **fit,
            }
            _atomic_write_text(out / "pretrain.json", json.dumps(record, indent=2))

    if config.pretrain_episodes and isinstance(venv, VecNormalize):
        # The clone was fitted to observations scaled by the demonstrations' statistics; left
        # to follow PPO's rollouts they drift, and the unchanged network then plays worse
        # (Score from rest: a clone at 86 % fell to 6-30 % with the learning rate at 1e-12).
        venv.training = False

    own: list[BaseCallback] = [CheckpointCallback(out, config.checkpoint_freq)]
    if config.self_play:
        own.append(
            SelfPlayCallback(
                window=config.selfplay_window,
                threshold=config.selfplay_threshold,
                pool_size=config.selfplay_pool,
                save_dir=out / "selfplay",
                verbose=1,
            )
        )
    curve = EvalCurveCallback(config, out, wall_offset)
    own.append(curve)

    start = time.perf_counter()
    remaining = max(config.timesteps - done_steps, 0)
    if remaining:
        model.learn(
            remaining,
            callback=CallbackList(own + list(callbacks or [])),
            progress_bar=progress_bar,
            reset_num_timesteps=not resume,
            tb_log_name="run",
        )
    rows = read_curve(out / "eval.csv") if (out / "eval.csv").exists() else []
    if curve.reached is None and (not rows or rows[-1]["timesteps"] < model.num_timesteps):
        curve.init_callback(model)  # a last point for the curve at the final timestep
        curve.run_eval()
    save_model(model, out / MODEL_FILE, out / NORM_FILE)
    venv.close()
    return TrainResult(out, int(model.num_timesteps), time.perf_counter() - start, curve.reached)


def _load_checkpoint(config: TrainConfig, out: Path, venv: Any) -> tuple[Any, int]:
    pointer_file = out / "checkpoints" / "latest.json"
    if not pointer_file.exists():
        raise ValueError(f"{out} has no checkpoint to resume from (no checkpoints/latest.json)")
    pointer = json.loads(pointer_file.read_text())
    if "vecnormalize" in pointer and isinstance(venv, VecNormalize):
        saved = VecNormalize.load(str(out / "checkpoints" / pointer["vecnormalize"]), venv.venv)
        venv.obs_rms, venv.ret_rms = saved.obs_rms, saved.ret_rms
    model = ALGOS[config.algo].load(
        out / "checkpoints" / pointer["model"],
        env=venv,
        device="cpu",
        tensorboard_log=str(out / "tb"),
    )
    return model, int(pointer["timesteps"])
