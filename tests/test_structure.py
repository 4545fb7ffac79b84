"""The design stays visible: one module touches pybullet, the package imports light."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

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


def test_a_tasks_interface_is_built_without_the_simulator():
    code = (
        "import sys; from foosball_gym.envs.interface import task_interface;"
        "i = task_interface('Foosball-KeeperVsKeeper-v0');"
        "assert 'pybullet' not in sys.modules, 'pybullet was imported';"
        "print(len(i.builder.names))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "10"


def test_the_interface_is_the_environments_own():
    import gymnasium as gym
    import numpy as np

    from foosball_gym import ENV_IDS
    from foosball_gym.envs.interface import task_interface

    for env_id in ENV_IDS:
        for kwargs in ({}, {"joint_velocities": False}):
            env = gym.make(env_id, **kwargs)
            interface = task_interface(env_id, kwargs)
            assert interface.builder.names == env.unwrapped.obs_builder.names
            env.reset(seed=0)
            action = np.linspace(-1.2, 0.9, env.action_space.shape[0])
            env.step(action.astype(np.float32))
            u = env.unwrapped
            sim_targets = dict(
                zip(
                    [(r, "slide") for r in u.layout.rods] + [(r, "spin") for r in u.layout.rods],
                    u._targets,
                )
            )
            for joint, value in interface.action_to_targets(action).items():
                assert sim_targets[joint] == pytest.approx(value), (env_id, joint)
            env.close()


def test_hardware_vision_estimation_and_the_play_loop_do_not_import_the_simulator():
    code = (
        "import sys;"
        "import foosball_gym.hardware.drives, foosball_gym.vision, foosball_gym.estimation;"
        "import foosball_gym.play.loop, foosball_gym.play.session, foosball_gym.play.stack;"
        "bad = [m for m in ('pybullet', 'foosball_gym.simulator') if m in sys.modules];"
        "assert not bad, bad"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def test_only_the_simulated_table_reaches_the_simulator_from_the_hardware_side():
    hardware_side = ("hardware", "vision", "estimation", "play")
    for folder in hardware_side:
        for path in (PACKAGE / folder).rglob("*.py"):
            source = path.read_text()
            assert "foosball_gym.simulator" not in source.replace(
                "``foosball_gym.simulator``", ""
            ), path
