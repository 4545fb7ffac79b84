"""A training run's configuration, the same for both backends.

Needs neither PyTorch nor Stable-Baselines3: ``foosball train`` builds its options (their
defaults and help) from :class:`TrainConfig`'s fields, and a run's ``config.json`` is read,
without them.
"""

from __future__ import annotations

import importlib.util
import json
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym

from foosball_gym.registration import ENV_IDS, check_env_id, check_env_options
from foosball_gym.training.config_kinds import KINDS_SPELLED, of_kind
from foosball_gym.training.curriculum import check_curriculum
from foosball_gym.training.held_rods import check_rods_held_share
from foosball_gym.training.run_dir.files import atomic_write_text, read_json
from foosball_gym.training.run_dir.physics import physics_record
from foosball_gym.training.selfplay.ladder import check_ladder_steps, check_levels
from foosball_gym.training.selfplay.rule import SELFPLAY_RULES, check_rule, default_threshold

if TYPE_CHECKING:
    from foosball_gym.envs.base import FoosballEnv

# crossq: sb3-contrib's CrossQ, SAC without target networks and with batch renormalisation.
ALGORITHMS = ("ppo", "sac", "crossq")
VEC_ENV_KINDS = ("dummy", "subproc", "batched")
LR_SCHEDULES = ("constant", "linear")
# Where PPO's update runs: SB3's PyTorch, or the same update compiled by JAX (sb3/jax_ppo.py).
LEARNERS = ("torch", "jax")
# The defaults before they became the from-scratch recipe: a run's config.json written before
# one of these fields existed trained with this value, and resumes with it.
LEGACY_DEFAULTS: dict[str, Any] = {
    "n_envs": 8,
    "normalize_reward": False,
    "net_arch": (256, 128, 64),
    "learning_rate": 1e-3,
    "n_epochs": 8,
    "log_std_init": 0.0,
    "adam_eps": None,
    "fused_adam": False,
    "lr_schedule": "constant",
    "eval_freq": 10_000,
    "selfplay_stall_games": 0,
    "learner": "torch",
    "vec_env": "dummy",
    "worker_rollouts": False,
}


def _field(default: Any, doc: str) -> Any:
    """A field with the one line that describes it (``foosball train --help`` shows it)."""
    return field(default=default, metadata={"help": doc})


@dataclass
class TrainConfig:
    """Everything a run needs; the defaults are PPO as it learns Block from scratch on a CPU.

    16 environments, split over one process per core, with a horizon of 128 give updates of
    2048 samples, passed over 20 times in minibatches of 256 by two layers of 64 units, the
    update compiled by JAX; :data:`LEGACY_DEFAULTS`
    holds the settings the defaults were before (the paper's network, sized for a CPU), which
    the shipped file ``builtin:paper-ppo`` also holds. Each field's metadata ``"help"``
    describes it.
    """

    env_id: str = field(metadata={"help": "environment id, e.g. Foosball-Block-v0"})
    env_kwargs: dict[str, Any] = field(
        default_factory=dict, metadata={"help": "the environment's options"}
    )
    algo: str = _field("ppo", "the learning algorithm")
    timesteps: int = _field(500_000, "environment steps to train for")
    n_envs: int = _field(16, "environments stepped side by side")
    seed: int = _field(0, "seed of the environments and the model")
    self_play: bool | None = _field(
        None, "play frozen copies of the learner (None: on for two-player tasks)"
    )
    normalize: bool = _field(True, "normalise observations by their running mean and variance")
    normalize_reward: bool = _field(True, "scale rewards by the running spread of returns")
    vec_env: str = _field(
        "batched",
        "dummy: environments in this process; subproc: one process each; batched: split over "
        "one process per core, this one among them",
    )
    net_arch: tuple[int, ...] = _field((64, 64), "hidden layers of the networks")
    learning_rate: float = _field(3e-4, "learning rate")
    gamma: float = _field(0.99, "discount factor")
    n_steps: int = _field(128, "PPO horizon per environment")
    batch_size: int = _field(256, "minibatch size")
    n_epochs: int = _field(20, "PPO's passes over each rollout")
    gae_lambda: float = _field(0.95, "PPO's GAE lambda")
    clip_range: float = _field(0.2, "PPO's clip range")
    # e^-1 of the half range: SB3's 0 explores so widely that Block's keeper never settles.
    log_std_init: float = _field(-1.0, "PPO's initial log standard deviation of actions")
    ent_coef: float = _field(0.0, "PPO's weight of the policy's entropy in its loss")
    use_sde: bool = _field(
        False,
        "generalised state-dependent exploration (gSDE, PPO and SAC): the actions' noise a "
        "random linear function of the policy's last hidden layer, drawn anew every "
        "sde_sample_freq steps, its log standard deviation starting at log_std_init",
    )
    sde_sample_freq: int = _field(
        -1, "with use_sde, draw new exploration noise every this many steps (-1: once a rollout)"
    )
    worker_rollouts: bool | None = _field(
        None,
        "PPO: each process that steps environments plays its share's whole rollout with a "
        "copy of the policy, one message a rollout instead of one a step (None: on where it "
        "can play; asked for where it cannot, refused with the reason)",
    )
    adam_eps: float | None = _field(
        1e-8, "Adam's epsilon (None: SB3's own, 1e-5 for PPO; PyTorch's default is 1e-8)"
    )
    fused_adam: bool = _field(
        True,
        "PyTorch's fused Adam, one kernel for every parameter: faster on a CPU, its steps not "
        "bit for bit those of the default",
    )
    lr_schedule: str = _field("linear", "constant, or linear decay to 0 over the run")
    learner: str | None = _field(
        None,
        "where the update runs: jax (SB3's PPO update, every epoch in one compiled call: "
        "several times faster on a CPU) or torch (SB3's own); default: jax for PPO, torch for "
        "SAC and CrossQ",
    )
    target_kl: float | None = _field(None, "end an update's epochs once the policy moved this far")
    pretrain_episodes: int = _field(
        0, "episodes of the scripted baseline to behaviour-clone before learning"
    )
    teacher_steps: int = _field(
        0,
        "PPO: for this many steps, fit the policy's mean to the scripted baseline's actions on "
        "the states each rollout visited (DAgger), less and less until then (0: off)",
    )
    teacher: str = _field(
        "scripted",
        "who labels the states for teacher_steps: scripted (the task's scripted baseline) or a "
        "model trained on the same environment (a run dir, a .zip or builtin:NAME), whose mean "
        "action is the label",
    )
    selfplay_rule: str = _field(
        "win_rate",
        "when self-play replaces its opponent: win_rate (the paper's: the learner wins at "
        "least the threshold of the window's games), net_score ((wins - losses) / games "
        "above it), winning (the win rate, and more wins than losses) or significant (the "
        "wins among decisive games pass a one-sided sign test at the threshold's level, "
        "e.g. 0.05)",
    )
    selfplay_window: int = _field(100, "games the self-play rule judges")
    selfplay_threshold: float | None = _field(
        None,
        "the self-play rule's threshold (default 0.2; for significant, the test's level, "
        "default 0.05)",
    )
    selfplay_pool: int = _field(1, "draw opponents from this many latest snapshots")
    selfplay_scripted_share: float = _field(
        0.0,
        "share of self-play games against the scripted opponent instead of a snapshot, in "
        "[0, 1); they do not count towards replacing the opponent",
    )
    selfplay_scripted_levels: tuple[int, ...] = _field(
        (),
        "the rungs of the game's scripted ladder that the scripted share of the games is drawn "
        "from, one at random for each game (empty: the top alone, the default opponent)",
    )
    selfplay_ladder_steps: int = _field(
        0,
        "the rungs of selfplay_scripted_levels join the scripted games one at a time, in the "
        "order listed, one more every this many steps (0: all from the start)",
    )
    selfplay_sampled: bool = _field(
        False,
        "self-play opponents sample their actions as the learner does, instead of acting on "
        "their policy's mean",
    )
    selfplay_gate: int = _field(
        0,
        "when the rule grants a replacement, the learner's mean first plays this many games "
        "against the newest opponent's mean, and both play as many against the scripted side; "
        "it stands only with no more losses than wins, and a better goal difference than the "
        "opponent's against the scripted side (0: off)",
    )
    selfplay_stall_games: int = _field(
        2000,
        "after this many games without a new opponent, self-play has stalled: the run says so "
        "and judges by selfplay_stall_fallback from then on (0: never)",
    )
    selfplay_stall_fallback: str = _field(
        "significant",
        "the replacement rule a stall switches to (none: keep the rule); significant needs "
        "no win rate, only more wins than losses among decisive games, beyond chance",
    )
    curriculum: dict[str, Any] = field(
        default_factory=dict,
        metadata={
            "help": "serve options (speed_range, serve_x_range, ...) with the values a run "
            "starts from; they move to the run's own over curriculum_steps"
        },
    )
    curriculum_steps: int = _field(0, "steps over which the curriculum's serves become the run's")
    rods_held_share: float = _field(
        0.0,
        "in each training game, each of the learner's rods is held at the action 0 with this "
        "chance, at least one left to it (0: none held)",
    )
    eval_freq: int = _field(25_000, "evaluate every this many steps")
    eval_episodes: int = _field(50, "seeded episodes per evaluation")
    checkpoint_freq: int = _field(50_000, "write a checkpoint every this many steps")
    target_success: float | None = _field(
        None, "stop once an evaluation reaches this success rate, 0-1"
    )
    torch_threads: int = _field(1, "PyTorch's threads")
    video_every: int | None = _field(
        None, "write a short clip of the policy to RUN/videos/ every this many steps"
    )

    def check(self) -> None:
        """Raise ValueError with what is allowed for anything out of range."""
        check_env_id(self.env_id)
        if self.algo not in ALGORITHMS:
            raise ValueError(f"unknown algorithm {self.algo!r}; allowed: {', '.join(ALGORITHMS)}")
        if self.vec_env not in VEC_ENV_KINDS:
            raise ValueError(
                f"unknown vec_env {self.vec_env!r}; allowed: {', '.join(VEC_ENV_KINDS)}"
            )
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
        if int(self.seed) < 0:
            raise ValueError(f"seed must be 0 or more, got {self.seed}")
        if not 0.0 <= float(self.selfplay_scripted_share) < 1.0:
            raise ValueError(
                f"selfplay_scripted_share must be in [0, 1), got {self.selfplay_scripted_share}"
            )
        if int(self.pretrain_episodes) < 0:
            raise ValueError(f"pretrain_episodes must be 0 or more, got {self.pretrain_episodes}")
        if int(self.selfplay_gate) < 0 or int(self.selfplay_gate) == 1:
            raise ValueError(
                f"selfplay_gate must be 0 (off) or at least 2 games, got {self.selfplay_gate}"
            )
        if int(self.teacher_steps) < 0:
            raise ValueError(f"teacher_steps must be 0 or more, got {self.teacher_steps}")
        if self.teacher_steps and self.algo != "ppo":
            raise ValueError(
                f"teacher_steps needs PPO (it fits each rollout), not {self.algo}; leave it at 0"
            )
        if not str(self.teacher).strip():
            raise ValueError("teacher must be 'scripted' or a model (run dir, .zip, builtin:NAME)")
        if self.teacher != "scripted" and not self.teacher_steps:
            raise ValueError(
                f"teacher {self.teacher!r} teaches only with teacher_steps above 0; set "
                "teacher_steps or leave teacher at 'scripted'"
            )
        if self.teacher_steps and self.env_kwargs.get("residual"):
            raise ValueError(
                "teacher_steps teaches the whole action (the scripted one or a model's), while a "
                "residual policy learns a correction to the scripted one; use one or the other"
            )
        if self.algo == "ppo" and (self.n_steps * self.n_envs < 2 or self.batch_size < 2):
            raise ValueError(
                "PPO needs n_steps x n_envs and batch_size of at least 2, got "
                f"{self.n_steps} x {self.n_envs} and {self.batch_size}"
            )
        rollout = self.n_steps * self.n_envs
        default_batch = next(f.default for f in fields(self) if f.name == "batch_size")
        if self.algo == "ppo" and default_batch != self.batch_size > rollout:
            # SB3 trains on the whole rollout where a minibatch does not fit, as the default
            # does with few environments; a minibatch asked for is meant to fit.
            raise ValueError(
                f"batch_size {self.batch_size} is more than a rollout holds: n_steps x n_envs = "
                f"{self.n_steps} x {self.n_envs} = {rollout}; give a batch_size of at most "
                f"{rollout}, or more n_steps or n_envs"
            )
        if not self.net_arch or any(int(n) < 1 for n in self.net_arch):
            raise ValueError(f"net_arch must be layer sizes of at least 1, got {self.net_arch}")
        # Written `not x > 0` and alike, so that NaN fails too.
        if not 0 < self.learning_rate < math.inf:
            raise ValueError(f"learning_rate must be a positive number, got {self.learning_rate}")
        if not 0 < self.gamma <= 1:
            raise ValueError(f"gamma must lie in (0, 1], got {self.gamma}")
        if not 0 <= self.gae_lambda <= 1:
            raise ValueError(f"gae_lambda must lie in [0, 1], got {self.gae_lambda}")
        if not 0 < self.clip_range < math.inf:
            raise ValueError(f"clip_range must be a positive number, got {self.clip_range}")
        if not 0 <= self.ent_coef < math.inf:
            raise ValueError(f"ent_coef must be a number, 0 or more, got {self.ent_coef}")
        if self.ent_coef and self.algo != "ppo":
            raise ValueError(
                f"ent_coef weighs PPO's entropy; {self.algo} tunes its own: leave it at 0"
            )
        if not math.isfinite(self.log_std_init):
            raise ValueError(f"log_std_init must be a finite number, got {self.log_std_init}")
        if self.use_sde and self.algo not in ("ppo", "sac"):
            raise ValueError(f"use_sde needs PPO or SAC, not {self.algo}; leave it off")
        if (
            isinstance(self.sde_sample_freq, bool)
            or not isinstance(self.sde_sample_freq, int)
            or not (self.sde_sample_freq == -1 or self.sde_sample_freq >= 1)
        ):
            raise ValueError(
                "sde_sample_freq must be -1 (new noise once a rollout) or a whole number of "
                f"steps, at least 1, got {self.sde_sample_freq!r}"
            )
        if self.sde_sample_freq != -1 and not self.use_sde:
            raise ValueError(
                f"sde_sample_freq {self.sde_sample_freq} says how often gSDE draws its noise; "
                "it needs use_sde"
            )
        if self.selfplay_threshold is None:
            self.selfplay_threshold = default_threshold(self.selfplay_rule)
        check_rule(self.selfplay_rule, self.selfplay_threshold)
        if self.selfplay_stall_fallback not in ("none", *SELFPLAY_RULES):
            raise ValueError(
                f"unknown selfplay_stall_fallback {self.selfplay_stall_fallback!r}; allowed: "
                f"none, {', '.join(SELFPLAY_RULES)}"
            )
        if self.selfplay_stall_games and self.selfplay_stall_games < self.selfplay_window:
            raise ValueError(
                f"selfplay_stall_games must be 0 (never) or at least a window of games "
                f"({self.selfplay_window}), got {self.selfplay_stall_games}"
            )
        if self.lr_schedule not in LR_SCHEDULES:
            raise ValueError(
                f"unknown lr_schedule {self.lr_schedule!r}; allowed: {', '.join(LR_SCHEDULES)}"
            )
        if self.learner is None:
            self.learner = "jax" if self.algo == "ppo" else "torch"
        if self.learner not in LEARNERS:
            raise ValueError(f"unknown learner {self.learner!r}; allowed: {', '.join(LEARNERS)}")
        if self.learner == "jax":
            if self.algo != "ppo":
                raise ValueError(f"learner jax runs PPO's update; {self.algo} takes learner torch")
            if importlib.util.find_spec("jax") is None:
                raise ValueError(
                    "learner jax needs JAX, which is not installed: pip install 'jax[cpu]' "
                    "(or foosball_gym's train extra), or train with learner torch"
                )
        if self.adam_eps is not None and not 0 < self.adam_eps < math.inf:
            raise ValueError(f"adam_eps must be a positive number or None, got {self.adam_eps}")
        if self.target_kl is not None and not 0 < self.target_kl < math.inf:
            raise ValueError(f"target_kl must be positive, got {self.target_kl}")
        if self.target_success is not None and not 0 < self.target_success <= 1:
            raise ValueError(f"target_success must lie in (0, 1], got {self.target_success}")
        if self.video_every is not None and (
            isinstance(self.video_every, bool)
            or not isinstance(self.video_every, int)
            or self.video_every < 1
        ):
            raise ValueError(
                "video_every must be a whole number of steps, at least 1, or None (no clips), "
                f"got {self.video_every!r}"
            )
        if self.env_id in ENV_IDS:
            # Checked as the environment checks them, without building one.
            checked = check_env_options(self.env_id, self.env_kwargs)
            names = list(checked.interface.builder.names)
            two_player = checked.two_player
            n_rods = len(checked.interface.layout.controlled)
            levels: Callable[[int], object] = partial(checked.task.scripted_level, names=names)
        else:
            # Another registered environment: only making it says what it takes.
            env = gym.make(self.env_id, **self.env_kwargs)
            try:
                foosball = cast("FoosballEnv", env.unwrapped)
                two_player, levels = bool(foosball.layout.opponent), foosball.scripted_opponent
                n_rods = len(foosball.layout.controlled)
            finally:
                env.close()
        if self.curriculum or self.curriculum_steps:
            if self.env_id not in ENV_IDS:
                raise ValueError(
                    f"a curriculum over serves needs one of {', '.join(ENV_IDS)}, not {self.env_id}"
                )
            check_curriculum(self.env_id, self.env_kwargs, self.curriculum, self.curriculum_steps)
        if self.self_play and not two_player:
            raise ValueError(f"{self.env_id} has no opponent; self-play needs a two-player task")
        if self.self_play is None:
            self.self_play = two_player
        if self.selfplay_scripted_levels:
            self.selfplay_scripted_levels = check_levels(
                self.selfplay_scripted_levels,
                bool(self.self_play),
                self.selfplay_scripted_share,
                levels,
            )
        check_ladder_steps(self.selfplay_ladder_steps, self.selfplay_scripted_levels)
        check_rods_held_share(self.rods_held_share, n_rods, self.env_id)
        if self.selfplay_gate and not self.self_play:
            raise ValueError(
                f"selfplay_gate judges self-play's replacements; {self.env_id} trains without "
                "self-play here"
            )
        self._check_worker_rollouts()
        if self.self_play:
            # The paper's self-play task has no early draw for a still ball (docs/self-play.md);
            # written into env_kwargs so that the run's evaluations play the game it trained on.
            # In a continuous match a still ball is served again, not drawn: that rule stays.
            if not self.env_kwargs.get("continuous"):
                self.env_kwargs.setdefault("stagnation_steps", 0)

    def _check_worker_rollouts(self) -> None:
        """Resolve worker_rollouts' default; refuse it where it was asked for and cannot play."""
        reasons = [
            (
                self.self_play and bool(self.env_kwargs.get("residual")),
                "worker_rollouts plays self-play's snapshots as they are; a residual learner's "
                "corrections are made whole in the training process: leave worker_rollouts off",
            ),
            (
                self.self_play and self.selfplay_sampled,
                "worker_rollouts plays self-play's snapshots on their mean; selfplay_sampled's "
                "draws are made in the training process: leave one of them off",
            ),
            (
                self.algo != "ppo",
                f"worker_rollouts plays PPO's rollouts; {self.algo} learns from a replay buffer "
                "step by step: leave it off",
            ),
            (
                self.use_sde,
                "worker_rollouts plays a Gaussian independent of the state; use_sde's noise is "
                "drawn in the training process: leave one of them off",
            ),
            (
                self.vec_env == "subproc",
                "worker_rollouts needs vec_env batched or dummy, whose processes can play a "
                "share of the environments, not subproc",
            ),
        ]
        if self.worker_rollouts is None:
            self.worker_rollouts = not any(stands for stands, _ in reasons)
        for stands, message in reasons:
            if self.worker_rollouts and stands:
                raise ValueError(message)

    def save(self, path: Path) -> None:
        """Write the configuration with the record of the physics it is about to train on.

        The record is not a field: it describes the physics of this installation, not a choice,
        so a configuration loaded from an older run and saved for a new one gets the current
        record. :meth:`load` ignores it.
        """
        data = {**asdict(self), "physics": physics_record()}
        atomic_write_text(path, json.dumps(data, indent=2))

    @classmethod
    def load(cls, path: Path) -> TrainConfig:
        """A run's configuration from its ``config.json``.

        Raises:
            ValueError: the file is not JSON, not an object, lacks ``env_id`` or holds a field
                of the wrong kind (the message names the file and the field); the values'
                ranges are :meth:`check`'s.
        """
        data = read_json(path, dict, "a run's configuration")
        names = {f.name for f in fields(cls)}
        if "env_id" not in data:
            raise ValueError(f"{path} is damaged: it names no env_id")
        for f in fields(cls):
            if f.name in data and not of_kind(data[f.name], str(f.type)):
                raise ValueError(
                    f"{path} is damaged: {f.name} must be {KINDS_SPELLED[str(f.type)]}, "
                    f"got {data[f.name]!r}"
                )
        if data.get("self_play") and "selfplay_rule" not in data:
            # Runs from before the rule was an option replaced their opponent on net score.
            data["selfplay_rule"] = "net_score"
        given = {k: v for k, v in data.items() if k in names}
        config = cls(**{**LEGACY_DEFAULTS, **given})
        config.net_arch = tuple(config.net_arch)
        config.selfplay_scripted_levels = tuple(config.selfplay_scripted_levels)
        return config


def stall_fallback(config: TrainConfig) -> str | None:
    """The rule a stall of ``config``'s self-play switches to; None keeps the rule."""
    return None if config.selfplay_stall_fallback == "none" else config.selfplay_stall_fallback
