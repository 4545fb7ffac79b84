"""The design stays visible: one module touches pybullet, the package imports light."""

from __future__ import annotations

import ast
import json
import re
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


def test_only_the_simulator_package_imports_pybullet_in_one_module():
    users = sorted(
        str(p.relative_to(PACKAGE))
        for p in PACKAGE.rglob("*.py")
        if {"pybullet", "pybullet_utils"} & imported_modules(p)
    )
    assert users == ["sim/worlds.py"]
    # The Bullet worlds are the simulator's own: nothing outside sim/ reaches them.
    outside = [
        str(p.relative_to(PACKAGE))
        for p in PACKAGE.rglob("*.py")
        if p.parent.name != "sim" and "foosball_gym.sim.worlds" in p.read_text()
    ]
    assert outside == []


def test_the_simulator_package_loads_pybullet_only_when_the_simulator_is_asked_for():
    code = (
        "import sys, foosball_gym.sim as sim;"
        "from foosball_gym.sim.options import check_physics;"
        "check_physics(480, 60);"
        "assert 'pybullet' not in sys.modules, 'pybullet was imported';"
        "names = {name: getattr(sim, name) for name in sim.__all__};"
        "assert names['TableSim'].__module__ == 'foosball_gym.sim.table_sim';"
        "assert 'pybullet' in sys.modules;"
        "exec('try: sim.Tablesim\\nexcept AttributeError as e: print(e)')"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "module 'foosball_gym.sim' has no attribute 'Tablesim'"


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
        "import sys; from foosball_gym.registration import task_interface;"
        "i = task_interface('Foosball-KeeperVsKeeper-v0');"
        "assert 'pybullet' not in sys.modules, 'pybullet was imported';"
        "print(len(i.builder.names))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "10"


def test_options_are_checked_without_the_simulator():
    code = (
        "import sys; from foosball_gym.registration import ENV_IDS, check_env_options;"
        "sizes = [check_env_options(i).observation_size for i in ENV_IDS];"
        "check_env_options('Foosball-FullGame-v0', {'estimated_state': True, 'residual': 0.5,"
        " 'drive_speed_range': (0.5, 1.0), 'opponent': 'scripted:1', 'render_mode': 'human'});"
        "bad = {'physics_hz': 250};"
        "exec('try: check_env_options(ENV_IDS[0], bad)\\nexcept ValueError: pass');"
        "assert 'pybullet' not in sys.modules, 'pybullet was imported';"
        # Of the simulator, only the physics options' checks, which build nothing.
        "sim = [m for m in sys.modules if m.startswith('foosball_gym.sim')];"
        "assert sim == ['foosball_gym.sim', 'foosball_gym.sim.options'], sim;"
        "print(sizes)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[6, 8, 10, 36]"


def test_the_interface_is_the_environments_own():
    import gymnasium as gym
    import numpy as np

    from foosball_gym import ENV_IDS
    from foosball_gym.registration import task_interface

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
                    u.game.targets,
                )
            )
            for joint, value in interface.action_to_targets(action).items():
                assert sim_targets[joint] == pytest.approx(value), (env_id, joint)
            env.close()


def test_hardware_vision_estimation_and_the_play_loop_do_not_import_the_simulator():
    code = (
        "import sys;"
        "import foosball_gym.real_table.hardware.drives, foosball_gym.real_table.vision;"
        "import foosball_gym.estimation;"
        "import foosball_gym.real_table.play.loop, foosball_gym.real_table.play.session;"
        "import foosball_gym.real_table.play.stack;"
        "bad = [m for m in ('pybullet', 'foosball_gym.sim') if m in sys.modules];"
        "assert not bad, bad"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def test_only_the_simulated_table_reaches_the_simulator_from_the_hardware_side():
    hardware_side = ("real_table/hardware", "real_table/vision", "estimation", "real_table/play")
    for folder in hardware_side:
        for path in (PACKAGE / folder).rglob("*.py"):
            source = path.read_text().replace("``foosball_gym.sim``", "")
            assert not re.search(r"foosball_gym\.sim\b", source), path


# Where each installed package's source lives: cli/ and urdf/ are installed into foosball_gym.
SOURCES = {
    "foosball_gym": PACKAGE,
    "foosball_gym.cli": PACKAGE.parent / "cli",
    "foosball_gym.urdf": PACKAGE.parent / "urdf",
}


def module_files(sources: dict[str, Path]) -> dict[str, Path]:
    """Every module under ``sources`` (installed name: folder), by its installed name."""
    found = {}
    for package, folder in sources.items():
        for path in folder.rglob("*.py"):
            parts = path.relative_to(folder).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join((package, *parts))] = path
    return found


def import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Which of ``modules`` each of them imports.

    Imports inside functions count: they close a cycle as surely as those at the top, only
    later. ``from a.b import c`` imports ``a.b.c`` where that is a module, else ``a.b``; the
    packages a module's parents run first are left out, as a package that imports its own
    modules is no cycle.
    """
    graph = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".")
                    parts = parts[: len(parts) - node.level + 1]
                    base = ".".join([*parts, *([node.module] if node.module else [])])
                names = [f"{base}.{alias.name}" for alias in node.names]
            else:
                continue
            for imported in names:
                while imported and imported not in modules:
                    imported = imported.rpartition(".")[0]
                if imported and imported != name:
                    targets.add(imported)
        graph[name] = targets
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """The modules along a cycle of ``graph``, the first repeated at the end; None if none."""
    on_path: list[str] = []
    done: set[str] = set()

    def visit(node: str) -> list[str] | None:
        on_path.append(node)
        for nxt in sorted(graph[node]):
            if nxt in on_path:
                return [*on_path[on_path.index(nxt) :], nxt]
            if nxt not in done:
                cycle = visit(nxt)
                if cycle:
                    return cycle
        on_path.pop()
        done.add(node)
        return None

    for node in sorted(graph):
        if node not in done:
            cycle = visit(node)
            if cycle:
                return cycle
    return None


def test_no_module_imports_itself_back_through_others():
    modules = module_files(SOURCES)
    assert {"foosball_gym.cli", "foosball_gym.cli.train", "foosball_gym.urdf.generate"} <= set(
        modules
    )
    cycle = find_cycle(import_graph(modules))
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


# Layers, lowest first: a module may import its own layer and those below, never one above.
# The real-table wing (real_table/: hardware, vision, play, virtual, sysid) stands on the ground
# floor beside the simulator; nothing outside it but the CLI imports it (see
# test_nothing_outside_the_real_table_wing_imports_it). Inside it, the drives and the camera
# (and the state estimator they share with the environments, with policy_io) never reach the
# simulator or the environments, whatever the training side does.
BELOW = {
    "foosball_gym.policy_io": {
        "foosball_gym.envs",
        "foosball_gym.sim",
        "foosball_gym.tasks",
        "foosball_gym.game",
    },
    # A task is pure: what is played, not how it is simulated or shown.
    "foosball_gym.tasks": {
        "foosball_gym.envs",
        "foosball_gym.sim",
        "foosball_gym.game",
        "foosball_gym.training",
    },
    "foosball_gym.game": {
        "foosball_gym.envs",
        "foosball_gym.training",
    },
    # The simulated table plays the game itself; it never builds an environment.
    "foosball_gym.real_table.virtual": {"foosball_gym.envs", "foosball_gym.training"},
    "foosball_gym.estimation": {
        "foosball_gym.envs",
        "foosball_gym.sim",
        "foosball_gym.training",
    },
    # The camera and the drives are the wing's floor: neither knows the other, the loop that
    # drives them, the simulated table or system identification.
    "foosball_gym.real_table.vision": {
        "foosball_gym.envs",
        "foosball_gym.sim",
        "foosball_gym.training",
        "foosball_gym.real_table.hardware",
        "foosball_gym.real_table.play",
        "foosball_gym.real_table.virtual",
        "foosball_gym.real_table.sysid",
    },
    "foosball_gym.real_table.hardware": {
        "foosball_gym.envs",
        "foosball_gym.sim",
        "foosball_gym.training",
        "foosball_gym.real_table.vision",
        "foosball_gym.real_table.play",
        "foosball_gym.real_table.virtual",
        "foosball_gym.real_table.sysid",
    },
    "foosball_gym.real_table.play": {
        "foosball_gym.envs",
        "foosball_gym.sim",
        "foosball_gym.game",
        "foosball_gym.training",
    },
    # One module owns the play-log format; its readers (replay pages, system identification)
    # read it there, not from the stack that writes it.
    "foosball_gym.session_log": {
        "foosball_gym.sim",
        "foosball_gym.envs",
        "foosball_gym.training",
    },
    "foosball_gym.replay": {
        "foosball_gym.sim",
        "foosball_gym.training",
    },
    # System identification reads logs; it neither plays (the loop, the simulated table, whose
    # calibration serves it gives) nor shows them.
    "foosball_gym.real_table.sysid": {
        "foosball_gym.real_table.play",
        "foosball_gym.real_table.virtual",
        "foosball_gym.replay",
    },
    "foosball_gym.policies": {
        "foosball_gym.envs",
        "foosball_gym.sim",
        "foosball_gym.training",
    },
    # Inside training: the run directory is the record both backends write alike, so it knows
    # neither of them; loading a policy to play needs no trainer; self-play serves both
    # backends; and each backend stands apart from the other.
    "foosball_gym.training.run_dir": {
        "foosball_gym.training.config",
        "foosball_gym.training.config_file",
        "foosball_gym.training.selfplay",
        "foosball_gym.training.sb3",
        "foosball_gym.training.rllib",
    },
    "foosball_gym.training.loading": {
        "foosball_gym.training.config",
        "foosball_gym.training.config_file",
        "foosball_gym.training.selfplay",
        "foosball_gym.training.sb3",
        "foosball_gym.training.rllib",
    },
    "foosball_gym.training.selfplay": {
        "foosball_gym.training.config",
        "foosball_gym.training.config_file",
        "foosball_gym.training.sb3",
        "foosball_gym.training.rllib",
    },
    "foosball_gym.training.sb3": {"foosball_gym.training.rllib"},
    "foosball_gym.training.rllib": {"foosball_gym.training.sb3"},
}


def test_no_module_imports_a_layer_above_its_own():
    graph = import_graph(module_files(SOURCES))
    # The check sees the state estimator reach the observation builder, from below.
    assert "foosball_gym.policy_io.observations" in graph["foosball_gym.estimation.state"]
    wrong = [
        f"{module} imports {target}"
        for module, targets in graph.items()
        for package, above in BELOW.items()
        if module == package or module.startswith(package + ".")
        for target in targets
        if any(target == a or target.startswith(a + ".") for a in above)
    ]
    assert wrong == []


def test_nothing_outside_the_real_table_wing_imports_it():
    graph = import_graph(module_files(SOURCES))
    # The check sees the wing's own arrows and the CLI's into it.
    assert "foosball_gym.real_table.hardware.config" in graph["foosball_gym.real_table.play.stack"]
    assert "foosball_gym.real_table.play.stack" in graph["foosball_gym.cli.play"]

    def inside(module: str, package: str) -> bool:
        return module == package or module.startswith(package + ".")

    wing = "foosball_gym.real_table"
    wrong = [
        f"{module} imports {target}"
        for module, targets in graph.items()
        if not inside(module, wing) and not inside(module, "foosball_gym.cli")
        for target in targets
        if inside(target, wing)
    ]
    assert wrong == []


def test_the_training_layers_are_seen_by_the_layer_check():
    graph = import_graph(module_files(SOURCES))
    # What the rules above hold apart is there to hold apart: both backends write the run
    # directory's curve, and both load policies from the package that plays them.
    for trainer in ("foosball_gym.training.sb3.callbacks", "foosball_gym.training.rllib.trainer"):
        assert "foosball_gym.training.run_dir.curve" in graph[trainer]
    assert (
        "foosball_gym.training.loading.rllib_policy" in graph["foosball_gym.training.rllib.trainer"]
    )


def test_no_training_module_is_over_500_lines():
    long = {
        str(p.relative_to(PACKAGE)): n
        for p in (PACKAGE / "training").rglob("*.py")
        if (n := len(p.read_text().splitlines())) > 500
    }
    assert long == {}


def test_loading_a_policy_imports_no_trainer(tmp_path):
    """Playing a trained policy needs neither backend's trainer nor Ray: a shipped policy, an
    SB3 model zip and an exported RLlib policy all load without them."""
    pytest.importorskip("stable_baselines3")
    pytest.importorskip("torch")
    import numpy as np

    from foosball_gym.training.loading import builtin_names, builtin_path
    from foosball_gym.training.rllib.export import export_policy

    rng = np.random.default_rng(0)
    state = {  # an RLlib PPO module's actor, as RLlib names its layers
        "encoder.actor_encoder.net.mlp.0.weight": rng.normal(size=(8, 10)),
        "encoder.actor_encoder.net.mlp.0.bias": rng.normal(size=8),
        "pi.net.mlp.0.weight": rng.normal(size=(4, 8)),
        "pi.net.mlp.0.bias": rng.normal(size=4),
    }
    export_policy(state, tmp_path / "rllib", env_id="Foosball-KeeperVsKeeper-v0", env_kwargs={})
    name = builtin_names()[0]
    specs = [f"builtin:{name}", str(builtin_path(name) / "model.zip"), str(tmp_path / "rllib")]
    code = (
        "import sys, warnings; from foosball_gym import load_policy;"
        "warnings.simplefilter('ignore');"
        "sizes = [load_policy(spec).observation_size for spec in sys.argv[1:]];"
        # The RLlib backend, a package now, was the module rllib_backend: the prefix takes both.
        "trainers = [m for m in sys.modules if m == 'ray' or m.startswith(('ray.',"
        " 'foosball_gym.training.rllib', 'foosball_gym.training.sb3'))];"
        "assert not trainers, trainers;"
        "print(sizes)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, *specs], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().endswith(", 10]")


def test_the_cycle_check_finds_a_cycle_closed_inside_a_function(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("from pkg import a\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from pkg.sub import b\n")
    (pkg / "sub" / "b.py").write_text("def later():\n    from .. import c\n")
    (pkg / "c.py").write_text("import pkg.a\n")
    assert find_cycle(import_graph(module_files({"pkg": pkg}))) == [
        "pkg.a",
        "pkg.sub.b",
        "pkg.c",
        "pkg.a",
    ]
    (pkg / "c.py").write_text("import pkg.sub\n")
    assert find_cycle(import_graph(module_files({"pkg": pkg}))) is None


# Put first in a fresh interpreter's code: torch and Stable-Baselines3 then fail to import, as
# on an installation without the train extra.
WITHOUT_TORCH = """
import sys


class _NotInstalled:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("torch", "stable_baselines3"):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None


sys.meta_path.insert(0, _NotInstalled())
try:
    import torch
except ImportError:
    pass
else:
    raise AssertionError("torch was not blocked")
"""


def run_without_torch(code: str, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", WITHOUT_TORCH + code, *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=120,
    )


def test_evaluation_and_the_scripted_eval_command_need_no_torch(tmp_path):
    code = """
from foosball_gym.registration import scripted_policy
from foosball_gym.evaluation import EvalResult, evaluate

result = evaluate(scripted_policy("Foosball-Block-v0"), "Foosball-Block-v0", episodes=2)
assert isinstance(result, EvalResult) and result.episodes == 2, result

from foosball_gym.cli import main

sys.exit(main(sys.argv[1:]))
"""
    out = tmp_path / "eval.json"
    argv = ["eval", "--policy", "scripted", "Foosball-Block-v0", "--episodes", "2"]
    done = run_without_torch(code, *argv, "--json", str(out), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "success rate" in done.stdout
    assert json.loads(out.read_text())["episodes"] == 2


def test_without_torch_the_cli_builds_and_names_the_extra_a_model_needs(tmp_path):
    code = """
from foosball_gym.cli import build_parser, main

build_parser().parse_args(["train", "Foosball-Block-v0"])
sys.exit(main(sys.argv[1:]))
"""
    done = run_without_torch(code, "eval", "builtin:block", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith("foosball eval: error:"), done.stderr
    assert 'pip install -e ".[train]"' in done.stderr and "Traceback" not in done.stderr


def test_every_package_is_listed_for_installation():
    """A package missing from setup.cfg works in an editable install and is absent from a
    real one."""
    import configparser

    config = configparser.ConfigParser()
    config.read(PACKAGE.parent / "setup.cfg")
    listed = set(config["options"]["packages"].split())
    found = {
        ".".join(("foosball_gym", *path.parent.relative_to(PACKAGE).parts))
        for path in PACKAGE.rglob("__init__.py")
    }
    assert "foosball_gym.tasks" in found
    assert found - listed == set()


# Where the modules the environments can import start: the packages that build and play the
# simulated game, and vision, whose camera estimated_state=True imitates. What they import is
# followed from here (see env_side).
ENV_ROOTS = (
    "foosball_gym.registration",
    "foosball_gym.envs",
    "foosball_gym.estimation",
    "foosball_gym.real_table.vision",
    "foosball_gym.tasks",
    "foosball_gym.game",
    "foosball_gym.policy_io",
    "foosball_gym.policies",
    "foosball_gym.sim",
    "foosball_gym.table",
)
# Packages with an extra beyond train (the real table; PettingZoo and Ray) or the training side.
OWN_EXTRAS = (
    "foosball_gym.training",
    "foosball_gym.multiagent",
    "foosball_gym.real_table.hardware",
    "foosball_gym.real_table.play",
    "foosball_gym.real_table.virtual",
)
# The import names of each distribution whose own name (lower case, - as _) is not one.
IMPORT_NAMES = {
    "opencv-python-headless": ("cv2",),
    "opencv-python": ("cv2",),
    "pyyaml": ("yaml",),
    "python-can": ("can",),
    "pybullet": ("pybullet", "pybullet_utils"),
}


def requirement_imports(setup_cfg: Path, extra: str) -> set[str]:
    """The import names of install_requires and of the extra ``extra`` in ``setup_cfg``."""
    import configparser
    import re

    config = configparser.ConfigParser(interpolation=None)
    config.read(setup_cfg)
    lines = [
        *config["options"]["install_requires"].splitlines(),
        *config["options.extras_require"][extra].splitlines(),
    ]
    names = {re.match(r"[A-Za-z0-9][\w.-]*", line.strip())[0].lower() for line in lines if line}
    return {i for name in names for i in IMPORT_NAMES.get(name, (name.replace("-", "_"),))}


def env_side() -> dict[str, Path]:
    """The modules the environments can import: ENV_ROOTS and every module they import, inside
    functions too (an option imports there)."""
    modules = module_files({"foosball_gym": PACKAGE})
    graph = import_graph(modules)
    reached, todo = (
        set(),
        [m for m in modules for r in ENV_ROOTS if m == r or m.startswith(r + ".")],
    )
    while todo:
        module = todo.pop()
        if module not in reached:
            reached.add(module)
            todo.extend(graph[module])
    return {name: modules[name] for name in reached}


def undeclared_imports(setup_cfg: Path) -> dict[str, set[str]]:
    """Each module the environments can import, with the third-party packages it imports that
    neither install_requires nor the train extra of ``setup_cfg`` installs."""
    declared = requirement_imports(setup_cfg, "train")
    missing = {
        name: {
            m
            for m in imported_modules(path)
            if m not in sys.stdlib_module_names and m != "foosball_gym" and m not in declared
        }
        for name, path in env_side().items()
    }
    return {name: found for name, found in missing.items() if found}


def test_the_environments_reach_no_package_with_an_extra_of_its_own():
    reached = env_side()
    assert {"foosball_gym.envs.block", "foosball_gym.estimation.kalman"} <= set(reached)
    outside = sorted(m for m in reached for p in OWN_EXTRAS if m == p or m.startswith(p + "."))
    assert outside == []


def test_every_environment_option_works_with_the_train_extra():
    """``pip install -e ".[train]"`` installs every third-party package the environments can
    import, estimated_state's filterpy included."""
    assert undeclared_imports(PACKAGE.parent / "setup.cfg") == {}


def test_the_extra_check_finds_a_package_the_train_extra_lacks(tmp_path):
    text = (PACKAGE.parent / "setup.cfg").read_text()
    setup_cfg = tmp_path / "setup.cfg"
    setup_cfg.write_text("\n".join(line for line in text.splitlines() if "filterpy" not in line))
    assert undeclared_imports(setup_cfg) == {"foosball_gym.estimation.kalman": {"filterpy"}}


# The packages that moved into real_table/, by their old names: foosball_gym.old_paths keeps
# those names importing for users, with a warning; the project itself no longer uses them.
OLD_PATH = re.compile(
    r"foosball_gym[./](hardware|vision|play|sysid|virtual_table)\b"
    r"|from foosball_gym import [\w, ()]*\b(hardware|vision|play|sysid|virtual_table)\b"
)
# What the project is made of (text files only), and the two files that name the old paths on
# purpose: the finder that maps them, and the test that they still import.
PROJECT = ("foosball_gym", "cli", "urdf", "tests", "benchmarks", "scripts", "docs", ".ci")
TOP_FILES = ("README.md", "mkdocs.yml", "setup.cfg", "tox.ini", "pyproject.toml", "ruff.toml")
TEXT = {".py", ".md", ".yml", ".yaml", ".cfg", ".ini", ".toml", ".ipynb", ".txt", ".sh", ""}
NAMING_THEM = {"foosball_gym/old_paths.py", "tests/test_old_paths.py"}


def old_path_uses(root: Path) -> list[str]:
    """Each ``file:line`` under ``root`` that names a moved package by its old path."""
    files = [root / name for name in TOP_FILES if (root / name).exists()]
    for folder in PROJECT:
        files += [p for p in (root / folder).rglob("*") if p.is_file() and p.suffix in TEXT]
    found = []
    for path in files:
        relative = path.relative_to(root).as_posix()
        if relative in NAMING_THEM or "__pycache__" in path.parts:
            continue
        for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            if OLD_PATH.search(line):
                found.append(f"{relative}:{number}")
    return found


def test_nothing_in_the_project_uses_an_old_path():
    assert old_path_uses(PACKAGE.parent) == []


def test_the_old_path_check_finds_an_old_path(tmp_path):
    package = "foosball_gym"  # written apart, so this file does not name an old path itself
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "page.md").write_text(f"::: {package}.real_table.vision\n")
    (tmp_path / "cli").mkdir()
    (tmp_path / "cli" / "play.py").write_text(
        f"import {package}.real_table.play\nfrom {package} import table, vision\n"
    )
    (tmp_path / "mkdocs.yml").write_text(f"- {package}/virtual_table/drive.py\n")
    assert old_path_uses(tmp_path) == ["mkdocs.yml:1", "cli/play.py:2"]
