"""Where a run directory keeps what loading a policy reads: the model to play of a run that did
not finish, the run's configuration, and its normalisation statistics."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from foosball_gym import user_json
from foosball_gym.training.run_dir.best import read_best
from foosball_gym.training.run_dir.files import (
    BEST_DIR,
    CHECKPOINT_DIR,
    CONFIG_FILE,
    LEGACY_NORM_FILE,
    MODEL_FILE,
    NORM_FILE,
    read_latest,
)


class ModelLoadError(ValueError):
    """A model could not be found or read; the message says which and why."""


def unfinished_run_model(run: Path) -> tuple[Path, str]:
    """The model to play of a run without a final ``model.zip`` (stopped by Ctrl-C, killed, or
    still training): its best model, else its newest checkpoint; and a line saying which.

    Raises:
        ModelLoadError: it has neither: it is no run of this package, nor any other kind
            :func:`load_policy` reads.
    """
    best = run / BEST_DIR / MODEL_FILE
    if best.is_file():
        try:
            row = read_best(run)
        except ValueError:
            row = None  # the model is there; what earned it is only told
        earned = (
            f" (success {row['success_rate']:.0%} at {int(row['timesteps']):,} steps)"
            if row
            else ""
        )
        return best, f"{run} has no {MODEL_FILE}: playing its best model, {best}{earned}"
    checkpoint = _newest_checkpoint(run)
    if checkpoint is not None:
        return checkpoint, (
            f"{run} has no {MODEL_FILE} nor {BEST_DIR}/{MODEL_FILE}: playing its newest "
            f"checkpoint, {checkpoint}"
        )
    raise ModelLoadError(
        f"{run} is a directory without {MODEL_FILE}, {BEST_DIR}/{MODEL_FILE} or a checkpoint: "
        "not a run of foosball_gym, nor an RL Zoo run (<env>/args.yml), nor an exported RLlib "
        "policy"
    )


def _newest_checkpoint(run: Path) -> Path | None:
    """The checkpoint ``checkpoints/latest.json`` names, or where it is missing or damaged, the
    one of most steps (their names count the steps with leading zeros)."""
    try:
        latest = read_latest(run)
    except ValueError:
        latest = None
    if latest is not None and "model" in latest:
        named = run / CHECKPOINT_DIR / latest["model"]
        if named.is_file():
            return named
    found = sorted((run / CHECKPOINT_DIR).glob("*.zip"))
    return found[-1] if found else None


def find_config(run_dir: Path) -> dict[str, Any] | None:
    """The run's ``config.json`` (beside the zip or one level up), checked as far as loading
    a model reads it; ModelLoadError in one line where it is damaged."""
    from foosball_gym.envs.options import check_residual

    for candidate in (run_dir / CONFIG_FILE, run_dir.parent / CONFIG_FILE):
        if candidate.exists():
            try:
                config = user_json.loads(candidate.read_text())
            except (ValueError, UnicodeDecodeError) as err:
                raise ModelLoadError(f"{candidate} is not valid JSON: {err}") from None
            if not isinstance(config, dict):
                raise ModelLoadError(
                    f"{candidate} holds a JSON {type(config).__name__}, not a run's "
                    "configuration (an object)"
                )
            env_id, env_kwargs = config.get("env_id"), config.get("env_kwargs", {})
            problem = None
            if env_id is not None and not isinstance(env_id, str):
                problem = f"env_id must be an environment id, got {env_id!r}"
            elif not isinstance(env_kwargs, dict):
                problem = f"env_kwargs must be an object of options, got {env_kwargs!r}"
            elif not isinstance(config.get("normalize", True), bool):
                problem = f"normalize must be true or false, got {config['normalize']!r}"
            else:
                try:
                    check_residual(env_kwargs.get("residual", 0.0))
                except ValueError as err:
                    problem = f"env_kwargs: {err}"
            if problem:
                raise ModelLoadError(f"{candidate} is damaged: {problem}")
            return config
    return None


def _norm_candidates(zip_path: Path, run_dir: Path) -> list[Path]:
    candidates = [zip_path.with_name(f"{zip_path.stem}_{name}") for name in NORM_NAMES]
    return candidates + [run_dir / name for name in NORM_NAMES]


def find_norm(zip_path: Path, run_dir: Path) -> Path | None:
    """The model's own statistics (a checkpoint's) before the run's; at each place the plain
    file before a legacy pickle, so a pickle beside a plain file is never read."""
    return next((c for c in _norm_candidates(zip_path, run_dir) if c.exists()), None)


def find_norm_names(zip_path: Path, run_dir: Path) -> str:
    return " or ".join(str(c) for c in _norm_candidates(zip_path, run_dir)[::2])


NORM_NAMES = (NORM_FILE, LEGACY_NORM_FILE)
