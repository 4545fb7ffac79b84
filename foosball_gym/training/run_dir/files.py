"""The files of a training run's directory: their names, and how they are written.

A run directory, of either backend, holds::

    config.json            the resolved configuration (what --resume reads back), under
                           "physics" the physics the run was trained on (see .physics), and
                           under "backend" the backend that trained it (rllib; none: sb3)
    model.zip              sb3: the final model (SB3's zip without its pickled fields)
    vecnormalize.json      sb3: observation-normalisation statistics, if used, as plain numbers
    policy.pt, policy.json rllib: the final policy, tensors and their description
    checkpoints/           periodic checkpoints (and one on Ctrl-C), written atomically;
                           latest.json names the last
    eval.csv, eval.png     the evaluation curve: success rate and reward against timesteps
    best/                  the model of the best evaluation so far
    tb/                    TensorBoard logs
    selfplay/              opponent snapshots and history.json (self-play runs)
    videos/                sb3: step_<timesteps>.mp4 clips of the policy (with --video-every)
    league.json, .png      the league's ratings (``foosball league``, self-play runs)

Runs from before plain files stored the statistics as ``vecnormalize.pkl``, a pickle, read
only where trusted (see :mod:`.storage`).

Imports nothing of the package, so whatever reads or writes a run (training, loading, the
CLI, the shipped policies) takes the names from here.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

CONFIG_FILE = "config.json"
MODEL_FILE = "model.zip"
NORM_FILE = "vecnormalize.json"
LEGACY_NORM_FILE = "vecnormalize.pkl"
POLICY_FILE = "policy.pt"
POLICY_INFO_FILE = "policy.json"
BEST_DIR = "best"
BEST_RECORD = "best.json"
CHECKPOINT_DIR = "checkpoints"
LATEST_FILE = "latest.json"
EVAL_CSV = "eval.csv"
EVAL_PNG = "eval.png"
PRETRAIN_FILE = "pretrain.json"
SELFPLAY_DIR = "selfplay"
HISTORY_FILE = "history.json"
VIDEO_DIR = "videos"
TB_DIR = "tb"

SB3_BACKEND = "sb3"
RLLIB_BACKEND = "rllib"

# What a start that failed may leave in a run directory without a checkpoint; a new start
# clears it so that its curve, best model and opponents are its own.
STALE = (EVAL_CSV, EVAL_PNG, PRETRAIN_FILE, BEST_DIR, SELFPLAY_DIR, VIDEO_DIR, CHECKPOINT_DIR)


def has_checkpoint(run: Path) -> bool:
    """Whether the run in ``run`` can be resumed: it has a checkpoint or a final model."""
    return (run / CHECKPOINT_DIR / LATEST_FILE).exists() or (run / MODEL_FILE).exists()


def read_latest(run: Path) -> dict[str, Any] | None:
    """What ``checkpoints/latest.json`` says of the run's last checkpoint; None if none."""
    path = run / CHECKPOINT_DIR / LATEST_FILE
    return json.loads(path.read_text()) if path.is_file() else None


def write_latest(run: Path, pointer: dict[str, Any]) -> None:
    """Name the checkpoint just written as the run's last."""
    atomic_write_text(run / CHECKPOINT_DIR / LATEST_FILE, json.dumps(pointer))


def clear_stale(run: Path) -> None:
    """Remove what a failed start left in ``run`` (:data:`STALE`)."""
    for name in STALE:
        stale = run / name
        if stale.is_dir():
            shutil.rmtree(stale)
        elif stale.exists():
            stale.unlink()


def read_backend(run: str | Path) -> str:
    """The backend that trained the run in ``run`` ("sb3" where config.json names none)."""
    path = Path(run) / CONFIG_FILE
    if not path.is_file():
        return SB3_BACKEND
    return json.loads(path.read_text()).get("backend", SB3_BACKEND)


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file, so a reader never sees half of it."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)
