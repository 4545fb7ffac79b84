"""Loading trained policies: from a run directory, a model zip, or a shipped name.

The policies shipped with the package live in ``foosball_gym/builtin/NAME/``, one run
directory each, and load as ``builtin:NAME``.
"""

from __future__ import annotations

import json
import pickle
import warnings
import zipfile
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from foosball_gym.training.config import PhysicsMismatchWarning, physics_mismatch
from foosball_gym.training.files import CONFIG_FILE, MODEL_FILE, NORM_FILE
from foosball_gym.training.run import ALGOS
from foosball_gym.training.snapshot import PolicySnapshot

__all__ = [
    "LoadedPolicy",
    "ModelLoadError",
    "PhysicsMismatchWarning",
    "builtin_names",
    "builtin_path",
    "load_policy",
]


class ModelLoadError(ValueError):
    """A model could not be found or read; the message says which and why."""


@dataclass
class LoadedPolicy:
    policy: PolicySnapshot
    env_id: str | None
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    source: str = ""


def _builtin_root() -> Path:
    return Path(str(resources.files("foosball_gym") / "builtin"))


def builtin_names() -> list[str]:
    """The names of the shipped policies, sorted."""
    root = _builtin_root()
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if (p / MODEL_FILE).exists())


def builtin_path(name: str) -> Path:
    """The run directory of the shipped policy ``name``.

    Raises:
        ModelLoadError: no policy of that name is shipped; the message lists those that are.
    """
    names = builtin_names()
    if name not in names:
        raise ModelLoadError(
            f"no built-in policy {name!r}; shipped: {', '.join(names) if names else 'none'}"
        )
    return _builtin_root() / name


def load_policy(spec: str | Path) -> LoadedPolicy:
    """Load a policy from a run directory, a model ``.zip``, or ``builtin:NAME``.

    The environment id and options come from the run's ``config.json`` (next to the zip, or
    one level up for a checkpoint); a bare zip without one loads with ``env_id=None``.

    Warns with :class:`PhysicsMismatchWarning` where the model was trained on another physics
    revision than the current one; a model without a record (a run from before runs recorded
    it, or a bare zip) counts as revision 1.
    """
    text = str(spec)
    if text.startswith("builtin:"):
        path = builtin_path(text.split(":", 1)[1])
    else:
        path = Path(text)
    if path.is_dir():
        run_dir, zip_path = path, path / MODEL_FILE
        if not zip_path.exists():
            raise ModelLoadError(f"{path} is a directory without {MODEL_FILE}: not a run")
    else:
        zip_path = path
        run_dir = path.parent
    if not zip_path.exists():
        raise ModelLoadError(f"no model at {zip_path}")
    config = _find_config(run_dir)
    algo = (config or {}).get("algo")
    candidates = [ALGOS[algo]] if algo in ALGOS else list(ALGOS.values())
    model, errors = None, []
    for cls in candidates:
        try:
            model = cls.load(zip_path, device="cpu")
            break
        except (
            zipfile.BadZipFile,
            KeyError,
            ValueError,
            RuntimeError,
            EOFError,
            pickle.UnpicklingError,
            AttributeError,
            TypeError,
        ) as err:
            errors.append(f"{cls.__name__}: {type(err).__name__}: {err}")
    if model is None:
        raise ModelLoadError(
            f"cannot read {zip_path} as a Stable-Baselines3 model ({'; '.join(errors)})"
        )
    norm = _find_norm(zip_path, run_dir)
    if norm is not None:
        try:
            with open(norm, "rb") as f:
                stats = pickle.load(f)
            snapshot = PolicySnapshot(
                model.policy, stats.obs_rms.mean, stats.obs_rms.var, stats.clip_obs, stats.epsilon
            )
        except Exception as err:  # noqa: BLE001 - any unreadable file gets the same message
            raise ModelLoadError(f"cannot read normalisation statistics {norm}: {err}") from err
    else:
        snapshot = PolicySnapshot(model.policy)
    mismatch = physics_mismatch(config, f"the model {text}")
    if mismatch:
        warnings.warn(mismatch, PhysicsMismatchWarning, stacklevel=2)
    return LoadedPolicy(
        policy=snapshot,
        env_id=(config or {}).get("env_id"),
        env_kwargs=dict((config or {}).get("env_kwargs", {})),
        source=str(path),
    )


def _find_config(run_dir: Path) -> dict[str, Any] | None:
    for candidate in (run_dir / CONFIG_FILE, run_dir.parent / CONFIG_FILE):
        if candidate.exists():
            try:
                return json.loads(candidate.read_text())
            except json.JSONDecodeError as err:
                raise ModelLoadError(f"{candidate} is not valid JSON: {err}") from err
    return None


def _find_norm(zip_path: Path, run_dir: Path) -> Path | None:
    for candidate in (zip_path.with_name(f"{zip_path.stem}_{NORM_FILE}"), run_dir / NORM_FILE):
        if candidate.exists():
            return candidate
    return None
