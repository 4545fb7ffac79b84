"""What real tables vary, as options: drives' speed and acceleration limits, calibration
offsets, rod angle noise and camera latency jitter. Each changes what it models, is drawn from
the environment's seeded generator, and is off by default."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import table
from foosball_gym.camera import CameraNoise
from foosball_gym.envs.estimated import EstimatedState
from foosball_gym.registration import task_interface

# A ball lying out of the keeper's reach: the keeper moves by its drives alone.
STILL_BALL = {"ball_position": (0.3, 0.3), "ball_velocity": (0.0, 0.0)}
KEEPER_SLIDE = 0.123  # m per unit of Block's and Score's slide action
SPIN_SCALE = 2 * np.pi  # rad per unit of Score's spin action


def joints(env) -> tuple[list[float], list[float]]:
    return env.unwrapped.rod_joint_values()


def slide_run(env, action, steps: int) -> list[float]:
    """The keeper's true slide speed after each of ``steps`` steps of ``action``."""
    env.reset(seed=0, options=STILL_BALL)
    speeds = []
    for _ in range(steps):
        env.step(np.asarray(action, np.float32))
        speeds.append(joints(env)[1][0])
    return speeds


# ------------------------------------------------------------------ the drives


def test_a_slower_drive_tops_out_at_its_share_of_the_rated_speed(make_env):
    plain = slide_run(make_env("Foosball-Block-v0"), [1.0], 12)
    slow = slide_run(make_env("Foosball-Block-v0", drive_speed_range=(0.5, 0.5)), [1.0], 12)
    # Across the whole range the rated drive goes faster than half its top speed, the slowed
    # one reaches half and no more.
    assert max(plain) > 0.6 * table.SLIDE_MAX_SPEED
    assert max(slow) == pytest.approx(0.5 * table.SLIDE_MAX_SPEED, rel=1e-9)


def test_a_weaker_drive_gathers_speed_at_its_share_of_the_acceleration(make_env):
    plain = slide_run(make_env("Foosball-Block-v0"), [1.0], 1)
    weak = slide_run(make_env("Foosball-Block-v0", drive_accel_range=(0.5, 0.5)), [1.0], 1)
    strong = slide_run(make_env("Foosball-Block-v0", drive_accel_range=(1.5, 1.5)), [1.0], 1)
    assert plain[0] > 0.3  # from rest, held by its acceleration alone in the first step
    assert weak[0] == pytest.approx(0.5 * plain[0], rel=1e-9)
    assert strong[0] == pytest.approx(1.5 * plain[0], rel=1e-9)


def test_each_driven_joint_draws_its_own_limits_within_the_ranges(make_env):
    env = make_env(
        "Foosball-FullGame-v0", drive_speed_range=(0.6, 0.9), drive_accel_range=(0.5, 1.5)
    )
    _, info = env.reset(seed=4)
    drawn = info["dynamics"]
    rods = env.unwrapped.layout.controlled
    for quantity, (low, high) in (("drive_speed", (0.6, 0.9)), ("drive_accel", (0.5, 1.5))):
        values = [drawn[f"{quantity}_{rod}_{kind}"] for rod in rods for kind in ("slide", "spin")]
        assert all(low <= v <= high for v in values)
        assert len(set(values)) == 2 * len(rods)
    # Only the learner's drives: the opponent's are the table's own.
    assert not any("away" in key for key in drawn)


def test_the_drive_limits_a_rod_meets_at_the_ball_are_the_drawn_ones(make_env):
    """Near the ball Bullet moves the rod; its motor takes the drawn top speed too."""
    speeds = []
    for factor in (1.0, 0.25):
        env = make_env("Foosball-Score-v0", drive_speed_range=(factor, factor))
        # In the keeper's path: it sweeps the ball aside.
        env.reset(seed=0, options={"ball_position": (-0.5, 0.1), "ball_velocity": (0.0, 0.0)})
        top = 0.0
        for _ in range(10):
            env.step(np.array([1.0, 0.0], np.float32))
            top = max(top, abs(joints(env)[1][0]))
        assert env.unwrapped.game.ball[0] > -0.49  # it met the ball
        speeds.append(top)
    assert speeds[1] == pytest.approx(0.25 * table.SLIDE_MAX_SPEED, rel=1e-3)
    assert speeds[0] > 2 * speeds[1]


def test_the_simulated_table_draws_the_drive_limits_too():
    from foosball_gym.real_table.virtual.simulated_table import SimulatedTable, virtual_table_config

    config = virtual_table_config(task_interface("Foosball-Block-v0"))
    t = SimulatedTable("Foosball-Block-v0", {"drive_speed_range": (0.5, 0.5)}, config)
    try:
        assert t.dynamics == {"drive_speed_home_keeper_slide": 0.5}
        sim = t.sim
        sim.command("position", [0.12, 0.0])
        top = 0.0
        for _ in range(12):
            sim.step()
            top = max(top, sim.joint_states()[1][0])
        assert top == pytest.approx(0.5 * table.SLIDE_MAX_SPEED, rel=1e-9)
    finally:
        t.close()


# ------------------------------------------------------------------ calibration


def test_a_slide_offset_shifts_what_is_read_and_where_commands_land(make_env):
    env = make_env("Foosball-Block-v0", slide_offset_range=(0.02, 0.02))
    obs, info = env.reset(seed=0, options=STILL_BALL)
    assert info["dynamics"] == {"slide_offset_home_keeper": 0.02}
    assert obs[0] == pytest.approx(joints(env)[0][0] + 0.02, abs=1e-7)
    for _ in range(40):
        obs, *_ = env.step(np.array([0.5], np.float32))
    true_slide = joints(env)[0][0]
    # The table believes it reached the target; the rod stands 2 cm short of it.
    assert obs[0] == pytest.approx(0.5 * KEEPER_SLIDE, abs=1e-5)
    assert true_slide == pytest.approx(0.5 * KEEPER_SLIDE - 0.02, abs=1e-5)
    # Velocities are read as they are.
    assert obs[1] == pytest.approx(joints(env)[1][0], abs=1e-7)


def test_an_angle_offset_shifts_what_is_read_and_where_commands_land(make_env):
    env = make_env("Foosball-Score-v0", angle_offset_range=(0.1, 0.1))
    names = env.unwrapped.obs_builder.names
    spin = names.index("home_keeper_spin_pos")
    obs, info = env.reset(seed=0, options=STILL_BALL)
    assert info["dynamics"] == {"angle_offset_home_keeper": 0.1}
    for _ in range(60):
        obs, *_ = env.step(np.array([0.0, 0.05], np.float32))
    true_angle = joints(env)[0][1]
    assert obs[spin] == pytest.approx(0.05 * SPIN_SCALE, abs=1e-3)
    assert true_angle == pytest.approx(0.05 * SPIN_SCALE - 0.1, abs=1e-3)
    assert obs[spin] - true_angle == pytest.approx(0.1, abs=1e-7)
    # The slide has no offset of its own.
    assert obs[names.index("home_keeper_slide_pos")] == pytest.approx(joints(env)[0][0], abs=1e-7)


def test_offsets_are_drawn_per_rod_at_every_reset_and_seeded(make_env):
    options = {"slide_offset_range": (-0.01, 0.01), "angle_offset_range": (-0.2, 0.2)}
    env = make_env("Foosball-FullGame-v0", **options)
    rods = env.unwrapped.layout.controlled
    draws = [env.reset(seed=seed)[1]["dynamics"] for seed in (1, 2, 1)]
    assert draws[0] == draws[2] and draws[0] != draws[1]
    for rod in rods:
        assert -0.01 <= draws[0][f"slide_offset_{rod}"] <= 0.01
        assert -0.2 <= draws[0][f"angle_offset_{rod}"] <= 0.2
    assert len({draws[0][f"slide_offset_{rod}"] for rod in rods}) == len(rods)
    # Held for the whole episode: every step's info has them.
    _, _, _, _, info = env.step(env.action_space.sample())
    assert info["dynamics"] == draws[2]


# ------------------------------------------------------------------ angle noise


def test_rod_angle_noise_scatters_the_read_angle_around_the_true_one(make_env):
    env = make_env("Foosball-Score-v0", rod_angle_noise=0.05)
    names = env.unwrapped.obs_builder.names
    spin, slide = names.index("home_keeper_spin_pos"), names.index("home_keeper_slide_pos")
    obs, _ = env.reset(seed=0, options=STILL_BALL)
    errors = []
    for _ in range(300):
        obs, *_ = env.step(np.zeros(2, np.float32))
        (true_slide, true_angle), _ = joints(env)
        errors.append(obs[spin] - true_angle)
        assert obs[slide] == pytest.approx(true_slide, abs=1e-7)
    errors = np.array(errors)
    assert abs(errors.mean()) < 0.01
    assert 0.04 < errors.std() < 0.06
    # Fresh at every step, not a fixed offset.
    assert len(set(np.round(errors, 6))) == len(errors)


def test_angle_noise_is_seeded(make_env):
    runs = []
    for _ in range(2):
        env = make_env("Foosball-Score-v0", rod_angle_noise=0.05)
        obs = [env.reset(seed=7)[0]]
        for _ in range(5):
            obs.append(env.step(np.zeros(2, np.float32))[0])
        runs.append(np.array(obs))
    np.testing.assert_array_equal(*runs)


# ------------------------------------------------------------------ camera latency jitter


def delivery_delays(jitter: float, steps: int = 240) -> tuple[list[float], list[float]]:
    """When each frame was taken, and how long after that the filter got it."""
    interface = task_interface("Foosball-Block-v0")
    state = EstimatedState(
        interface.builder,
        CameraNoise(fps=60, latency_s=0.03, latency_jitter_s=jitter, drop_rate=0.0),
        np.random.default_rng(0),
    )
    none = np.zeros((0, 3))
    ball = (0.3, 0.0, -1.0, 0.0)
    state.reset(ball, [0.0, 0.0], none)
    taken, delays, now = [], [], [0.0]
    original = state.estimator.update

    def update(t, *measured):
        taken.append(t)
        delays.append(now[0] - t)
        original(t, *measured)

    state.estimator.update = update
    for k in range(1, steps + 1):
        now[0] = k / 60
        state.advance(1 / 60, ball, [0.0, 0.0], none)
    return taken, delays


def test_latency_jitter_delays_each_frame_by_a_varying_time_keeping_their_order():
    taken, fixed = delivery_delays(0.0)
    taken_late, jittered = delivery_delays(0.05)
    # Every frame arrives, in the order it was taken.
    assert taken_late == sorted(taken_late) and len(set(taken_late)) == len(taken_late)
    assert len(taken_late) >= len(taken) - 6  # those still on their way at the end
    # Without jitter each frame waits the latency, to the next control step; with it, up to
    # the jitter more (or for the frame before it).
    assert all(0.03 - 1e-9 <= d < 0.03 + 1 / 60 for d in fixed)
    assert all(0.03 - 1e-9 <= d < 0.03 + 0.05 + 1 / 60 for d in jittered)
    assert max(jittered) - min(jittered) > 0.04
    assert np.mean(jittered) > np.mean(fixed) + 0.015


def test_latency_jitter_makes_the_estimates_lag(make_env):
    """A filter fed later frames than it allows for trails a moving ball further."""
    errors = []
    for jitter in (0.0, 0.1):
        env = make_env(
            "Foosball-Block-v0",
            estimated_state=True,
            camera_noise={"latency_jitter_s": jitter, "position_std": 0.0, "drop_rate": 0.0},
        )
        error = []
        for seed in range(3):
            env.reset(seed=seed, options={"ball_position": (0.4, 0.0), "ball_velocity": (-4, 0)})
            for _ in range(15):
                obs, *_ = env.step(np.zeros(1, np.float32))
                ball_x = env.unwrapped.game.ball[0]
                error.append(abs(obs[2] - ball_x))
        errors.append(np.mean(error))
    assert errors[1] > 2 * errors[0]


def seen_and_true(env, seed: int, steps: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """The ball as observed and as it truly was over an episode of a still keeper."""
    obs = [env.reset(seed=seed)[0][2:6]]
    true = [np.array(env.unwrapped.game.ball[:4])]
    for _ in range(steps):
        obs.append(env.step(np.zeros(1, np.float32))[0][2:6])
        true.append(np.array(env.unwrapped.game.ball[:4]))
    return np.array(obs), np.array(true)


def test_a_camera_seed_changes_the_detections_and_not_the_balls(make_env):
    """The same balls through other detections: what several camera seeds measure."""

    def camera(seed):
        noise = {} if seed is None else {"camera_noise": {"seed": seed}}
        return make_env("Foosball-Block-v0", estimated_state=True, **noise)

    (seen_a, true_a), (seen_b, true_b), (seen_env, true_env) = (
        seen_and_true(camera(s), 7) for s in (1, 2, None)
    )
    np.testing.assert_array_equal(true_a, true_b)
    np.testing.assert_array_equal(true_a, true_env)
    assert np.abs(seen_a - seen_b).max() > 1e-4
    # Seeded by the camera's seed and the episode's, whatever ran before it.
    again = camera(1)
    seen_and_true(again, 3)
    np.testing.assert_array_equal(seen_and_true(again, 7)[0], seen_a)


# ------------------------------------------------------------------ defaults and checks


def test_neutral_values_play_the_default_game_bit_for_bit(make_env):
    """The machinery itself changes nothing: factors of 1 and offsets of 0 (which still draw,
    from the start's own generator, so the start is given) play the default game exactly,
    at the ball too."""
    neutral = {
        "drive_speed_range": (1.0, 1.0),
        "drive_accel_range": (1.0, 1.0),
        "slide_offset_range": (0.0, 0.0),
        "angle_offset_range": (0.0, 0.0),
    }
    start = {"ball_position": (-0.4, 0.05), "ball_velocity": (-1.0, 0.3)}
    runs = []
    for kwargs in ({}, neutral):
        env = make_env("Foosball-Score-v0", **kwargs)
        rng = np.random.default_rng(3)
        obs = [env.reset(seed=0, options=start)[0]]
        for _ in range(40):
            obs.append(env.step(rng.uniform(-1, 1, 2).astype(np.float32))[0])
        runs.append(np.array(obs))
    np.testing.assert_array_equal(*runs)


def test_the_options_are_off_by_default(make_env):
    for env_id in ("Foosball-Block-v0", "Foosball-FullGame-v0"):
        defaults = type(gym.make(env_id).unwrapped).option_defaults()
        assert [defaults[name] for name in ("drive_speed_range", "drive_accel_range")] == [None] * 2
        assert defaults["slide_offset_range"] is defaults["angle_offset_range"] is None
        assert defaults["rod_angle_noise"] == 0.0
        _, info = make_env(env_id).reset(seed=0)
        assert "dynamics" not in info
    assert CameraNoise().latency_jitter_s == 0.0


BLOCK, SCORE = "Foosball-Block-v0", "Foosball-Score-v0"


def jitter(value):
    return {"estimated_state": True, "camera_noise": {"latency_jitter_s": value}}


def camera_seed(value):
    return {"estimated_state": True, "camera_noise": {"seed": value}}


@pytest.mark.parametrize(
    "env_id, kwargs, message",
    [
        (BLOCK, {"drive_speed_range": (0.5, 1.5)}, r"drive_speed_range must satisfy 0.1 <= low"),
        (BLOCK, {"drive_accel_range": (0.0, 1.0)}, r"drive_accel_range must satisfy 0.1 <="),
        (BLOCK, {"slide_offset_range": (-0.1, 0.0)}, r"slide_offset_range must satisfy -0.05"),
        (BLOCK, {"slide_offset_range": 0.01}, r"slide_offset_range must be a pair"),
        (SCORE, {"angle_offset_range": (0.3, 0.2)}, r"angle_offset_range must satisfy -0.5"),
        (SCORE, {"rod_angle_noise": -0.1}, r"rod_angle_noise must be a .* in \[0, 0.5\] rad"),
        (SCORE, {"rod_angle_noise": "high"}, r"rod_angle_noise must be"),
        (SCORE, {"rod_angle_noise": True}, r"rod_angle_noise must be"),
        (BLOCK, {"angle_offset_range": (0.0, 0.1)}, r"angle_offset_range needs a rod that turns"),
        (BLOCK, {"rod_angle_noise": 0.01}, r"rod_angle_noise needs a rod that turns"),
        (BLOCK, jitter(-0.01), r"latency_jitter_s must be a finite number, 0 or more"),
        (BLOCK, jitter(float("nan")), r"latency_jitter_s must be"),
        (BLOCK, camera_seed(-1), r"camera_noise seed must be an integer, 0 or more, or None"),
        (BLOCK, camera_seed(1.5), r"camera_noise seed must be an integer"),
    ],
)
def test_bad_values_are_refused_in_one_line_naming_what_is_allowed(env_id, kwargs, message):
    with pytest.raises(ValueError, match=message) as err:
        gym.make(env_id, **kwargs)
    assert "\n" not in str(err.value)
