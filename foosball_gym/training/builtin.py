"""Trained policies shipped with the package, loadable as ``builtin:NAME``."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from foosball_gym.training.run import MODEL_FILE


def _root() -> Path:
    return Path(str(resources.files("foosball_gym") / "builtin"))


def builtin_names() -> list[str]:
    root = _root()
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if (p / MODEL_FILE).exists())


def builtin_path(name: str) -> Path:
    """The run directory of the shipped policy ``name``."""
    from foosball_gym.training.models import ModelLoadError

    names = builtin_names()
    if name not in names:
        raise ModelLoadError(
            f"no built-in policy {name!r}; shipped: {', '.join(names) if names else 'none'}"
        )
    return _root() / name
