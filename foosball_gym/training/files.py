"""The files of a training run's directory: their names, and how they are written.

A run directory holds::

    config.json            the resolved configuration (what --resume reads back), and under
                           "physics" the physics the run was trained on (see config.physics_record)
    model.zip              the final model (SB3's zip without its pickled fields)
    vecnormalize.json      observation-normalisation statistics, if used, as plain numbers
    checkpoints/           periodic checkpoints (and one on Ctrl-C), written atomically;
                           latest.json names the last
    eval.csv, eval.png     the evaluation curve: success rate and reward against timesteps
    best/                  the model of the best evaluation so far
    tb/                    TensorBoard logs
    selfplay/              opponent snapshots and history.json (self-play runs)
    videos/                step_<timesteps>.mp4 clips of the policy (with --video-every)
    league.json, .png      the league's ratings (``foosball league``, self-play runs)

Runs from before plain files stored the statistics as ``vecnormalize.pkl``, a pickle, read
only where trusted (see :mod:`.storage`).

Imports nothing, so whatever reads or writes a run (training, loading, the CLI, the shipped
policies) takes the names from here.
"""

from __future__ import annotations

from pathlib import Path

CONFIG_FILE = "config.json"
MODEL_FILE = "model.zip"
NORM_FILE = "vecnormalize.json"
LEGACY_NORM_FILE = "vecnormalize.pkl"
BEST_DIR = "best"
CHECKPOINT_DIR = "checkpoints"
LATEST_FILE = "latest.json"


def has_checkpoint(run: Path) -> bool:
    """Whether the run in ``run`` can be resumed: it has a checkpoint or a final model."""
    return (run / CHECKPOINT_DIR / LATEST_FILE).exists() or (run / MODEL_FILE).exists()


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file, so a reader never sees half of it."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)
