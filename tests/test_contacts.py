"""Fast contacts keep their bounce and stop where they should (docs/simulated-table.md):
rebounds at every speed, angle and moment of contact, no tunnelling at 20 m/s, kicks whose
angle follows the offset, a ball that rolls a few metres, and no kick that throws the ball off
the table.

``benchmarks/physics_report.py`` prints the full grids; these are the cases the tests hold."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym.sim import TableSim, probes
from foosball_gym.table import BALL_RADIUS, BALL_TABLE_RESTITUTION, FIGURINE_FOOT_HEIGHT


@pytest.fixture(scope="module")
def sim():
    table = TableSim(["home_keeper"])
    yield table
    table.close()


@pytest.mark.parametrize("speed", [1.5, 3.0, 7.0, 12.0, 20.0])
@pytest.mark.parametrize("angle", [0.0, 30.0, 60.0])
def test_a_side_wall_rebound_keeps_half_the_normal_speed(sim, speed, angle):
    for phase in (0.0, 0.3, 0.7):
        ratio = probes.wall_rebound(sim, speed, angle, phase)
        assert ratio == pytest.approx(BALL_TABLE_RESTITUTION, abs=0.08), (phase, ratio)


@pytest.mark.parametrize("target", ["figurine", "wall", "post"])
def test_a_20_m_s_ball_does_not_pass_through(sim, target):
    result = probes.tunnelling(sim, 20.0, target)
    assert not result["passed"] and not result["out_of_table"]
    if target == "figurine":
        assert result["stopped"]  # turned back, not squeezed past


def test_a_corner_kick_turns_smoothly_with_the_offset(sim):
    # Over the foot's width, in 0.5 mm steps: the launch angle only grows, and the ball's
    # crossing of the away keeper's line (wall bounces unfolded) moves the same way.
    offsets = np.arange(0.0, 0.0265, 0.0005)
    kicks = [probes.corner_kick(sim, float(o)) for o in offsets]
    angles = np.array([k["angle_deg"] for k in kicks])
    assert np.diff(angles).min() > -0.5
    assert angles[0] == pytest.approx(0.0, abs=0.5) and angles[-1] > 45
    assert np.diff(angles).max() < 6.0  # degrees per 0.5 mm: no jump from a facet or an edge
    crossing = np.array([k["unfolded_y"] for k in kicks if k["unfolded_y"] is not None])
    assert len(crossing) >= len(offsets) - 2
    assert np.diff(crossing).min() > -0.005
    assert all(k["speed"] > 2.0 for k in kicks)


def test_a_rolling_ball_stops_within_three_to_seven_metres(sim):
    assert 3.0 <= probes.rolling_distance(sim, 1.0) <= 7.0


@pytest.mark.parametrize("resistance", [0.005, 0.02])
def test_rolling_resistance_sets_how_far_the_ball_rolls(resistance):
    table = TableSim(["home_keeper"], rolling_resistance=resistance)
    try:
        distance = probes.rolling_distance(table, 1.0)
    finally:
        table.close()
    # v^2 / (2 (c g + damping)), damping slowing a 1 m/s ball by about 0.01 m/s^2.
    expected = 1.0 / (2 * (resistance * 9.81 + 0.01))
    assert distance == pytest.approx(expected, rel=0.1)


def scripted_games(env_id: str, seeds: range, **kwargs):
    """Play the task's scripted policy for every seed; yields (seed, env, info) after each step."""
    env = gym.make(env_id, **kwargs)
    policy = env.unwrapped.scripted_policy()
    try:
        for seed in seeds:
            obs, _ = env.reset(seed=seed)
            done = False
            while not done:
                obs, _, terminated, truncated, info = env.step(policy(obs))
                yield seed, env.unwrapped, info
                done = terminated or truncated
    finally:
        env.close()


@pytest.mark.parametrize("ball_start", ["resting", "incoming"])
def test_a_kick_keeps_the_ball_on_the_table(ball_start):
    highest = 0.0
    for seed, env, info in scripted_games("Foosball-Score-v0", range(15), ball_start=ball_start):
        highest = max(highest, env.sim.ball_state().position[2] - BALL_RADIUS)
        assert not info["out_of_table"], seed
    # A kick may make the ball hop, never fly: its lowest point stays below the feet's soles.
    assert highest < FIGURINE_FOOT_HEIGHT + 0.005


@pytest.mark.parametrize("speed", [2.0, 6.0, 10.0])
def test_a_shot_at_a_standing_keeper_stays_on_the_table(sim, speed):
    for y in (-0.008, 0.0, 0.008):
        sim.reset(slide=[0.0], ball_position=(0.2, y), ball_velocity=(-speed, 0.0))
        for _ in range(30):
            sim.command("position", [0.0, 0.0])
            _, out = sim.step()
            assert not out
            assert sim.ball_state().position[2] - BALL_RADIUS < 0.005


def test_fine_steps_are_taken_only_near_a_contact(sim):
    # A ball rolling in the open costs the base rate; one meeting the keeper costs more.
    sim.reset(slide=[0.12], ball_position=(0.3, 0.0), ball_velocity=(-1.0, 0.0))
    before = sim.physics_steps
    sim.step()
    assert sim.physics_steps - before == sim.substeps
    sim.reset(slide=[0.0], ball_position=(-0.45, 0.0), ball_velocity=(-8.0, 0.0))
    before = sim.physics_steps
    sim.step()
    assert sim.physics_steps - before > 4 * sim.substeps


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"rolling_resistance": -0.1}, r"rolling_resistance must be a number in \[0.0, 0.5\]"),
        ({"physics_hz": 30}, r"physics_hz \(30\) must be at least control_hz \(60\)"),
        ({"physics_hz": 250}, r"whole multiple of control_hz \(60\), e.g. 240"),
        ({"contact_travel": 0.0}, r"contact_travel must be a number in \[0.0001, 0.02\] m"),
        ({"control_hz": 60.5}, "control_hz must be a positive integer"),
    ],
)
def test_bad_physics_options_name_the_option_and_the_allowed_range(kwargs, message):
    with pytest.raises(ValueError, match=message):
        TableSim(["home_keeper"], **kwargs)


def test_the_drives_never_outrun_the_speed_the_near_contact_test_assumes(monkeypatch):
    # Fine steps are chosen from a bound on how fast each rod can move within the step; if a
    # rod outran it, a foot could reach the ball in a coarse step. Random targets, a ball
    # knocking the keepers about. Speeds are watched after every physics step, in Bullet for
    # the rods near the ball and in the drive model for the others.
    rng = np.random.default_rng(0)
    table = TableSim(["home_keeper", "away_keeper"])
    peak = [0.0] * 4
    simulate = table._advance

    def simulating(world, duration, steps, watch):
        step = world.step

        def watched_step() -> None:
            step()
            worlds = table._worlds
            for j, state in zip(worlds.joints, world.joint_states(world.body, worlds.links)):
                peak[j] = max(peak[j], abs(state[1]))

        if not table._worlds.joints:
            return simulate(world, duration, steps, watch)
        world.step = watched_step
        try:
            return simulate(world, duration, steps, watch)
        finally:
            world.step = step

    advance = table._drives.advance

    def advancing(joints, dt, steps=1):
        joints = list(joints)
        for _ in range(steps):
            advance(joints, dt, 1)
            for j in joints:
                peak[j] = max(peak[j], abs(table._drives.vel[j]))

    monkeypatch.setattr(table, "_advance", simulating)
    monkeypatch.setattr(table._drives, "advance", advancing)
    worst = 0.0
    handed_to_bullet = 0
    try:
        table.reset(ball_position=(0.0, 0.0), ball_velocity=(3.0, 1.0))
        for k in range(600):
            table.command("position", [*rng.uniform(-0.12, 0.12, 2), *rng.uniform(-6.2, 6.2, 2)])
            drives = table._drives
            bounds = [
                drives.speed_bound(j, table.control_dt, table._reach.accel[j]) for j in range(4)
            ]
            peak[:] = [0.0] * 4
            table.step()
            handed_to_bullet += bool(table._worlds.simulated)
            worst = max(worst, *(p / b for p, b in zip(peak, bounds)))
            if k % 60 == 0:
                table.place_ball(rng.uniform(-0.5, 0.5, 2) * (1, 0.6), rng.uniform(-6, 6, 2))
    finally:
        table.close()
    assert worst <= 1.0 + 1e-6
    assert handed_to_bullet > 20  # the keepers met the ball, in Bullet, many times (51)


def test_scripted_full_games_keep_the_ball_on_the_table():
    # What is left: a ball hopping off the surface and struck in the air by a swinging foot, about 4
    # in 100 scripted games on this physics, 22 in 100 before (docs/simulated-table.md). Which seeds
    # lose it moves with any change to the stepping, so this allows one.
    lost = {
        seed
        for seed, _, info in scripted_games("Foosball-FullGame-v0", range(20))
        if info["out_of_table"]
    }
    assert len(lost) <= 1, lost  # with 0.05 friction on the figurines, seeds 0, 11 and 18
