"""The simulated table behaves like a table: goals count, fast balls are stopped, drives obey
their limits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from foosball_gym import table
from foosball_gym.sim import AWAY_SCORED, HOME_SCORED, NO_GOAL, TableSim
from foosball_gym.sim.table_sim import inside_walls


@pytest.fixture
def keeper_sim():
    sim = TableSim(["home_keeper"])
    yield sim
    sim.close()


def run(sim: TableSim, steps: int, targets=None):
    """Step until a goal or the ball leaves; returns (goal, out, steps taken)."""
    for k in range(steps):
        if targets is not None:
            sim.command("position", targets)
        goal, out = sim.step()
        if goal != NO_GOAL or out:
            return goal, out, k + 1
    return NO_GOAL, False, steps


def test_shot_into_the_empty_goal_is_a_goal(keeper_sim):
    keeper_sim.reset(
        slide=[table.rod("home_keeper").slide_limit],
        ball_position=(0.0, -0.05),
        ball_velocity=(-5.0, 0.0),
    )
    goal, out, steps = run(keeper_sim, 60)
    assert goal == AWAY_SCORED and not out
    # 0.56 m to the goal line at 5 m/s takes about 7 control steps.
    assert 6 <= steps <= 9


def test_shot_into_the_away_goal_counts_for_home():
    sim = TableSim(["away_keeper"])
    try:
        sim.reset(slide=[0.12], ball_position=(0.0, 0.05), ball_velocity=(4.0, 0.0))
        goal, _, _ = run(sim, 60)
        assert goal == HOME_SCORED
    finally:
        sim.close()


def test_shot_beside_the_goal_is_no_goal(keeper_sim):
    keeper_sim.reset(ball_position=(0.0, 0.2), ball_velocity=(-5.0, 0.0))
    xs, vxs = [], []
    for _ in range(15):
        goal, out = keeper_sim.step()
        assert goal == NO_GOAL and not out
        x, _, vx, _ = keeper_sim.ball_xy()
        xs.append(x)
        vxs.append(vx)
    assert min(xs) >= -table.FIELD_HALF_LENGTH + table.BALL_RADIUS - 2e-3
    assert vxs[-1] > 1.0  # bounced back off the end wall


@pytest.mark.parametrize("speed", [10.0, 15.0, 20.0])
def test_fast_shot_at_the_keeper_is_blocked(keeper_sim, speed):
    keeper_sim.reset(slide=[0.0], ball_position=(0.3, 0.0), ball_velocity=(-speed, 0.0))
    goal, out, _ = run(keeper_sim, 90)
    assert goal != AWAY_SCORED and not out
    x, _, _, _ = keeper_sim.ball_xy()
    assert x > table.rod("home_keeper").x


@pytest.mark.parametrize("speed", [10.0, 15.0])
def test_fast_ball_grazing_a_figurine_is_deflected_not_passed_through(keeper_sim, speed):
    # The ball's centre passes 25 mm beside the figurine's: their edges overlap by 9 mm.
    keeper_sim.reset(slide=[0.0], ball_position=(0.3, 0.025), ball_velocity=(-speed, 0.0))
    deflected = False
    for _ in range(8):
        keeper_sim.step()
        _, _, vx, vy = keeper_sim.ball_xy()
        deflected |= abs(vy) > 0.3 or vx > 0
    assert deflected


def test_ball_passing_beside_a_figurine_is_not_touched(keeper_sim):
    keeper_sim.reset(slide=[0.0], ball_position=(0.3, 0.036), ball_velocity=(-15.0, 0.0))
    for _ in range(4):
        keeper_sim.step()
    _, y, vx, vy = keeper_sim.ball_xy()
    assert y == pytest.approx(0.036, abs=1e-4) and vy == pytest.approx(0.0, abs=1e-3)


@pytest.mark.parametrize("speed", [5.0, 15.0, 20.0])
def test_ball_bounces_off_a_side_wall_and_stays_on_the_table(keeper_sim, speed):
    keeper_sim.reset(slide=[0.12], ball_position=(0.3, 0.0), ball_velocity=(0.0, speed))
    ys = []
    for _ in range(30):
        goal, out = keeper_sim.step()
        assert goal == NO_GOAL and not out
        x, y, vx, vy = keeper_sim.ball_xy()
        ys.append(y)
        z = keeper_sim.ball_state().position[2]
        # A ball overlaps a wall by at most the travel allowed per physics step near a wall,
        # twice that near a figurine.
        assert abs(y) <= table.FIELD_HALF_WIDTH - table.BALL_RADIUS + 2 * table.CONTACT_TRAVEL
        assert -1e-3 <= z <= table.OUT_OF_TABLE_HEIGHT
    assert max(ys) > 0.30  # it reached the wall ...
    assert ys[-1] < max(ys)  # ... and came back


@pytest.mark.parametrize("speed", [15.0, 20.0])
def test_fast_ball_at_the_end_wall_beside_the_goal_stays_on_the_table(keeper_sim, speed):
    keeper_sim.reset(slide=[0.0], ball_position=(0.3, 0.25), ball_velocity=(speed, 0.0))
    for _ in range(30):
        goal, out = keeper_sim.step()
        assert goal == NO_GOAL and not out
        x, y, _, _ = keeper_sim.ball_xy()
        assert abs(x) <= table.FIELD_HALF_LENGTH


def test_ball_thrown_upwards_is_out_of_table(keeper_sim):
    keeper_sim.reset(ball_position=(0.2, 0.0, 0.05), ball_velocity=(0.0, 0.0, 3.0))
    goal, out, _ = run(keeper_sim, 30)
    assert out and goal == NO_GOAL


@pytest.mark.parametrize(
    "position, velocity",
    [
        ((0.0, 0.2), (0.0, 250.0)),  # through a side wall: far faster than the table is built for
        ((0.2, 0.0, -0.05), (0.0, 0.0)),  # under the surface
        ((0.0, 0.5), (0.0, 0.0)),  # beside the table
        ((0.64, 0.2), (0.0, 0.0)),  # in the end wall beside the goal
    ],
)
def test_a_ball_outside_the_walls_is_out_of_the_table(keeper_sim, position, velocity):
    keeper_sim.reset(ball_position=position, ball_velocity=velocity)
    assert run(keeper_sim, 5) == (NO_GOAL, True, 1)


def test_the_table_holds_the_field_the_goal_mouths_and_their_pockets():
    r = table.BALL_RADIUS
    inside = [
        (0.0, 0.0, r),
        (table.BALL_LIMIT_X, table.BALL_LIMIT_Y, r),
        (-table.GOAL_LINE_X, 0.08, r),  # in the mouth
        (table.POCKET_BACK_X - r, -0.08, r),  # in the pocket
        (0.3, 0.1, table.OUT_OF_TABLE_HEIGHT - 0.01),  # in the air
    ]
    outside = [
        (0.0, table.FIELD_HALF_WIDTH + table.WALL_THICKNESS, r),  # past a side wall's middle
        (table.GOAL_LINE_X + 0.01, 0.2, r),  # in the end wall beside the goal
        (table.POCKET_BACK_X + 0.015, 0.0, r),  # through the pocket's back
        (table.GOAL_LINE_X + 0.03, 0.0, table.GOAL_HEIGHT + 0.03),  # through the pocket's roof
        (0.0, 0.0, -0.02),  # through the surface
        (0.0, 0.0, table.OUT_OF_TABLE_HEIGHT + 0.01),  # flown off
        (5.0, 0.0, r),
    ]
    assert all(inside_walls(*p) for p in inside)
    assert not any(inside_walls(*p) for p in outside)


def test_ball_rolling_slowly_keeps_rolling_straight(keeper_sim):
    keeper_sim.reset(slide=[0.12])
    keeper_sim.place_ball((0.3, -0.2), (-0.5, 0.0), rolling=True)
    run(keeper_sim, 30)
    x, y, vx, vy = keeper_sim.ball_xy()
    assert x < 0.3 - 0.2 and abs(y + 0.2) < 1e-3
    assert -0.5 < vx < -0.4  # a little rolling loss, no skid


def test_a_shot_slides_until_the_table_makes_it_roll(keeper_sim):
    # Sliding friction (0.1) slows it by about 1 m/s^2 until, after 0.15 s, it rolls at 5/7 of
    # its speed; from then on only rolling resistance (0.1 m/s^2) slows it.
    keeper_sim.reset(slide=[0.12], ball_position=(0.3, -0.2), ball_velocity=(-0.5, 0.0))
    speeds = []
    for _ in range(30):
        keeper_sim.step()
        speeds.append(-keeper_sim.ball_xy()[2])
    assert speeds[0] == pytest.approx(0.5 - 0.98 / 60, abs=0.005)
    assert 0.5 * 5 / 7 - 0.06 < speeds[-1] < 0.5 * 5 / 7
    assert (speeds[-11] - speeds[-1]) * 6 < 0.2  # m/s^2 over the last 10 steps


def test_keeper_reaches_its_target_within_the_drive_limits(keeper_sim):
    keeper_sim.reset()
    target = 0.1
    speeds, positions = [], []
    for _ in range(30):
        keeper_sim.command("position", [target, 0.0])
        keeper_sim.step()
        pos, vel = keeper_sim.joint_states()
        positions.append(pos[0])
        speeds.append(abs(vel[0]))
    assert abs(positions[-1] - target) < 1e-3
    assert max(speeds) <= table.SLIDE_MAX_SPEED + 1e-6
    assert max(positions) < target + 2e-3  # no overshoot worth the name
    reached = next(i for i, p in enumerate(positions) if abs(p - target) < 2e-3)
    # 0.1 m at up to 4 m/s with 70 N: about a tenth of a second.
    assert reached * keeper_sim.control_dt < 0.15


def test_position_targets_are_clamped_to_the_joint_limits(keeper_sim):
    keeper_sim.reset()
    for _ in range(40):
        keeper_sim.command("position", [1.0, 100.0])
        keeper_sim.step()
    pos, _ = keeper_sim.joint_states()
    assert pos[0] == pytest.approx(table.rod("home_keeper").slide_limit, abs=1e-3)
    assert pos[1] == pytest.approx(table.SPIN_LIMIT, abs=0.02)


def test_velocity_control_moves_at_the_commanded_speed_up_to_the_drive_limit(keeper_sim):
    keeper_sim.reset(slide=[-0.12])
    keeper_sim.command("velocity", [1.0, 0.0])
    for _ in range(6):
        keeper_sim.step()
    _, vel = keeper_sim.joint_states()
    assert vel[0] == pytest.approx(1.0, abs=0.02)
    keeper_sim.command("velocity", [50.0, 0.0])  # beyond the drive: clamped to 4 m/s
    keeper_sim.reset(slide=[-0.12])
    keeper_sim.command("velocity", [50.0, 0.0])
    keeper_sim.step()
    _, vel = keeper_sim.joint_states()
    assert 0 < vel[0] <= table.SLIDE_MAX_SPEED + 1e-6


def test_torque_control_spins_the_rod_the_right_way(keeper_sim):
    keeper_sim.reset()
    keeper_sim.command("torque", [0.0, 0.05])
    keeper_sim.step()
    pos, vel = keeper_sim.joint_states()
    assert pos[1] > 0 and vel[1] > 0
    # Positive spin swings the home keeper's foot towards +x, the goal it attacks.
    foot_x = keeper_sim.figurine_positions()[0, 0]
    assert foot_x > table.rod("home_keeper").x


@pytest.mark.parametrize("spell", ["velocity", "torque"])
def test_a_position_drive_keeps_its_top_speed_after_a_spell_of_other_control(spell):
    # Bullet drops a motor's speed clamp on a velocity command (which letting the motors go
    # for torque control used to be). The ball waits 3 mm in front of the keeper's foot,
    # within its reach but not in its way, so Bullet moves the keeper throughout.
    sim = TableSim(["home_keeper"])
    keeper = table.rod("home_keeper")
    try:
        sim.reset(ball_position=(keeper.x + 0.025, 0.0))
        sim.command(spell, [0.0, 0.0])
        sim.step()
        peak, in_bullet = 0.0, 0
        for k in range(24):
            sim.place_ball((keeper.x + 0.025, sim.joint_states()[0][0]))
            # From stop to stop: the drive asks for 12 m/s.
            sim.command("position", [keeper.slide_limit * (1 if k % 8 < 4 else -1), 0.0])
            sim.step()
            if sim._worlds.simulated:  # Bullet had the keeper to the end of the step
                in_bullet += 1
                peak = max(peak, abs(sim.joint_states()[1][0]))
    finally:
        sim.close()
    assert in_bullet >= 20
    assert table.SLIDE_MAX_SPEED * 0.9 < peak <= table.SLIDE_MAX_SPEED * (1 + 1e-9)


def test_a_velocity_drive_gets_no_more_torque_in_fine_steps():
    # Bullet caps a motor's impulse per step at its force times the step size at the time of
    # the command; the ball beside the foot (never touched) sets the steps as the rod spins.
    sim = TableSim(["home_keeper"])
    keeper = table.rod("home_keeper")
    try:
        sim.reset(ball_position=(keeper.x, 0.035))
        sim.command("velocity", [0.0, table.SPIN_MAX_SPEED])
        speeds, steps = [], []
        for _ in range(3):
            before = sim.physics_steps
            sim.place_ball((keeper.x, 0.035))
            sim.step()
            steps.append(sim.physics_steps - before)
            speeds.append(sim.joint_states()[1][1])
        gain = table.SPIN_MAX_TORQUE / sim._drives.mass[1] * sim.control_dt
    finally:
        sim.close()
    assert len(set(steps)) > 1 and max(steps) > 2 * sim.substeps
    # What 1.41 N m gives the rod in each control step, whatever the steps (give or take
    # gravity's pull on the figurine: 0.3 %). Sent once at the first step's size, 2.2 times.
    assert speeds == pytest.approx([gain, 2 * gain, 3 * gain], rel=0.01)


def test_unknown_control_mode_is_rejected(keeper_sim):
    with pytest.raises(ValueError, match="position, velocity, torque"):
        keeper_sim.command("force", [0.0, 0.0])


def test_figurine_positions_match_the_collision_shapes():
    sim = TableSim(["home_defense", "away_offense"])
    try:
        sim.reset(slide=[0.1, -0.05], spin=[0.4, -0.7])
        for _ in range(3):
            sim.command("position", [0.1, -0.05, 0.4, -0.7])
            sim.step()
        centres = sim.figurine_positions()
        assert centres.shape == (5, 3)
        # The whole table as it is drawn: every rod posed where its drive has it.
        view = sim._view_world()
        for c in centres:
            # A ray straight down onto the computed centre hits a rod link, not the table.
            hit = view.client.rayTest([c[0], c[1], 0.3], [c[0], c[1], c[2]])[0]
            assert hit[0] == view.body and hit[1] >= 0, (c, hit)
        # And a ray 3 cm beside a figurine (in y) misses it.
        c = centres[0]
        miss = view.client.rayTest([c[0], c[1] + 0.03, 0.3], [c[0], c[1] + 0.03, 0.02])[0]
        assert miss[1] == -1
    finally:
        sim.close()


def test_rods_out_of_play_do_not_touch_the_ball(keeper_sim):
    # The home defense stands at x = -0.373; with only the keeper in play the ball rolls
    # straight through where it would be.
    keeper_sim.reset(slide=[0.12], ball_position=(-0.3, 0.1235), ball_velocity=(-2.0, 0.0))
    run(keeper_sim, 6)
    x, y, _, _ = keeper_sim.ball_xy()
    assert x < -0.40 and y == pytest.approx(0.1235, abs=1e-3)


def test_close_twice_is_safe():
    sim = TableSim(["home_keeper"])
    sim.close()
    sim.close()


def test_unknown_rod_is_rejected_with_the_allowed_names():
    with pytest.raises(ValueError, match="home_keeper"):
        TableSim(["home_goalie"])


def test_physics_and_control_rates_are_configurable():
    sim = TableSim(["home_keeper"], physics_hz=480, control_hz=120)
    try:
        assert sim.control_dt == pytest.approx(1 / 120) and sim.substeps == 4
        sim.reset(ball_position=(0.0, 0.2), ball_velocity=(-1.0, 0.0))
        sim.step()
        x, _, _, _ = sim.ball_xy()
        assert x == pytest.approx(-1.0 / 120, abs=2e-3)
    finally:
        sim.close()
    assert math.isclose(TableSim.__init__.__kwdefaults__["physics_hz"], 240)
    np.testing.assert_equal(TableSim.__init__.__kwdefaults__["control_hz"], 60)


@pytest.mark.parametrize("joint, target", [(0, 0.1), (1, 1.5)])
def test_a_drive_moves_the_same_whatever_the_physics_rate(joint, target):
    # Bullet's position gain acts per physics step; the simulator rescales it, so a finer
    # step (a higher rate, or the fine steps taken near a contact) leaves the motion alone.
    paths = []
    for hz in (240, 960, 2400):
        sim = TableSim(["home_keeper"], physics_hz=hz)
        try:
            sim.reset(ball_position=(0.3, 0.2))
            targets = [0.0, 0.0]
            targets[joint] = target
            path = []
            for _ in range(12):
                sim.command("position", targets)
                sim.step()
                path.append(sim.joint_states()[0][joint])
            paths.append(path)
        finally:
            sim.close()
    # Finer steps agree closely; 240 Hz differs by its integrator's own error while the drive
    # accelerates (4 mm, 0.12 rad at most), not by a different drive (a per-step gain at
    # 2400 Hz would ask ten times the speed for the same error).
    fine = 0.001 if joint == 0 else 0.03
    coarse = 0.005 if joint == 0 else 0.15
    np.testing.assert_allclose(paths[1], paths[2], atol=fine)
    np.testing.assert_allclose(paths[0], paths[2], atol=coarse)
    assert paths[0][-1] == pytest.approx(target, abs=fine)
