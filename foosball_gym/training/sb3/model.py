"""A run's Stable-Baselines3 model: built from its configuration, or from its last checkpoint
without unpickling anything."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from stable_baselines3 import PPO, SAC
from stable_baselines3.common.vec_env import VecNormalize

from foosball_gym.training.config import TrainConfig
from foosball_gym.training.run_dir.files import (
    CHECKPOINT_DIR,
    CONFIG_FILE,
    LEGACY_NORM_FILE,
    MODEL_FILE,
    NORM_FILE,
    TB_DIR,
    read_latest,
)
from foosball_gym.training.run_dir.storage import (
    NormStats,
    read_model_zip,
    read_norm,
    statistics_beside,
    zip_statistics,
)
from foosball_gym.training.sb3.jax_ppo import JaxPPO
from foosball_gym.training.sb3.worker_rollouts import WorkerRollouts


def build_model(config: TrainConfig, venv: Any, tb_dir: Path | None) -> Any:
    policy_kwargs: dict[str, Any] = {"net_arch": list(config.net_arch)}
    if config.adam_eps is not None or config.fused_adam:
        # Left out, SB3 gives Adam its own epsilon (1e-5 for PPO); given, it takes these as
        # they are, PyTorch's 1e-8 where no epsilon is named.
        optimizer: dict[str, Any] = {"fused": True} if config.fused_adam else {}
        if config.adam_eps is not None:
            optimizer["eps"] = config.adam_eps
        policy_kwargs["optimizer_kwargs"] = optimizer
    lr = config.learning_rate
    common: dict[str, Any] = {
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
    if config.use_sde:
        common.update(use_sde=True, sde_sample_freq=config.sde_sample_freq)
    if config.algo == "ppo":
        policy_kwargs["log_std_init"] = config.log_std_init
        return _ppo_class(config)(
            "MlpPolicy",
            venv,
            n_steps=config.n_steps,
            batch_size=config.batch_size,
            n_epochs=config.n_epochs,
            gae_lambda=config.gae_lambda,
            clip_range=config.clip_range,
            target_kl=config.target_kl,
            ent_coef=config.ent_coef,
            policy_kwargs=policy_kwargs,
            **common,
        )
    if config.algo == "crossq":
        from sb3_contrib import CrossQ

        return CrossQ(
            "MlpPolicy", venv, batch_size=config.batch_size, policy_kwargs=policy_kwargs, **common
        )
    return SAC(
        "MlpPolicy", venv, batch_size=config.batch_size, policy_kwargs=policy_kwargs, **common
    )


def _ppo_class(config: TrainConfig) -> type[PPO]:
    if config.worker_rollouts:
        return RolloutJaxPPO if config.learner == "jax" else RolloutPPO
    return JaxPPO if config.learner == "jax" else PPO


class RolloutPPO(WorkerRollouts, PPO):
    """SB3's PPO, its rollouts played where the environments are."""


class RolloutJaxPPO(WorkerRollouts, JaxPPO):
    """PPO with JAX's update, its rollouts played where the environments are."""


def load_checkpoint(config: TrainConfig, out: Path, venv: Any) -> tuple[Any, int]:
    """The model of the run's last checkpoint (or its final model), and its timesteps.

    The model is built from the run's configuration and given the checkpoint's weights and
    optimiser state, read as tensors, so nothing is unpickled; ``venv``'s normalisation is
    given the statistics the checkpoint holds (a checkpoint from before they went into the
    zip: those beside it). A checkpoint of a run from before plain files (with
    ``vecnormalize.pkl``) is refused, with how to migrate it; so is one whose statistics are
    missing, damaged or do not fit the run's configuration.
    """
    pointer = read_latest(out)
    if pointer is not None:
        zip_path = out / CHECKPOINT_DIR / str(pointer.get("model", ""))
        named = pointer.get("vecnormalize")
        beside = [out / CHECKPOINT_DIR / named] if named else []
    else:
        zip_path = out / MODEL_FILE
        beside = [out / NORM_FILE, out / LEGACY_NORM_FILE]
    if not zip_path.is_file():
        raise ValueError(f"cannot resume {out}: its checkpoint {zip_path} is missing")
    try:
        stats = _statistics(zip_path, beside, out)
        data, params, variables = read_model_zip(zip_path)
    except ValueError as err:
        raise ValueError(f"cannot resume from {zip_path}: {err}") from None
    normalised = isinstance(venv, VecNormalize)
    if normalised != (stats is not None):
        raise ValueError(
            f"cannot resume from {zip_path}: the run's {CONFIG_FILE} "
            + (
                "normalises observations, but the checkpoint holds no statistics"
                if normalised
                else "does not normalise observations, but the checkpoint holds statistics"
            )
        )
    if stats is not None:
        try:
            stats.apply(venv)
        except ValueError as err:
            raise ValueError(f"cannot resume from {zip_path}: {err}") from None
    model = build_model(config, venv, out / TB_DIR)
    try:
        model.set_parameters(params, exact_match=True, device="cpu")
    except (ValueError, RuntimeError) as err:
        raise ValueError(f"{zip_path} does not fit the run's configuration: {err}") from None
    for name, value in (variables or {}).items():
        if value is not None:
            getattr(model, name).data = value.data
    steps = int(pointer["timesteps"]) if pointer else int(data.get("num_timesteps", 0))
    model.num_timesteps = steps
    model._n_updates = int(data.get("_n_updates", 0))
    return model, steps


def _statistics(zip_path: Path, beside: list[Path], out: Path) -> NormStats | None:
    """The statistics of the model in ``zip_path``: its own, or for a zip from before they
    went into it, the first file of ``beside`` (or the one its name gives) that exists."""
    recorded, stats = zip_statistics(zip_path)
    if recorded:
        return stats
    found = [p for p in [*beside, *statistics_beside(zip_path)] if p.exists()]
    return read_norm(found[0], out, trust=False) if found else None
