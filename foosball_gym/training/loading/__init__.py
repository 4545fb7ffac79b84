"""Loading trained policies to play or to rate: :func:`load_policy` reads a run directory of
either backend, a model zip of any SB3 or sb3-contrib algorithm that acts on continuous
actions, an RL Zoo run, or ``builtin:NAME``; :func:`sb3_objects` and :func:`sb3_normalize` load this
package's model zips with Stable-Baselines3's own ``load``.

Needs PyTorch and Stable-Baselines3 (the ``train`` extra), and never imports a trainer or Ray.
"""

from foosball_gym.training.loading.loader import (
    LoadedPolicy,
    ModelLoadError,
    builtin_names,
    builtin_path,
    load_policy,
)
from foosball_gym.training.loading.sb3_load import sb3_normalize, sb3_objects
from foosball_gym.training.run_dir.physics import PhysicsMismatchWarning, UnknownPhysicsWarning

__all__ = [
    "LoadedPolicy",
    "ModelLoadError",
    "PhysicsMismatchWarning",
    "UnknownPhysicsWarning",
    "builtin_names",
    "builtin_path",
    "load_policy",
    "sb3_normalize",
    "sb3_objects",
]
