"""The design stays visible: one module touches pybullet, the package imports light."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "foosball_gym"


def imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def test_only_the_simulator_module_imports_pybullet():
    users = sorted(
        str(p.relative_to(PACKAGE))
        for p in PACKAGE.rglob("*.py")
        if {"pybullet", "pybullet_utils"} & imported_modules(p)
    )
    assert users == ["simulator.py"]


def test_importing_the_package_needs_no_torch_and_registers_the_ids():
    code = (
        "import sys, gymnasium as gym, foosball_gym;"
        "assert 'torch' not in sys.modules and 'stable_baselines3' not in sys.modules;"
        "assert all(i in gym.registry for i in foosball_gym.ENV_IDS);"
        "print(len(foosball_gym.ENV_IDS))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
