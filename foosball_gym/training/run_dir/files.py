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
    train.lock             held by the training that writes the run (see :mod:`.lock`)
    lost/after_<steps>/    what a run killed after its last checkpoint had recorded past it,
                           set aside when it resumed (see :mod:`.branch`)

A model zip written since its statistics went into it holds them (:mod:`.storage`); runs from
before kept them beside it in ``vecnormalize.json``, and runs from before plain files as
``vecnormalize.pkl``, a pickle, read only where trusted.

Imports nothing of the package, so whatever reads or writes a run (training, loading, the
CLI, the shipped policies) takes the names from here.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
from pathlib import Path
from typing import Any

from foosball_gym import user_json

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
LOCK_FILE = "train.lock"
LOST_DIR = "lost"

SB3_BACKEND = "sb3"
RLLIB_BACKEND = "rllib"

# What a start that failed may leave in a run directory without a checkpoint; a new start
# clears it so that its curve, best model and opponents are its own.
STALE = (EVAL_CSV, EVAL_PNG, PRETRAIN_FILE, BEST_DIR, SELFPLAY_DIR, VIDEO_DIR, CHECKPOINT_DIR)


def has_checkpoint(run: Path) -> bool:
    """Whether the run in ``run`` can be resumed: it has a checkpoint or a final model."""
    return (run / CHECKPOINT_DIR / LATEST_FILE).exists() or (run / MODEL_FILE).exists()


def read_json(path: Path, kind: type, what: str) -> Any:
    """The JSON in ``path``, which must be a ``kind`` (dict or list); ValueError in one line
    naming the file and ``what`` it should hold otherwise."""
    try:
        value = user_json.loads(Path(path).read_text(encoding="utf-8"))
    except ValueError as err:
        raise ValueError(f"{path} is not valid JSON ({err}): it should hold {what}") from None
    if not isinstance(value, kind):
        raise ValueError(
            f"{path} holds a JSON {type(value).__name__}, not the "
            f"{'object' if kind is dict else 'list'} of {what}"
        )
    return value


def read_latest(run: Path) -> dict[str, Any] | None:
    """What ``checkpoints/latest.json`` says of the run's last checkpoint; None if none.

    Raises:
        ValueError: the file is damaged (the message names it).
    """
    path = run / CHECKPOINT_DIR / LATEST_FILE
    if not path.is_file():
        return None
    pointer = read_json(path, dict, "the run's last checkpoint")
    steps = pointer.get("timesteps")
    if not isinstance(steps, int) or isinstance(steps, bool) or steps < 0:
        raise ValueError(f"{path}: timesteps must be a whole number, 0 or more, got {steps!r}")
    for key in ("model", "vecnormalize", "checkpoint", "replay"):
        if key in pointer and (not isinstance(pointer[key], str) or "/" in pointer[key]):
            raise ValueError(f"{path}: {key} must name a file in {CHECKPOINT_DIR}/")
    return pointer


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
    """The backend that trained the run in ``run`` ("sb3" where config.json names none).

    Raises:
        ValueError: config.json is damaged, or names no backend of this package.
    """
    path = Path(run) / CONFIG_FILE
    if not path.is_file():
        return SB3_BACKEND
    backend = read_json(path, dict, "a run's configuration").get("backend", SB3_BACKEND)
    if backend not in (SB3_BACKEND, RLLIB_BACKEND):
        raise ValueError(
            f"{path}: backend must be {SB3_BACKEND} or {RLLIB_BACKEND}, got {backend!r}"
        )
    return str(backend)


# What a run's directory can fail with that is the file system's, not the run's: a message
# says so in one line (see :func:`storage_error`).
STORAGE_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EIO)


def storage_error(err: OSError) -> bool:
    """Whether ``err`` is the storage's refusal (full, read-only, not permitted)."""
    return err.errno in STORAGE_ERRNOS


def write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file beside it, so that a reader never
    sees half of it, and nothing is left behind where it fails (a full disk): the temporary
    file is removed and the OSError names ``path``."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    try:
        _write_file(tmp, data)
        tmp.replace(path)
    except BaseException as err:
        tmp.unlink(missing_ok=True)
        if isinstance(err, OSError) and err.filename is None:
            raise OSError(err.errno, err.strerror, str(path)) from None
        raise


def _write_file(path: Path, data: bytes) -> None:
    # Apart, so that a test can make it fail as a full disk does: part written, then ENOSPC.
    with open(path, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` as :func:`write_bytes` does."""
    write_bytes(path, text.encode())


def append_text(path: Path, text: str) -> None:
    """Append ``text`` to ``path``, all of it or (where the write fails) none of it."""
    path = Path(path)
    size = path.stat().st_size if path.exists() else None
    try:
        with open(path, "a") as f:
            f.write(text)
            f.flush()
    except BaseException:
        if size is None:
            path.unlink(missing_ok=True)
        else:
            with open(path, "r+b") as f:
                f.truncate(size)
        raise
