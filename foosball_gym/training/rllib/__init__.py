"""Self-play PPO on Ray RLlib: sampling spread over env runners, on one machine or a cluster.

The two-player task is played as its PettingZoo game (:mod:`foosball_gym.multiagent`) on
RLlib's multi-agent API. One module, ``learner``, plays ``home`` and is trained; ``away`` is
played by frozen snapshots of it, ``opponent_<generation>``, drawn per episode from a pool
(:mod:`.opponent_pool`). The pool follows the rule of the Stable-Baselines3 backend
(:mod:`foosball_gym.training.selfplay.rule`): once the learner wins at least
``selfplay_threshold`` (20 %) of the last ``selfplay_window`` games (or, with
``selfplay_rule="net_score"``, its net score exceeds it), a snapshot of the learner joins the
pool, which keeps the last ``selfplay_pool`` of them.

A run directory is laid out as an SB3 run's (see :mod:`foosball_gym.training.run_dir.files`)::

    config.json            the TrainConfig, with "backend": "rllib" and "num_workers"
    policy.pt, policy.json the learned home policy (see below): what `foosball eval` loads
    checkpoints/           step_<timesteps>/ (learner.pt, optimizer.pt, policy.pt/.json);
                           latest.json names the last
    selfplay/              opponent_<generation>.pt and history.json
    eval.csv, eval.png     the evaluation curve against the env's scripted opponent
    best/                  the policy of the best evaluation so far
    tb/                    TensorBoard scalars (where tensorboard is installed)

The policy is written without pickle (:mod:`.export`) and read without Ray
(:mod:`foosball_gym.training.loading.rllib_policy`).

Differences from the SB3 backend: PPO only, two-player tasks only (self-play is the point);
observations are not normalised (RLlib's MeanStdFilter would feed the frozen opponents the
away side's running statistics, not those they were trained with), so ``normalize`` is
recorded as false, and so are ``normalize_reward`` and ``fused_adam`` (rewards are not scaled;
the optimiser is RLlib's own Adam, ``adam_eps`` recorded as null, and its update its own,
``learner`` recorded as torch); ``target_kl`` and
``pretrain_episodes`` are not supported; resuming keeps
the weights, the optimiser's state, the pool and the curve.

:func:`.trainer.train_rllib` runs it. Needs the ``distributed`` extra:
``pip install -e ".[distributed]"``.
"""
