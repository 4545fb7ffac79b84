"""The RLlib backend's configuration: what it refuses to train, and the PPO configuration
RLlib builds its algorithm from."""

from __future__ import annotations

import functools
import math
from typing import Any

from foosball_gym.policy_io.task import residual_scale
from foosball_gym.training.config import TrainConfig
from foosball_gym.training.rllib.env_runner import ENV_NAME, LEARNER, map_agent, record_game


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
    if residual_scale(config.env_kwargs.get("residual")):
        raise ValueError(
            "the rllib backend's snapshots would play their bare corrections as the opponent; "
            "train a residual policy (the environment option residual) with --backend sb3"
        )
    if config.env_kwargs.get("slide_around_ball"):
        raise ValueError(
            "the rllib backend's snapshots would slide around the ball as the opponent, "
            "where its side slides over the rods' travel; train self-play with "
            "slide_around_ball with --backend sb3"
        )
    if config.use_sde:
        raise ValueError(
            "the rllib backend explores with a Gaussian of its own; leave use_sde off, or train "
            "with --backend sb3"
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
    if config.rods_held_share:
        raise ValueError(
            "the rllib backend drives every rod in every game; leave rods_held_share at 0, or "
            "train with --backend sb3"
        )
    if config.video_every is not None:
        raise ValueError(
            "the rllib backend writes no clips; leave video_every out, or record the run "
            "afterwards with foosball eval RUN --video FILE"
        )
    if not isinstance(num_workers, int) or num_workers < 0:
        raise ValueError(f"num_workers must be 0 or more, got {num_workers!r}")


def build_config(
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
            ENV_NAME,
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
            entropy_coeff=config.ent_coef,
            grad_clip=0.5,
            grad_clip_by="global_norm",
        )
        .callbacks(on_episode_end=record_game)
        .debugging(seed=config.seed, log_level="ERROR")
        .reporting(metrics_num_episodes_for_smoothing=config.selfplay_window)
    )
