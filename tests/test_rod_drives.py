"""A rod the ball cannot reach moves by the drive model (foosball_gym/sim/drives.py), one it
may meet moves in Bullet: both must move it the same, end stops and all three control modes
included, or a rod would change its course as the ball came near."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from foosball_gym import table
from foosball_gym.sim import TableSim
from foosball_gym.sim.drives import RodDrives

RODS = ["home_keeper", "away_midfield", "home_defense", "away_offense"]


def _targets(mode: str, rng: np.random.Generator) -> list[float]:
    n = len(RODS)
    if mode == "position":  # beyond the end stops too: the drives run into them
        return [*rng.uniform(-0.2, 0.2, n), *rng.uniform(-7.0, 7.0, n)]
    if mode == "velocity":
        return [*rng.uniform(-5.0, 5.0, n), *rng.uniform(-400.0, 400.0, n)]
    return [*rng.uniform(-80.0, 80.0, n), *rng.uniform(-1.6, 1.6, n)]


@pytest.mark.parametrize("mode", ["position", "velocity", "torque"])
def test_a_rod_moves_the_same_in_bullet_and_in_the_drive_model(mode):
    # Each control step starts both from Bullet's state: that is what a rod handed from one to
    # the other carries over. (Over many steps at the end stops the two drift apart: Bullet's
    # iterative solver leaves 1e-5 rad/s there, and a stop met a step earlier or later
    # changes what follows.)
    sim = TableSim(RODS)
    try:
        # The ball waits far from every figurine while all four rods move in Bullet.
        sim.reset(ball_position=(0.3, 0.0))
        world = sim._worlds.use(tuple(range(len(RODS))), sim._ball_full, sim._materials())
        bullet = sim._drives
        model = copy.deepcopy(bullet)
        rng = np.random.default_rng(1)
        base = 1.0 / sim.physics_hz
        worst = 0.0
        stops = 0
        for k in range(300):
            if mode != "torque" or k % 6 == 0:  # torques run on for a while, into the stops
                targets = _targets(mode, rng)
                sim.command(mode, targets)
                model.command(mode, targets)
            model.pos[:], model.vel[:] = bullet.pos, bullet.vel
            for _ in range(sim.substeps):
                sim._advance(world, base, 1, watch=True)
                sim._worlds.take_rods()
                model.advance(range(model.n), base)
                stops += sum(
                    not lo < q < hi for q, lo, hi in zip(model.pos, model.lower, model.upper)
                )
            worst = max(worst, *(abs(a - b) for a, b in zip(bullet.pos, model.pos)))
    finally:
        sim.close()
    assert stops > 10  # the end stops were met
    assert worst < 1e-6, worst  # 1.4e-7 to 1.9e-7, at the stops


def test_a_spinning_rod_swings_under_gravity_with_its_drive_off():
    # The figurines hang below the axis: with no torque a rod turned sideways swings back.
    sim = TableSim(["home_midfield"])
    try:
        sim.reset(spin=[math.pi / 2])
        sim.command("torque", [0.0, 0.0])
        for _ in range(10):
            sim.step()
        _, vel = sim.joint_states()
        assert vel[1] < -0.5  # falling back towards feet-down
    finally:
        sim.close()


def test_bad_drive_model_settings_are_refused():
    with pytest.raises(ValueError, match="gains needs one value per joint"):
        RodDrives(
            mass=[1.0, 1.0],
            gravity=[0.0, 0.0],
            max_force=[1.0, 1.0],
            max_speed=[1.0, 1.0],
            lower=[-1.0, -1.0],
            upper=[1.0, 1.0],
            gains=[1.0],
            erp_rate=table.PHYSICS_HZ * 0.01,
        )
    drives = RodDrives(
        mass=[1.0],
        gravity=[0.0],
        max_force=[1.0],
        max_speed=[1.0],
        lower=[-1.0],
        upper=[1.0],
        gains=[1.0],
        erp_rate=2.4,
    )
    with pytest.raises(ValueError, match="position, velocity, torque"):
        drives.command("force", [0.0])
