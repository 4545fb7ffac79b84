"""The old import paths of the real-table packages and of the simulator's options and probes still
work for a release, and say where they went."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

from foosball_gym.old_paths import MOVED, new_name

# A module of each moved package (or the moved module itself), by its old name; the name that
# moved; something defined in the module.
OLD_MODULES = [
    ("foosball_gym.hardware.config", "foosball_gym.hardware", "JointConfig"),
    ("foosball_gym.vision.projection", "foosball_gym.vision", "CameraCalibration"),
    ("foosball_gym.play.session", "foosball_gym.play", "SessionLog"),
    ("foosball_gym.sysid.logs", "foosball_gym.sysid", "PlayLog"),
    ("foosball_gym.virtual_table.drive_states", "foosball_gym.virtual_table", "next_state"),
    ("foosball_gym.physics_options", "foosball_gym.physics_options", "check_physics"),
    ("foosball_gym.physics_probes", "foosball_gym.physics_probes", "volley"),
]


@pytest.fixture
def old_names_unloaded():
    """The old names out of sys.modules, before and after, so each import finds them anew; the
    modules at the new paths stay loaded."""

    def unload():
        for name in [n for n in sys.modules if new_name(n)]:
            del sys.modules[name]
        for old in MOVED:
            package, _, attribute = old.rpartition(".")
            sys.modules[package].__dict__.pop(attribute, None)

    unload()
    yield
    unload()


def test_every_moved_name_is_tried():
    assert {moved for _, moved, _ in OLD_MODULES} == set(MOVED)


@pytest.mark.parametrize(("old", "package", "attribute"), OLD_MODULES)
def test_an_old_path_warns_and_gives_the_module_at_its_new_path(
    old, package, attribute, old_names_unloaded
):
    if old.startswith("foosball_gym.vision"):
        pytest.importorskip("cv2")
    new = new_name(old)
    assert new is not None and new.startswith(("foosball_gym.real_table.", "foosball_gym.sim."))
    with pytest.warns(DeprecationWarning) as warned:
        module = importlib.import_module(old)
    # One warning for the statement, naming where the name went, pointing at the importer.
    assert [str(w.message) for w in warned] == [
        f"{package} has moved to {MOVED[package]}; import it from there "
        "(the old path goes in the next release)"
    ]
    assert warned[0].filename == __file__
    # One module, not a copy: its classes are the same objects whichever name imported them.
    assert module is importlib.import_module(new)
    assert getattr(module, attribute) is getattr(sys.modules[new], attribute)
    assert module.__name__ == module.__spec__.name == new
    assert sys.modules[package] is sys.modules[MOVED[package]]


def test_a_module_imported_later_by_its_old_path_warns_for_itself(old_names_unloaded):
    with pytest.warns(DeprecationWarning, match="foosball_gym.hardware has moved"):
        import foosball_gym.hardware  # noqa: F401
    with pytest.warns(DeprecationWarning) as warned:
        from foosball_gym.hardware.config import JointConfig
    assert [str(w.message).split(";")[0] for w in warned] == [
        "foosball_gym.hardware.config has moved to foosball_gym.real_table.hardware.config"
    ]
    from foosball_gym.real_table.hardware.config import JointConfig as Joint

    assert JointConfig is Joint


def test_from_an_old_package_import_gives_the_same_class(old_names_unloaded):
    with pytest.warns(DeprecationWarning, match="foosball_gym.real_table.hardware"):
        from foosball_gym.hardware import TableConfig, load_config
    from foosball_gym.real_table.hardware import TableConfig as Table
    from foosball_gym.real_table.hardware import shipped_table

    assert TableConfig is Table
    # An object made at either path is an instance of the class at the other.
    assert isinstance(load_config(shipped_table()), Table)


def test_other_names_are_left_to_the_usual_finders(old_names_unloaded):
    assert new_name("foosball_gym.hardwares") is None
    assert new_name("foosball_gym.real_table.vision") is None
    with pytest.warns(DeprecationWarning), pytest.raises(ModuleNotFoundError, match="no_such"):
        importlib.import_module("foosball_gym.hardware.no_such_module")


def test_the_new_paths_do_not_warn_and_load_no_old_name():
    """Every module of the wing, imported in a fresh interpreter: none warns of a moved path,
    and none loads one under its old name."""
    code = """
import importlib, pkgutil, sys, warnings
warnings.simplefilter("always")
with warnings.catch_warnings(record=True) as caught:
    import foosball_gym.real_table as wing
    names = [m.name for m in pkgutil.walk_packages(wing.__path__, wing.__name__ + ".")]
    for name in names:
        importlib.import_module(name)
moved = [str(w.message) for w in caught if "has moved to" in str(w.message)]
assert not moved, moved
from foosball_gym.old_paths import new_name
old = [m for m in sys.modules if new_name(m)]
assert not old, old
print(len(names))
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert int(done.stdout) > 30
