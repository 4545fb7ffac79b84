"""Loading a trained policy to play: from a run directory of either backend, a model zip, or
a shipped name: ``builtin:NAME``, one of the run directories in ``foosball_gym/builtin/``.

Imports no trainer: an exported RLlib policy is read without Ray, an SB3 model without its
algorithm.
"""

from __future__ import annotations

import inspect
import warnings
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

from foosball_gym.policy_io.task import residual_action, residual_scale
from foosball_gym.training.loading.recurrent import RecurrentSnapshot
from foosball_gym.training.loading.rl_zoo import find_zoo_run, is_zoo_run
from foosball_gym.training.loading.rllib_policy import (
    RllibPolicy,
    is_rllib_run,
    load_rllib_policy,
)
from foosball_gym.training.loading.run_lookup import (
    ModelLoadError,
    find_config,
    find_norm,
    find_norm_names,
    unfinished_run_model,
)
from foosball_gym.training.loading.sb3_policies import (
    is_recurrent,
    policy_class_name,
    policy_from_zip,
)
from foosball_gym.training.loading.sb3_snapshot import PolicySnapshot, policy_from_state_dict
from foosball_gym.training.loading.threads import use_one_torch_thread
from foosball_gym.training.run_dir.files import CONFIG_FILE, MODEL_FILE
from foosball_gym.training.run_dir.physics import warn_physics
from foosball_gym.training.run_dir.storage import (
    NormStats,
    UntrustedFileError,
    load_pickled_norm,
    read_model_zip,
    read_norm,
    zip_statistics,
)

if TYPE_CHECKING:
    from foosball_gym.registration import CheckedOptions


@dataclass
class LoadedPolicy:
    """A trained policy with the environment it was trained on; call it with an observation
    to get the action (its normalisation applied).

    A model trained with the environment option ``residual`` learned a correction to the
    task's scripted baseline: calling it gives the whole action, baseline and correction, so
    that it plays wherever an action is expected (``foosball play`` on a real table included).
    Its ``env_kwargs`` then leave ``residual`` out (``trained_residual`` keeps the scale):
    an environment made with them takes the whole action. The baseline is the one for the
    state it was trained on; :meth:`with_baseline_for` gives it the baseline for where it
    plays (``foosball eval`` and :func:`~foosball_gym.evaluation.evaluate` do so, and
    ``foosball play`` for a table's camera and filter).

    ``source`` is what was loaded: the run directory or zip given, ``builtin:NAME`` as given,
    or where a run has no final model, the zip played in its place, which ``note`` tells in
    one line (None where the model asked for was loaded).
    """

    policy: PolicySnapshot | RllibPolicy
    env_id: str | None
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    source: str = ""
    trained_residual: float | tuple[float, ...] = 0.0
    baseline: Any = None
    note: str | None = None

    @property
    def observation_size(self) -> int:
        """The size of the observations it takes."""
        return self.policy.observation_size

    @property
    def recurrent(self) -> bool:
        """Whether it carries a state from call to call (RecurrentPPO): :meth:`reset` it where
        each episode starts."""
        return isinstance(self.policy, RecurrentSnapshot)

    def reset(self) -> None:
        """Start a new episode: a recurrent policy forgets its state; others have none."""
        if isinstance(self.policy, RecurrentSnapshot):
            self.policy.reset()

    def __call__(self, obs: Any) -> np.ndarray:
        action = self.policy(obs)
        if self.baseline is None:
            return action
        obs = np.asarray(obs)
        base = self.baseline(obs) if obs.ndim == 1 else [self.baseline(o) for o in obs]
        return residual_action(base, self.trained_residual, action)

    def whole_action(self) -> Any:
        """This policy as a player of actions over the rods' travel, for the away side of a
        game or for games made without its options (:func:`whole_action_policy`): itself,
        unless it was trained with ``slide_around_ball`` (a residual policy plays its baseline
        already)."""
        if self.env_id is None or not self.env_kwargs.get("slide_around_ball"):
            return self
        return whole_action_policy(self, self.env_id, self.env_kwargs)[0]

    def with_baseline_for(
        self, env_id: str, env_kwargs: dict[str, Any] | None = None, on_table: bool = False
    ) -> LoadedPolicy:
        """This policy with the scripted baseline of where it plays: ``env_id`` with options
        ``env_kwargs``, or a table's camera and filter (``on_table``); itself if no residual.

        The scripted baselines play the estimated state differently from the true state (the
        Score keeper volleys a ball it would deflect, as a deflection needs the ball's path to
        a millimetre), and a correction learned on one state is small beside its baseline.

        Raises:
            ValueError: ``env_id`` is not registered, or an option has a bad value.
            TypeError: an option the environment does not take.
        """
        if self.baseline is None:
            return self
        from foosball_gym.registration import check_env_options

        # gymnasium.make's own keywords (max_episode_steps, ...) are not the environment's.
        own = set(inspect.signature(gym.make).parameters)
        options = {k: v for k, v in (env_kwargs or {}).items() if k not in own}
        return self.with_baseline_of(check_env_options(env_id, options), on_table)

    def with_baseline_of(self, checked: CheckedOptions, on_table: bool = False) -> LoadedPolicy:
        """:meth:`with_baseline_for` the options ``checked`` (check_env_options) holds."""
        if self.baseline is None:
            return self
        from foosball_gym.registration import scripted_for

        return replace(self, baseline=scripted_for(checked, on_table))

    def check_env(
        self, env_id: str, env_kwargs: Any = None, checked: CheckedOptions | None = None
    ) -> None:
        """Raise ValueError where the env's observations (``checked``'s, if given) do not fit."""
        from foosball_gym.registration import observation_size

        size = checked.observation_size if checked else observation_size(env_id, env_kwargs)
        expected = self.policy.observation_size
        if size != expected:
            trained = f" of {self.env_id}" if self.env_id else ""
            raise ValueError(
                f"{self.source} expects observations of size {expected}{trained}, but "
                f"{env_id} gives {size}: give a model trained on {env_id}"
            )


def _builtin_root() -> Path:
    return Path(str(resources.files("foosball_gym") / "builtin"))


def builtin_names() -> list[str]:
    """The names of the shipped policies, sorted."""
    root = _builtin_root()
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if (p / MODEL_FILE).exists())


def builtin_path(name: str) -> Path:
    """The run directory of the shipped policy ``name``.

    Raises:
        ModelLoadError: no policy of that name is shipped; the message lists those that are.
    """
    names = builtin_names()
    if name not in names:
        raise ModelLoadError(
            f"no built-in policy {name!r}; shipped: {', '.join(names) if names else 'none'}"
        )
    return _builtin_root() / name


def load_policy(spec: str | Path, trust: bool = False) -> LoadedPolicy:
    """Load a policy from a run directory, a model ``.zip``, an RL Zoo run, or ``builtin:NAME``.

    The environment id and options come from the run's ``config.json`` (next to the zip, or
    one level up for a checkpoint); a bare zip without one loads with ``env_id=None``. A run
    without its final ``model.zip`` (stopped before the end) gives its best model, else its
    newest checkpoint, and says which in the policy's ``note``. An RL
    Zoo run folder (``<log>/<algo>/<env>_<n>/``, or a zip in one) gives its final model with
    the environment and options it trained on (see :func:`.rl_zoo.find_zoo_run`).

    The model zip may be of any Stable-Baselines3 or sb3-contrib algorithm that acts on
    continuous actions, with its ``MlpPolicy`` (:data:`.sb3_policies.SUPPORTED`); others are
    refused in one line saying which load. A RecurrentPPO policy carries its LSTM state from
    call to call: ``reset()`` it where an episode starts (``evaluate`` does).

    Nothing is unpickled unless ``trust`` is given: the weights are read as tensors and the
    policy rebuilt around them, the pickled fields SB3 keeps in the zip are left unread, and
    normalisation statistics are read from the zip's own record (a zip from before it, from
    ``vecnormalize.json`` beside it). A run from before that file (``vecnormalize.pkl``) is
    refused with a message saying how to migrate it; an RL Zoo run's ``vecnormalize.pkl``,
    with one saying to trust it. A model whose run normalised its observations but whose
    statistics are missing (or whose zip records that it has none), statistics that make no
    sense, or statistics of another size of observation are refused too: the policy would act
    on observations it never saw.

    Warns with :class:`~foosball_gym.training.run_dir.physics.PhysicsMismatchWarning` where
    the model was trained on another physics revision than the current one (a run from before
    runs recorded it was trained on revision 1). A model with no run's ``config.json`` at all
    (a bare zip, an RL Zoo run) warns with
    :class:`~foosball_gym.training.run_dir.physics.UnknownPhysicsWarning`: its revision is
    unknown.

    PyTorch is left with one thread, unless ``OMP_NUM_THREADS`` asks for another number
    (:func:`~foosball_gym.training.loading.threads.use_one_torch_thread`): more only slow a
    policy that plays one observation at a time.

    Args:
        spec: the run directory, the model zip, the RL Zoo run folder, or ``builtin:NAME``.
        trust: also read pickled files (a legacy or RL Zoo ``vecnormalize.pkl``): only for
            files whose source you trust, since unpickling runs whatever code the file holds.

    Raises:
        ModelLoadError: no model there, or it cannot be read (or only by unpickling, untrusted).
    """
    use_one_torch_thread()
    text = str(spec)
    if text.startswith("builtin:"):
        path = builtin_path(text.split(":", 1)[1])
    else:
        path = Path(text)
    if path.is_dir() and is_rllib_run(path):
        try:
            rllib = load_rllib_policy(path)
        except ValueError as err:
            raise ModelLoadError(str(err)) from None
        return LoadedPolicy(
            policy=rllib, env_id=rllib.env_id, env_kwargs=rllib.env_kwargs, source=str(path)
        )
    env_id: str | None
    note: str | None = None
    zoo = is_zoo_run(path)
    if zoo:
        try:
            found = find_zoo_run(path)
        except ValueError as err:
            raise ModelLoadError(str(err)) from None
        zip_path, norm, run_dir, config = found.model, found.norm, found.folder, None
        env_id, env_kwargs = found.env_id, found.env_kwargs
    else:
        if path.is_dir() and not (path / MODEL_FILE).exists():
            zip_path, note = unfinished_run_model(path)
            run_dir = zip_path.parent
        elif path.is_dir():
            run_dir, zip_path = path, path / MODEL_FILE
        else:
            zip_path, run_dir = path, path.parent
        if not zip_path.exists():
            raise ModelLoadError(f"no model at {zip_path}")
        config = find_config(run_dir)
        env_id = (config or {}).get("env_id")
        env_kwargs = dict((config or {}).get("env_kwargs") or {})
        norm = find_norm(zip_path, run_dir)
    policy, recurrent = _read_policy(zip_path)
    try:
        recorded, stats = zip_statistics(zip_path)
    except ValueError as err:
        raise ModelLoadError(f"{zip_path}: {err}") from None
    if recorded and norm is not None and not zoo:
        warnings.warn(
            f"{norm} is not read: {zip_path} holds its own normalisation statistics",
            stacklevel=2,
        )
    elif not recorded and norm is not None:
        run = text if text.startswith("builtin:") else run_dir
        stats = _read_stats(norm, run, trust, zoo)
    elif not recorded and config is not None and config.get("normalize", True):
        raise ModelLoadError(
            f"{zip_path} was trained on normalised observations ({CONFIG_FILE} says normalize: "
            f"true), but its statistics ({find_norm_names(zip_path, run_dir)}) are missing: "
            "without them the policy acts on observations it never saw (a run killed between "
            "writing the two?); the run's other models (checkpoints/, best/) may have theirs"
        )
    if recorded and stats is None and config is not None and config.get("normalize", True):
        # The zip says it was trained without statistics, its run says with: one of them is
        # another run's, and the policy would act on observations it never saw.
        raise ModelLoadError(
            f"{zip_path} holds no normalisation statistics, but its run's {CONFIG_FILE} says "
            "normalize: true: the policy would act on observations it never saw (a model of "
            "another run?), so it is refused, as foosball train --resume refuses it"
        )
    if stats is not None and stats.norm_obs and len(stats.obs_mean) != policy_size(policy):
        raise ModelLoadError(
            f"the normalisation statistics of {zip_path} are of {len(stats.obs_mean)} "
            f"observations, the policy takes {policy_size(policy)}: they are another model's"
        )
    cls = RecurrentSnapshot if recurrent else PolicySnapshot
    if stats is not None and stats.norm_obs:
        snapshot = cls(
            policy, stats.obs_mean, stats.obs_var, stats.clip_obs, stats.epsilon, env_id=env_id
        )
    else:
        snapshot = cls(policy, env_id=env_id)
    warn_physics(config, f"the model {text}")
    residual = residual_scale(env_kwargs.pop("residual", 0.0))
    baseline = None
    if residual and env_id is not None:
        from foosball_gym.registration import scripted_policy

        try:
            baseline = scripted_policy(env_id, env_kwargs)
        except ValueError as err:  # an environment or options no longer registered
            raise ModelLoadError(f"the model {text} is a residual: {err}") from None
    return LoadedPolicy(
        policy=snapshot,
        env_id=env_id,
        env_kwargs=env_kwargs,
        source=text if text.startswith("builtin:") else str(zip_path if note else path),
        trained_residual=residual,
        baseline=baseline,
        note=note,
    )


def _read_policy(zip_path: Path) -> tuple[Any, bool]:
    """The policy in a Stable-Baselines3 zip, and whether it is recurrent."""
    try:
        data, params, _ = read_model_zip(zip_path)
        state = params["policy"]
        if policy_class_name(data) is None:
            # Zips that do not name their policy: a PPO or SAC MlpPolicy, told by its weights.
            return policy_from_state_dict(state), False
        return policy_from_zip(data, state), is_recurrent(data)
    except (KeyError, ValueError, RuntimeError, EOFError) as err:
        reason = "it has no policy weights" if isinstance(err, KeyError) else str(err)
        raise ModelLoadError(
            f"cannot read {zip_path} as a Stable-Baselines3 model ({reason})"
        ) from None


def _read_stats(norm: Path, run: Path | str, trust: bool, zoo: bool) -> NormStats:
    """The normalisation statistics in ``norm``: plain numbers, or a pickle only if trusted."""
    try:
        if zoo and norm.suffix == ".pkl":
            if not trust:
                raise UntrustedFileError(
                    f"{norm} holds the RL Zoo run's observation normalisation as a pickle, "
                    "which can run any code when it is read, so it was not read: give "
                    "--trust-model (load_policy's trust=True) if you trust where the run "
                    "comes from"
                )
            return load_pickled_norm(norm)
        return read_norm(norm, run, trust)
    except UntrustedFileError as err:
        raise ModelLoadError(str(err)) from None
    except Exception as err:  # noqa: BLE001 - any unreadable file gets the same message
        detail = str(err) if str(norm) in str(err) else f"{norm}: {err}"
        raise ModelLoadError(f"cannot read normalisation statistics: {detail}") from err


def policy_size(policy: Any) -> int:
    """The size of the observations an SB3 policy takes."""
    return int(np.prod(policy.observation_space.shape))


# The options under which a trained policy's action is not the action over the rods' travel
# that the opponent's side, a gate's and a league's games take (whole_action_policy).
NOT_WHOLE_ACTION = ("residual", "slide_around_ball", "slide_skip")


def whole_action_options(env_kwargs: dict[str, Any]) -> dict[str, Any]:
    """``env_kwargs`` for an environment where players from :func:`whole_action_policy` play
    both sides: without the options that make a learner's action something else."""
    return {k: v for k, v in env_kwargs.items() if k not in NOT_WHOLE_ACTION}


def whole_action_policy(
    policy: Any, env_id: str, env_kwargs: dict[str, Any]
) -> tuple[Any, dict[str, Any]]:
    """``policy`` (a snapshot of a model trained on ``env_id`` with ``env_kwargs``) as a
    player that gives the whole action, and the options of an environment that takes it.

    A model trained with the option ``residual`` gives corrections to the scripted baseline:
    wherever it plays as an opponent, or in a game whose environment must take both sides'
    whole actions (self-play's opponents, a gate, a league), it plays as the baseline plus its
    correction, and the environment is made without ``residual``. A model trained with
    ``slide_around_ball`` slides around the ball it observes: there it plays as an
    :class:`~foosball_gym.policy_io.around_ball.AroundBallPlayer`, sliding over the rods'
    travel, and the environment is made without the band. Any other policy is returned as it
    is, with the options unchanged.
    """
    options = dict(env_kwargs)
    if options.get("slide_around_ball"):
        from foosball_gym.policy_io.around_ball import AroundBallPlayer
        from foosball_gym.registration import check_env_options

        interface = check_env_options(env_id, options).interface
        return AroundBallPlayer(policy, interface), whole_action_options(options)
    residual = residual_scale(options.pop("residual", 0.0))
    if not residual:
        return policy, dict(env_kwargs)
    from foosball_gym.registration import scripted_policy

    baseline = scripted_policy(env_id, options)
    player = LoadedPolicy(
        policy=policy,
        env_id=env_id,
        env_kwargs=options,
        source=f"a residual policy of {env_id}",
        trained_residual=residual,
        baseline=baseline,
    )
    return player, options
