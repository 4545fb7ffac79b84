"""Converting a run from before plain model files into one that loads without unpickling.

Such a run keeps its normalisation statistics in ``vecnormalize.pkl`` files, its model zips
carry SB3's pickled fields, and its self-play snapshots hold a pickled policy. Converting
reads those pickles once, so it runs only for a run whose source is trusted.
"""

from __future__ import annotations

import json
from pathlib import Path

from foosball_gym.training.loading.sb3_snapshot import PolicySnapshot
from foosball_gym.training.run_dir.files import (
    CHECKPOINT_DIR,
    LATEST_FILE,
    LEGACY_NORM_FILE,
    NORM_FILE,
    read_latest,
    write_latest,
)
from foosball_gym.training.run_dir.lock import run_lock
from foosball_gym.training.run_dir.storage import (
    SERIALIZED,
    load_pickled_norm,
    read_entry,
    strip_pickles,
)


def _holds_pickles(zip_path: Path) -> bool:
    import zipfile

    with zipfile.ZipFile(zip_path) as archive:
        data = json.loads(read_entry(archive, "data")) if "data" in archive.namelist() else {}
    return any(isinstance(v, dict) and SERIALIZED in v for v in data.values())


def migrate_run(run: str | Path, trust: bool = False) -> list[Path]:
    """Rewrite every pickle of the run directory ``run`` as plain data.

    ``vecnormalize.pkl`` files become ``vecnormalize.json`` (the pickles are removed and
    ``checkpoints/latest.json`` names the new files), model zips lose their pickled fields, and
    self-play snapshots are saved again as tensors. Running it on a converted run changes
    nothing.

    Args:
        run: the run directory.
        trust: required: converting unpickles the run's files, which runs whatever code they
            hold.

    Returns:
        The files written, in the order they were.

    Raises:
        ValueError: ``trust`` is False, ``run`` is not a directory, or a training is writing
            it (:class:`~foosball_gym.training.run_dir.lock.RunInUseError`).
    """
    run = Path(run)
    if not trust:
        raise ValueError(
            f"migrating {run} unpickles its files, which runs any code they hold: give "
            "--trust-model if you trust where the run comes from"
        )
    if not run.is_dir():
        raise ValueError(f"{run} is not a run directory")
    with run_lock(run):  # not while a training writes it
        return _migrate(run)


def _migrate(run: Path) -> list[Path]:
    written: list[Path] = []
    for legacy in sorted(run.rglob(f"*{LEGACY_NORM_FILE}")):
        target = legacy.with_name(legacy.name[: -len(LEGACY_NORM_FILE)] + NORM_FILE)
        load_pickled_norm(legacy).save(target)
        legacy.unlink()
        written.append(target)
    pointer = read_latest(run)
    if pointer is not None:
        name = pointer.get("vecnormalize", "")
        if name.endswith(LEGACY_NORM_FILE):
            pointer["vecnormalize"] = name[: -len(LEGACY_NORM_FILE)] + NORM_FILE
            write_latest(run, pointer)
            written.append(run / CHECKPOINT_DIR / LATEST_FILE)
    for zip_path in sorted(run.rglob("*.zip")):
        if _holds_pickles(zip_path):
            strip_pickles(zip_path)
            written.append(zip_path)
    for snapshot in sorted(run.rglob("opponent_*.pt")):
        try:
            PolicySnapshot.load(snapshot)
        except ValueError:
            PolicySnapshot.load(snapshot, trust=True).save(snapshot)
            written.append(snapshot)
    return written
