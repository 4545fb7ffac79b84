"""The lost branch of a run killed after its last checkpoint, set aside where it resumes.

A run killed (SIGKILL, a crash, a lost power) between two checkpoints has recorded
evaluations, a best model and clips of the steps after its last checkpoint; resumed, it
trains those steps again, and would record them twice. :func:`set_aside_lost_branch` moves
what was recorded after the checkpoint into ``lost/after_<steps>/`` before it does, so that
the run's own records rise step by step and describe the models it keeps; nothing is
deleted. Self-play's generations are set aside by
:func:`~foosball_gym.training.selfplay.history.set_aside_generations`, into the same folder.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

from foosball_gym.training.run_dir.best import read_best
from foosball_gym.training.run_dir.curve import EvalCurve, csv_text, plot_curve
from foosball_gym.training.run_dir.files import (
    BEST_DIR,
    EVAL_CSV,
    LOST_DIR,
    VIDEO_DIR,
    write_bytes,
)

_VIDEO = re.compile(r"step_(\d+)\.mp4")


def lost_branch_dir(run: Path, timesteps: int) -> Path:
    """A folder of ``lost/`` not used yet, for the branch lost after ``timesteps``."""
    base = Path(run) / LOST_DIR / f"after_{timesteps:010d}"
    found, k = base, 1
    while found.exists():
        k += 1
        found = base.with_name(f"{base.name}_{k}")
    return found


def set_aside_lost_branch(run: Path, timesteps: int, lost: Path, title: str) -> list[str]:
    """Move what the run in ``run`` recorded after ``timesteps`` into ``lost``: its rows of
    ``eval.csv``, its ``best/`` where a later evaluation earned it, and its clips.

    Args:
        run: the run directory.
        timesteps: the steps of the checkpoint the run resumes from.
        lost: where the branch goes (:func:`lost_branch_dir`), made where anything is moved.
        title: the curve's title, for ``eval.png`` drawn again.

    Returns:
        What was set aside, in words (empty: nothing was recorded past the checkpoint).
    """
    run = Path(run)
    moved = []
    curve = EvalCurve(run, title)
    rows = [r for r in curve.rows() if r["timesteps"] > timesteps]
    if rows:
        lost.mkdir(parents=True, exist_ok=True)
        write_bytes(lost / EVAL_CSV, csv_text(rows, header=True).encode())
        curve.cut(timesteps)
        moved.append(f"{len(rows)} rows of {EVAL_CSV}")
        try:
            plot_curve(curve.csv, curve.png, title)
        except ImportError:
            pass
    best = read_best(run)
    if best is not None and best["timesteps"] > timesteps:
        lost.mkdir(parents=True, exist_ok=True)
        shutil.move(run / BEST_DIR, lost / BEST_DIR)
        moved.append(f"{BEST_DIR}/ (of {int(best['timesteps'])} steps)")
    videos = run / VIDEO_DIR
    clips = [
        clip
        for clip in (sorted(videos.iterdir()) if videos.is_dir() else [])
        if (m := _VIDEO.fullmatch(clip.name)) and int(m.group(1)) > timesteps
    ]
    if clips:
        (lost / VIDEO_DIR).mkdir(parents=True, exist_ok=True)
        for clip in clips:
            shutil.move(clip, lost / VIDEO_DIR / clip.name)
        moved.append(f"{len(clips)} clips")
    return moved
