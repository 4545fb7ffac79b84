"""The Stable-Baselines3 backend: PPO or SAC in this process, on vectorised envs.

:func:`.trainer.train` runs it: the envs (:mod:`.vec_env`), the model and its checkpoints
(:mod:`.model`), the callbacks that evaluate, checkpoint and stop it (:mod:`.callbacks`) and
record clips (:mod:`.videos`), behaviour cloning before it (:mod:`.pretrain`) and a teacher
during it (:mod:`.teacher`). Self-play's callback and envs are in
:mod:`foosball_gym.training.selfplay`, the run directory's files in
:mod:`foosball_gym.training.run_dir`.
"""
