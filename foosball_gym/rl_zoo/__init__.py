"""RL Zoo (rl_zoo3) hyperparameter files for every environment, in RL Zoo's own format.

``rl_zoo3.train -conf FILE`` reads them; :func:`hyperparams_file` gives the path of the
shipped one of an algorithm. ``python -m foosball_gym.rl_zoo SCRIPT ARGS`` runs an RL Zoo
script with the environment ids registered, for the scripts that take no ``--gym-packages``
(``record_video``). RL Zoo itself comes with the ``zoo`` extra; this module needs nothing.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

#: The algorithms a hyperparameter file is shipped for.
ALGOS: tuple[str, ...] = ("ppo",)


def hyperparams_file(algo: str = "ppo") -> Path:
    """The shipped RL Zoo hyperparameter file of ``algo``: one entry per environment id.

    Args:
        algo: RL Zoo's name of the algorithm (its ``--algo``).

    Raises:
        ValueError: no file is shipped for ``algo``; the message names those there are.
    """
    if algo not in ALGOS:
        raise ValueError(
            f"no RL Zoo hyperparameters are shipped for {algo!r}; shipped: {', '.join(ALGOS)}"
        )
    return Path(str(resources.files(__name__) / f"{algo}.yml"))
