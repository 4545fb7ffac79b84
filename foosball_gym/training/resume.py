"""Resuming a run, for either backend: what it recorded past its last checkpoint set aside."""

from __future__ import annotations

from pathlib import Path

from foosball_gym.training.run_dir.branch import lost_branch_dir, set_aside_lost_branch
from foosball_gym.training.run_dir.files import SELFPLAY_DIR
from foosball_gym.training.selfplay.history import set_aside_generations


def set_aside_after(out: Path, steps: int, title: str) -> Path | None:
    """Set aside what the run in ``out`` recorded after the checkpoint of ``steps`` it resumes
    from (:mod:`~foosball_gym.training.run_dir.branch`), self-play's generations included,
    and say so; the folder it went to (None: nothing was recorded past the checkpoint)."""
    lost = lost_branch_dir(out, steps)
    moved = set_aside_lost_branch(out, steps, lost, title)
    generations = set_aside_generations(out / SELFPLAY_DIR, steps, lost / SELFPLAY_DIR)
    if generations:
        moved.append(f"{generations} self-play generations")
    if not moved:
        return None
    print(
        f"resuming {out} from its checkpoint of {steps} steps: what it recorded after it "
        f"({', '.join(moved)}) is set aside in {lost}"
    )
    return lost
