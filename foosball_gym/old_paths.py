"""Old import paths, kept working for one release.

``foosball_gym.hardware``, ``vision``, ``play``, ``sysid`` and ``virtual_table`` moved into
:mod:`foosball_gym.real_table`; ``foosball_gym.physics_options`` and ``physics_probes`` into
:mod:`foosball_gym.sim` as ``options`` and ``probes``. Importing one of them by its old name, or
any module inside it (``foosball_gym.vision.detectors``), gives the module at its new path, the
very same object, so a class has one identity whichever name imported it, and warns with a
:class:`DeprecationWarning` naming the new path, pointing at the import (once per statement:
``import foosball_gym.vision.detectors`` names the package). Nothing is loaded twice: the old name
is only an entry in :data:`sys.modules` pointing at the module the new name loaded.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from collections.abc import Sequence
from types import FrameType, ModuleType

#: Each moved package or module: its old name, its new one.
MOVED = {
    "foosball_gym.hardware": "foosball_gym.real_table.hardware",
    "foosball_gym.vision": "foosball_gym.real_table.vision",
    "foosball_gym.play": "foosball_gym.real_table.play",
    "foosball_gym.sysid": "foosball_gym.real_table.sysid",
    "foosball_gym.virtual_table": "foosball_gym.real_table.virtual",
    "foosball_gym.physics_options": "foosball_gym.sim.options",
    "foosball_gym.physics_probes": "foosball_gym.sim.probes",
}


def new_name(name: str) -> str | None:
    """The module's name at its new path, if ``name`` is an old one; else None."""
    for old, new in MOVED.items():
        if name == old or name.startswith(old + "."):
            return new + name[len(old) :]
    return None


def _importer() -> tuple[FrameType, int]:
    """The frame of the code that imported an old name, and its stack level as warnings.warn
    counts from :meth:`_Alias.create_module`, for the warning to point at that code.

    warnings.warn steps over the import system's own frames (``importlib._bootstrap``) without
    counting them; this module's frames and :func:`importlib.import_module`'s count.
    """
    import_module = importlib.__file__
    frame, level = sys._getframe(2), 1  # create_module's frame: stack level 1
    while frame.f_back is not None:
        frame = frame.f_back
        name = frame.f_code.co_filename
        if "importlib" in name and "_bootstrap" in name:
            continue
        level += 1
        if name not in (__file__, import_module):
            break
    return frame, level


#: Each old name loaded, with the import statement that loaded it (its frame's id and the
#: instruction): ``import foosball_gym.vision.detectors`` warns for the package only.
_loaded_by: dict[str, tuple[int, int]] = {}


class _Alias(importlib.abc.Loader):
    """Loads an old name as the module its new name loads."""

    def __init__(self, new: str) -> None:
        self.new = new
        self.spec: importlib.machinery.ModuleSpec | None = None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        module = importlib.import_module(self.new)
        # The import system sets the module's __spec__ to the old name's; exec_module puts its
        # own back.
        self.spec = module.__spec__
        frame, level = _importer()
        statement = (id(frame), frame.f_lasti)
        del frame
        if _loaded_by.get(spec.name.rpartition(".")[0]) != statement:
            warnings.warn(
                f"{spec.name} has moved to {self.new}; import it from there "
                f"(the old path goes in the next release)",
                DeprecationWarning,
                stacklevel=level,
            )
        _loaded_by[spec.name] = statement
        return module

    def exec_module(self, module: ModuleType) -> None:
        module.__spec__ = self.spec


class OldPathFinder(importlib.abc.MetaPathFinder):
    """Finds the old names of the moved packages and their modules (see the module docstring)."""

    def find_spec(
        self,
        fullname: str,
        path: Sequence[str] | None = None,
        target: ModuleType | None = None,
    ) -> importlib.machinery.ModuleSpec | None:
        new = new_name(fullname)
        if new is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, _Alias(new))


def install() -> None:
    """Put the finder first on :data:`sys.meta_path`, once."""
    if not any(isinstance(finder, OldPathFinder) for finder in sys.meta_path):
        sys.meta_path.insert(0, OldPathFinder())
