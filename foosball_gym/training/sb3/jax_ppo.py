"""PPO whose update runs in JAX: SB3's PPO, its rollouts, its policy and its files, with the
update's epochs compiled into one XLA call.

On a CPU, PyTorch spends most of a small network's gradient step in per-operation overhead
(1.6-1.8 ms for 64-64 networks on 256 samples here); XLA fuses the whole loss, its gradient,
the gradient clipping and Adam into one program and runs every minibatch of every epoch in one
call. The PyTorch policy stays the model: each update reads its parameters and Adam's moments
from it and writes them back, so checkpoints, resuming, evaluation and play see an ordinary SB3
PPO. The update is SB3's (clipped surrogate, unclipped or clipped value loss, per-minibatch
advantage normalisation, gradient norm clipped, PyTorch's Adam, early stop on target_kl), the
same steps to floating-point rounding, not bit for bit.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.utils import explained_variance

from foosball_gym.training.sb3.mlp_layers import mlp_layers

JAX_MISSING = (
    "learner: jax needs JAX; install it with pip install 'jax[cpu]' (or the train extra of "
    "foosball_gym), or train with learner: torch"
)


def import_jax() -> Any:
    """jax.numpy, imported without moving NumPy's global generator (importing JAX draws from it,
    and SB3 shuffles minibatches with it: a run's seed would mean other minibatches)."""
    state = np.random.get_state()
    try:
        import jax.numpy as jnp
    except ImportError:
        raise ImportError(JAX_MISSING) from None
    finally:
        np.random.set_state(state)
    return jnp


class JaxPPO(PPO):
    """SB3's PPO with :meth:`train` compiled by JAX (see the module's docstring)."""

    def _setup_model(self) -> None:
        import_jax()
        super()._setup_model()
        if not isinstance(self.action_space, spaces.Box):
            raise ValueError(f"learner: jax needs a Box action space, not {self.action_space}")
        if (
            not isinstance(self.observation_space, spaces.Box)
            or len(self.observation_space.shape) != 1
        ):
            raise ValueError(
                f"learner: jax needs a flat Box observation space, not {self.observation_space}"
            )
        policy = self.policy
        dist = policy.dist_kwargs or {}
        if self.use_sde and (
            dist.get("use_expln") or not dist.get("full_std", True) or dist.get("squash_output")
        ):
            raise ValueError(
                "learner: jax takes gSDE with SB3's defaults (full_std, no expln, no squashing), "
                f"not {dist}"
            )
        self._jax_pi = mlp_layers(policy.mlp_extractor.policy_net, "mlp_extractor.policy_net.")
        self._jax_pi.append(("action_net.weight", "action_net.bias", "none"))
        self._jax_vf = mlp_layers(policy.mlp_extractor.value_net, "mlp_extractor.value_net.")
        self._jax_vf.append(("value_net.weight", "value_net.bias", "none"))
        names = [n for n, _ in policy.named_parameters()]
        used = {n for layer in self._jax_pi + self._jax_vf for n in layer[:2]} | {"log_std"}
        if set(names) != used:
            # A shared network or a features extractor with weights would go untrained.
            raise ValueError(
                f"learner: jax does not know the policy's parameters {sorted(set(names) - used)}"
            )
        self._jax_update: Any = None
        self._jax_update_key: tuple[Any, ...] | None = None
        self._jax_warned = False

    def _excluded_save_params(self) -> list[str]:
        return [
            *super()._excluded_save_params(),
            "_jax_pi",
            "_jax_vf",
            "_jax_update",
            "_jax_update_key",
            "_jax_warned",
        ]

    def _compiled_update(self, n_epochs: int, n_batches: int, clip_vf: bool) -> Any:
        key = (n_epochs, n_batches, clip_vf, self.normalize_advantage, self.target_kl is not None)
        if self._jax_update is None or self._jax_update_key != key:
            self._jax_update = _build_update(
                self._jax_pi,
                self._jax_vf,
                normalize_advantage=self.normalize_advantage,
                clip_vf=clip_vf,
                early_stop=self.target_kl is not None,
                sde=self.use_sde,
            )
            self._jax_update_key = key
        return self._jax_update

    def train(self) -> None:
        import jax.numpy as jnp

        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        lr = self.lr_schedule(self._current_progress_remaining)
        clip_range = self.clip_range(self._current_progress_remaining)  # type: ignore[operator]
        clip_range_vf = (
            None
            if self.clip_range_vf is None
            else self.clip_range_vf(self._current_progress_remaining)  # type: ignore[operator]
        )
        buffer = self.rollout_buffer
        n = buffer.buffer_size * buffer.n_envs
        if n % self.batch_size:
            # A short last minibatch would need a second compiled step; SB3's own update takes it.
            if not self._jax_warned:
                warnings.warn(
                    f"learner jax: batch_size {self.batch_size} does not divide the rollout's "
                    f"{n} samples (n_steps x n_envs), so SB3's PyTorch update runs instead: the "
                    "same update, slower",
                    stacklevel=2,
                )
                self._jax_warned = True
            super().train()
            return
        n_batches = n // self.batch_size

        def flat(array: np.ndarray, scalar: bool = False) -> Any:
            # The rollout buffer's (step, env, ...) order, flattened env by env as SB3's get()
            # does (unless get() has flattened it already), so a permutation picks the same
            # samples it would.
            if not buffer.generator_ready:
                array = array.swapaxes(0, 1)
            array = array.reshape(n, -1)
            return jnp.asarray(array[:, 0] if scalar else array, dtype=jnp.float32)

        data = (
            flat(buffer.observations),
            flat(buffer.actions),
            flat(buffer.log_probs, scalar=True),
            flat(buffer.advantages, scalar=True),
            flat(buffer.returns, scalar=True),
            flat(buffer.values, scalar=True),
        )
        # One permutation per epoch from NumPy's global generator, as SB3's get() draws it.
        order = np.stack([np.random.permutation(n) for _ in range(self.n_epochs)])
        order = order.reshape(self.n_epochs, n_batches, self.batch_size).astype(np.int32)

        params, adam = self._read_torch()
        update = self._compiled_update(self.n_epochs, n_batches, clip_range_vf is not None)
        hyper = np.array(
            [
                lr,
                clip_range,
                0.0 if clip_range_vf is None else clip_range_vf,
                self.ent_coef,
                self.vf_coef,
                self.max_grad_norm,
                np.inf if self.target_kl is None else 1.5 * self.target_kl,
            ],
            np.float32,
        )
        group = self.policy.optimizer.param_groups[0]
        betas = np.array([*group["betas"], group["eps"]], np.float32)
        params, adam, stats = update(params, adam, data, jnp.asarray(order), hyper, betas)
        self._write_torch(params, adam)

        stats = {k: np.asarray(v) for k, v in stats.items()}
        taken = stats["done"].astype(bool)  # the minibatch steps taken, (epochs, batches)
        # SB3 logs the losses of every minibatch it looked at, the one that stopped it too, and
        # counts the epoch it stopped in.
        seen = taken | np.concatenate([np.ones((1,), bool), taken.ravel()[:-1]]).reshape(
            taken.shape
        )
        self._n_updates += int(seen.any(axis=1).sum())
        explained = explained_variance(buffer.values.flatten(), buffer.returns.flatten())
        self.logger.record("train/entropy_loss", float(stats["entropy_loss"][seen].mean()))
        self.logger.record("train/policy_gradient_loss", float(stats["pg_loss"][seen].mean()))
        self.logger.record("train/value_loss", float(stats["value_loss"][seen].mean()))
        last_epoch = seen.any(axis=1).nonzero()[0][-1]
        self.logger.record(
            "train/approx_kl", float(stats["approx_kl"][last_epoch][seen[last_epoch]].mean())
        )
        self.logger.record("train/clip_fraction", float(stats["clip_fraction"][seen].mean()))
        self.logger.record("train/loss", float(stats["loss"][seen].ravel()[-1]))
        self.logger.record("train/explained_variance", explained)
        self.logger.record("train/std", th.exp(self.policy.log_std).mean().item())
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/clip_range", clip_range)
        if clip_range_vf is not None:
            self.logger.record("train/clip_range_vf", clip_range_vf)

    def _read_torch(self) -> tuple[dict[str, Any], dict[str, Any]]:
        """The policy's parameters and Adam's state, as JAX arrays by parameter name."""
        import jax.numpy as jnp

        optimizer = self.policy.optimizer
        params, m, v = {}, {}, {}
        step = 0.0
        for name, p in self.policy.named_parameters():
            params[name] = jnp.asarray(p.detach().numpy())
            state = optimizer.state.get(p, {})
            if state:
                m[name] = jnp.asarray(state["exp_avg"].numpy())
                v[name] = jnp.asarray(state["exp_avg_sq"].numpy())
                step = float(state["step"])
            else:
                m[name] = jnp.zeros_like(params[name])
                v[name] = jnp.zeros_like(params[name])
        return params, {"m": m, "v": v, "step": jnp.float32(step)}

    def _write_torch(self, params: dict[str, Any], adam: dict[str, Any]) -> None:
        optimizer = self.policy.optimizer
        step = float(adam["step"])
        with th.no_grad():
            for name, p in self.policy.named_parameters():
                p.copy_(th.from_numpy(np.array(params[name])))
                if step == 0:
                    continue  # no step taken (target_kl stopped the first): Adam stays empty
                state = optimizer.state[p]
                if not state:
                    # PyTorch's Adam keeps its step count as a float tensor (a CPU scalar, fused
                    # or not), each parameter its own.
                    state["step"] = th.tensor(0.0)
                    state["exp_avg"] = th.zeros_like(p)
                    state["exp_avg_sq"] = th.zeros_like(p)
                state["step"].fill_(step)
                state["exp_avg"].copy_(th.from_numpy(np.array(adam["m"][name])))
                state["exp_avg_sq"].copy_(th.from_numpy(np.array(adam["v"][name])))


def _build_update(
    pi: list[tuple[str, str, str]],
    vf: list[tuple[str, str, str]],
    *,
    normalize_advantage: bool,
    clip_vf: bool,
    early_stop: bool,
    sde: bool = False,
) -> Any:
    """The jitted update: every epoch's minibatches, in order, in one call.

    With ``sde``, the actions' distribution is gSDE's as SB3 builds it: a Gaussian about the
    mean whose variance is the squared last hidden layer (held fixed: SB3 detaches it) times
    the squared standard deviations of the noise matrix, plus 1e-6.
    """
    import jax
    import jax.numpy as jnp

    activations = {"tanh": jnp.tanh, "relu": jax.nn.relu, "none": lambda x: x}

    def mlp(params: dict[str, Any], layers: list[tuple[str, str, str]], x: Any) -> Any:
        for weight, bias, act in layers:
            x = activations[act](x @ params[weight].T + params[bias])
        return x

    def losses(params: dict[str, Any], batch: tuple[Any, ...], hyper: Any) -> tuple[Any, Any]:
        obs, actions, old_log_prob, advantages, returns, old_values = batch
        clip, clip_v, ent_coef, vf_coef = hyper[1], hyper[2], hyper[3], hyper[4]
        latent = mlp(params, pi[:-1], obs)
        weight, bias, _ = pi[-1]
        mean = latent @ params[weight].T + params[bias]
        log_std = params["log_std"]
        if sde:
            variance = jnp.square(jax.lax.stop_gradient(latent)) @ jnp.exp(2 * log_std)
            log_std = 0.5 * jnp.log(variance + 1e-6)
        log_prob = jnp.sum(
            -0.5 * jnp.square((actions - mean) / jnp.exp(log_std))
            - log_std
            - 0.5 * jnp.log(2 * jnp.pi),
            axis=-1,
        )
        values = mlp(params, vf, obs)[:, 0]
        if normalize_advantage and advantages.shape[0] > 1:
            advantages = (advantages - advantages.mean()) / (jnp.std(advantages, ddof=1) + 1e-8)
        ratio = jnp.exp(log_prob - old_log_prob)
        pg_loss = -jnp.mean(
            jnp.minimum(advantages * ratio, advantages * jnp.clip(ratio, 1 - clip, 1 + clip))
        )
        if clip_vf:
            values = old_values + jnp.clip(values - old_values, -clip_v, clip_v)
        value_loss = jnp.mean(jnp.square(returns - values))
        # A diagonal Gaussian's entropy depends on the observation only through gSDE's spread.
        entropy = jnp.sum(0.5 + 0.5 * jnp.log(2 * jnp.pi) + log_std, axis=-1)
        entropy_loss = -jnp.mean(entropy)
        loss = pg_loss + ent_coef * entropy_loss + vf_coef * value_loss
        log_ratio = log_prob - old_log_prob
        stats = {
            "pg_loss": pg_loss,
            "value_loss": value_loss,
            "entropy_loss": entropy_loss,
            "loss": loss,
            "clip_fraction": jnp.mean((jnp.abs(ratio - 1) > clip).astype(jnp.float32)),
            "approx_kl": jax.lax.stop_gradient(jnp.mean(jnp.exp(log_ratio) - 1 - log_ratio)),
        }
        return loss, stats

    grad_fn = jax.grad(losses, has_aux=True)

    def minibatch(carry: Any, index: Any, data: Any, hyper: Any, betas: Any) -> Any:
        params, adam, stopped = carry
        batch = tuple(x[index] for x in data)
        grads, stats = grad_fn(params, batch, hyper)
        # SB3 checks the KL before the step and stops the update there.
        stop = stopped | (stats["approx_kl"] > hyper[6]) if early_stop else stopped
        norm = jnp.sqrt(sum(jnp.sum(jnp.square(g)) for g in jax.tree_util.tree_leaves(grads)))
        # PyTorch's clip_grad_norm_.
        scale = jnp.minimum(hyper[5] / (norm + 1e-6), 1.0)
        b1, b2, eps = betas[0], betas[1], betas[2]
        step = adam["step"] + 1
        m = jax.tree_util.tree_map(lambda m, g: b1 * m + (1 - b1) * g * scale, adam["m"], grads)
        v = jax.tree_util.tree_map(
            lambda v, g: b2 * v + (1 - b2) * jnp.square(g * scale), adam["v"], grads
        )
        # PyTorch's Adam: lr / (1 - b1^t) times m / (sqrt(v) / sqrt(1 - b2^t) + eps).
        step_size = hyper[0] / (1 - b1**step)
        root = jnp.sqrt(1 - b2**step)
        new_params = jax.tree_util.tree_map(
            lambda p, m, v: p - step_size * m / (jnp.sqrt(v) / root + eps), params, m, v
        )
        new = (new_params, {"m": m, "v": v, "step": step})
        params, adam = jax.tree_util.tree_map(
            lambda a, b: jnp.where(stop, a, b), (params, adam), new
        )
        stats["done"] = jnp.logical_not(stop)
        return (params, adam, stop), stats

    @jax.jit
    def update(params: Any, adam: Any, data: Any, order: Any, hyper: Any, betas: Any) -> Any:
        def epoch(carry: Any, indices: Any) -> Any:
            return jax.lax.scan(lambda c, i: minibatch(c, i, data, hyper, betas), carry, indices)

        (params, adam, _), stats = jax.lax.scan(epoch, (params, adam, jnp.bool_(False)), order)
        return params, adam, stats

    return update
