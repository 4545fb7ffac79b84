"""The files of a training run's directory: their names, and how they are written.

A run directory holds::

    config.json            the resolved configuration (what --resume reads back), and under
                           "physics" the physics the run was trained on (see config.physics_record)
    model.zip              the final model (SB3)
    vecnormalize.pkl       observation-normalisation statistics, if used
    checkpoints/           periodic checkpoints, written atomically; latest.json names the last
    eval.csv, eval.png     the evaluation curve: success rate and reward against timesteps
    best/                  the model of the best evaluation so far
    tb/                    TensorBoard logs
    selfplay/              opponent snapshots and history.json (self-play runs)

Imports nothing, so whatever reads or writes a run (training, loading, the CLI, the shipped
policies) takes the names from here.
"""

from __future__ import annotations

from pathlib import Path

CONFIG_FILE = "config.json"
MODEL_FILE = "model.zip"
NORM_FILE = "vecnormalize.pkl"
BEST_DIR = "best"


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file, so a reader never sees half of it."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)
