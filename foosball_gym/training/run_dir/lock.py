"""One training at a time in a run's directory: ``train.lock``, held while a run is written.

A second training (or a second ``--resume``) into the same directory would interleave its
checkpoints and ``eval.csv`` rows with the first's, so it is refused while the first runs.
The lock is the operating system's (``flock``, through the ``filelock`` package): it ends
with the process that held it, however that ended (SIGKILL, a crash, a lost power), so a
lock left by a dead training never blocks the next one. The file itself stays (empty): it is
the lock's name, not the lock.
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from foosball_gym.training.run_dir.files import LOCK_FILE


class RunInUseError(ValueError):
    """Another training is writing the run directory."""


@contextmanager
def run_lock(run: Path) -> Iterator[None]:
    """Hold ``run``'s lock meanwhile; the directory is created where it is missing.

    Raises:
        RunInUseError: another process holds it.
        OSError: the directory cannot be written (read-only, full): the lock is its first
            write, so nothing of the run was touched.
    """
    from filelock import FileLock, Timeout

    run = Path(run)
    created = not run.exists()
    run.mkdir(parents=True, exist_ok=True)
    path = run / LOCK_FILE
    lock = FileLock(str(path), timeout=0)
    try:
        lock.acquire()
    except Timeout:
        raise RunInUseError(
            f"{run} is being written by another training, which holds {path}: wait for it "
            "to end (or train into another folder)"
        ) from None
    except BaseException:
        if created:
            shutil.rmtree(run, ignore_errors=True)
        raise
    try:
        yield
    finally:
        lock.release()
        if created and [p.name for p in run.iterdir()] == [LOCK_FILE]:
            # A start that failed before writing anything leaves no folder behind.
            shutil.rmtree(run, ignore_errors=True)
