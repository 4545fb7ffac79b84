"""The table URDF: what it holds matches the spec, it is up to date and it ships in the wheel
(with the CLI, installed from cli/ the same way)."""

from __future__ import annotations

import math
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import yourdfpy

from foosball_gym import table
from foosball_gym.sim import TableSim
from foosball_gym.sim.urdf import urdf_path

ROOT = Path(__file__).resolve().parents[1]
URDF_DIR = ROOT / "urdf"

# The paper's rods, written out again on purpose: a change to table.py must be a change to this too.
PAPER_RODS = {
    "home_keeper": (-0.52200, 1, 0.1230),
    "home_defense": (-0.37295, 2, 0.1790),
    "away_offense": (-0.22372, 3, 0.1185),
    "home_midfield": (-0.07469, 5, 0.0615),
    "away_midfield": (0.07469, 5, 0.0615),
    "home_offense": (0.22372, 3, 0.1185),
    "away_defense": (0.37295, 2, 0.1790),
    "away_keeper": (0.52200, 1, 0.1230),
}


@pytest.fixture(scope="module")
def urdf() -> yourdfpy.URDF:
    return yourdfpy.URDF.load(str(urdf_path()), load_meshes=False, build_scene_graph=False)


def test_urdf_has_two_joints_per_rod_with_spec_limits(urdf):
    movable = {n: j for n, j in urdf.joint_map.items() if j.type != "fixed"}
    assert len(movable) == 16
    for name, (x, _, slide_limit) in PAPER_RODS.items():
        slide, spin = movable[f"{name}_slide"], movable[f"{name}_spin"]
        assert slide.type == "prismatic" and spin.type == "revolute"
        assert slide.limit.lower == pytest.approx(-slide_limit)
        assert slide.limit.upper == pytest.approx(slide_limit)
        assert slide.limit.effort == pytest.approx(70.0)
        assert slide.limit.velocity == pytest.approx(4.0)
        assert spin.limit.lower == pytest.approx(-2 * math.pi, rel=1e-5)
        assert spin.limit.upper == pytest.approx(2 * math.pi, rel=1e-5)
        assert spin.limit.effort == pytest.approx(1.41)
        assert spin.limit.velocity == pytest.approx(100 * math.pi, rel=1e-5)
        assert slide.origin[0, 3] == pytest.approx(x)
        assert slide.origin[2, 3] == pytest.approx(0.083)


def test_urdf_has_22_figurines_at_spec_offsets(urdf):
    figurines = [n for n in urdf.link_map if "_figurine_" in n]
    assert len(figurines) == 22
    for name, (_, count, _) in PAPER_RODS.items():
        mounts = [j for n, j in urdf.joint_map.items() if n.startswith(f"{name}_figurine_")]
        assert len(mounts) == count
        offsets = sorted(round(j.origin[1, 3], 4) for j in mounts)
        assert offsets == sorted(round(o, 4) for o in table.rod(name).figurine_offsets)
        for j in mounts:
            # The full 30 x 34 mm body from 0.040 m above the surface to the head, 0.040 m
            # above the axis; below it the slim leg down to the foot, 0.011 m above the surface.
            body, leg = urdf.link_map[j.child].collisions
            centre = 0.083 + j.origin[2, 3]
            assert tuple(body.geometry.box.size) == pytest.approx((0.030, 0.034, 0.083))
            assert centre + body.origin[2, 3] - 0.083 / 2 == pytest.approx(0.040)
            assert centre + body.origin[2, 3] + 0.083 / 2 == pytest.approx(0.083 + 0.040)
            assert Path(leg.geometry.mesh.filename).name == "figurine_leg.obj"
            assert centre + leg.origin[2, 3] == pytest.approx(0.0)  # the mesh is in heights


def test_the_leg_has_the_cad_figurines_cross_sections():
    vertices = np.array(
        [
            [float(v) for v in line.split()[1:]]
            for line in (URDF_DIR / "figurine_leg.obj").read_text().splitlines()
            if line.startswith("v ")
        ]
    )
    assert vertices[:, 2].min() == pytest.approx(0.011)  # the sole
    assert vertices[:, 2].max() == pytest.approx(0.040)
    assert vertices[:, 1].min() == pytest.approx(-0.012) and vertices[:, 1].max() == pytest.approx(
        0.012
    )
    for height, x0, x1 in ((0.012, -0.0025, 0.0029), (0.017, -0.0045, 0.0048)):
        section = vertices[np.isclose(vertices[:, 2], height)]
        assert section[:, 0].min() == pytest.approx(x0) and section[:, 0].max() == pytest.approx(x1)
        # Full thickness out to |y| = 9 mm, then narrowing to a point at 12 mm.
        flat = section[np.abs(section[:, 1]) <= 0.009 + 1e-9]
        assert np.ptp(flat[:, 0]) == pytest.approx(x1 - x0)
        tips = section[np.isclose(np.abs(section[:, 1]), 0.012)]
        assert len(tips) == 2 and np.ptp(tips[:, 0]) == pytest.approx(0.0)
        # Between them the ends are round: every point lies on or inside the ellipse through
        # the corners and the tip, so no facet sticks out.
        mid, half = (x0 + x1) / 2, (x1 - x0) / 2
        end = section[np.abs(section[:, 1]) > 0.009 + 1e-9]
        ellipse = ((end[:, 0] - mid) / half) ** 2 + ((np.abs(end[:, 1]) - 0.009) / 0.003) ** 2
        np.testing.assert_allclose(ellipse, 1.0, atol=1e-3)  # 6 digits in the file
        assert len(end) >= 20  # finely faceted


def test_away_rods_are_turned_half_a_turn(urdf):
    for name in PAPER_RODS:
        yaw_cos = urdf.joint_map[f"{name}_slide"].origin[0, 0]
        assert yaw_cos == pytest.approx(1.0 if name.startswith("home") else -1.0)


def test_committed_urdf_is_what_the_generator_writes():
    sys.path.insert(0, str(ROOT))
    from urdf import generate

    assert (ROOT / "urdf" / generate.TABLE_FILE).read_text() == generate.table_urdf()
    assert (ROOT / "urdf" / generate.BALL_FILE).read_text() == generate.ball_urdf()
    assert (ROOT / "urdf" / generate.LEG_FILE).read_text() == generate.leg_obj()


def test_urdf_loads_in_pybullet_with_every_rod():
    sim = TableSim([r.name for r in table.RODS])
    try:
        view = sim._view_world()  # the whole table, as it is drawn
        assert view.client.getNumJoints(view.body) == 16  # figurines merged into their rods
    finally:
        sim.close()


def test_wheel_ships_the_urdf_and_the_cli_and_an_installed_copy_runs(tmp_path):
    """Build a wheel, install it without the source tree on the path, make an env and list
    the environments through the installed CLI."""
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(tmp_path),
            str(ROOT),
        ],
        check=True,
    )
    wheel = next(tmp_path.glob("foosball_gym-*.whl"))
    with zipfile.ZipFile(wheel) as zf:
        names = zf.namelist()
    assert "foosball_gym/urdf/foosball_table.urdf" in names
    assert "foosball_gym/urdf/ball.urdf" in names
    assert "foosball_gym/urdf/figurine_leg.obj" in names
    assert "foosball_gym/policies/deflection_table.npz" in names
    assert "foosball_gym/rl_zoo/ppo.yml" in names
    shipped_cli = {n for n in names if n.startswith("foosball_gym/cli/")}
    assert shipped_cli == {f"foosball_gym/cli/{p.name}" for p in (ROOT / "cli").glob("*.py")}
    site = tmp_path / "site"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--no-deps",
            "-q",
            "--target",
            str(site),
            str(wheel),
        ],
        check=True,
    )
    code = (
        "import foosball_gym, gymnasium as gym, sys;"
        "assert foosball_gym.__file__.startswith(sys.argv[1]), foosball_gym.__file__;"
        "env = gym.make('Foosball-Block-v0'); env.reset(seed=0); env.step([0.0]);"
        "env = gym.make('Foosball-Score-v0', ball_start='incoming'); obs, _ = env.reset(seed=0);"
        "env.step(env.unwrapped.scripted_policy()(obs));"
        "import foosball_gym.cli as cli;"
        "assert cli.__file__.startswith(sys.argv[1]), cli.__file__;"
        "assert cli.main(['envs']) == 0;"
        "print('ok')"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, str(site)],
        cwd=tmp_path,
        env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0, out.stderr
    assert "ok" in out.stdout


def test_table_urdfs_rewritten_between_two_envs_do_not_change_the_second(tmp_path, monkeypatch):
    """Bullet loads a URDF from a file: another user who rewrites one that a first env left
    in the temp folder must not change the table of the next."""
    import tempfile
    import xml.etree.ElementTree as ET

    import gymnasium as gym

    from foosball_gym.sim.urdf import urdf_with_rods

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    urdf_with_rods.cache_clear()  # nothing from before this test's temp folder

    def shot_at_the_keeper() -> int:
        env = gym.make("Foosball-Block-v0")
        env.reset(options={"ball_position": (-0.3, 0.0), "ball_velocity": (-4.0, 0.0)})
        for _ in range(60):
            _, _, terminated, _, info = env.step([0.0])
            if terminated:
                break
        env.close()
        return info["goal"]

    assert shot_at_the_keeper() == 0  # blocked
    left = list(tmp_path.rglob("*.urdf"))
    for path in left:  # the keeper without a collision shape, were it read again
        tree = ET.parse(path)
        for link in tree.getroot().iter("link"):
            if link.get("name", "").startswith("home_keeper"):
                for collision in link.findall("collision"):
                    link.remove(collision)
        tree.write(path)
    assert shot_at_the_keeper() == 0
    assert left == []


def test_the_urdf_bullet_reads_is_in_a_folder_only_its_user_opens_and_gone_after():
    import os
    import stat

    from foosball_gym.sim.urdf import urdf_file, urdf_with_rods

    text = urdf_with_rods(("home_keeper",))
    with urdf_file(text) as path:
        folder = os.stat(os.path.dirname(path))
        assert stat.S_IMODE(folder.st_mode) == 0o700 and folder.st_uid == os.getuid()
        assert Path(path).read_text() == text
    assert not os.path.exists(os.path.dirname(path))
