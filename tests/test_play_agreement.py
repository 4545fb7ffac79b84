"""Play and eval meet the same game: the environment's safety layer shapes targets as the play
stack does (``safety_layer``), and the simulated table serves the balls of the environment's
seeded episodes, seen by a camera that errs as the environment's camera model."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import table
from foosball_gym.real_table.hardware.config import simulated_joint
from foosball_gym.real_table.hardware.safety import JointLimits, TargetLimiter
from foosball_gym.registration import task_interface

STILL_BALL = {"ball_position": (0.3, 0.3), "ball_velocity": (0.0, 0.0)}
KEEPER_LIMIT = table.rod("home_keeper").slide_limit


def sent_targets(env, actions) -> list[list[float]]:
    """The simulated drives' targets of the learner's joints after each action."""
    game = env.unwrapped.game
    out = []
    for action in actions:
        env.step(np.asarray(action, np.float32))
        out.append([game.targets[i] for i in game._own])
    return out


def random_actions(n_actions: int, steps: int, seed: int = 0) -> np.ndarray:
    # Jumps from end to end, holds and small moves: what the limiter must shape.
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1, 1, size=(steps, n_actions))
    actions[rng.random(steps) < 0.3] = 1.0
    return actions


def test_on_by_default_with_estimated_state_and_off_on_the_true_state(make_env):
    assert make_env("Foosball-Block-v0").unwrapped._safety is None
    assert make_env("Foosball-Block-v0", estimated_state=True).unwrapped._safety is not None
    off = make_env("Foosball-Block-v0", estimated_state=True, safety_layer=False)
    assert off.unwrapped._safety is None
    assert make_env("Foosball-Block-v0", safety_layer=True).unwrapped._safety is not None


@pytest.mark.parametrize("env_id", ["Foosball-Block-v0", "Foosball-Score-v0"])
def test_the_drives_get_what_the_play_stacks_limiter_sends(make_env, env_id):
    """The very targets ``TableDrives.command`` sends a simulated table, step by step."""
    from foosball_gym.real_table.virtual.simulated_table import virtual_table_config

    env = make_env(env_id, safety_layer=True)
    env.reset(seed=0, options=STILL_BALL)
    interface = env.unwrapped.interface
    config = virtual_table_config(interface)
    start = env.unwrapped.game.own_readings()
    limiters = [
        TargetLimiter(JointLimits.of(config.joint(j)), config.control_period, p)
        for j, p in zip(interface.action_joints, start)
    ]
    actions = random_actions(interface.n_actions, 40).astype(np.float32)
    got = sent_targets(env, actions)
    for action, targets in zip(actions, got):
        wanted = [
            lim.step(s * float(a)) for lim, s, a in zip(limiters, interface.action_scales, action)
        ]
        assert targets == pytest.approx(wanted, abs=1e-12)


def test_targets_stay_inside_the_margin_and_move_no_faster_than_the_drive(make_env):
    env = make_env("Foosball-Block-v0", safety_layer=True)
    env.reset(seed=0, options=STILL_BALL)
    targets = [t[0] for t in sent_targets(env, [[1.0]] * 30 + [[-1.0]] * 30)]
    assert max(targets) == pytest.approx(KEEPER_LIMIT - 0.005)
    assert min(targets) == pytest.approx(-(KEEPER_LIMIT - 0.005))
    steps = np.abs(np.diff([0.0, *targets]))
    assert steps.max() <= table.SLIDE_MAX_SPEED / table.CONTROL_HZ + 1e-12
    # Without it the first step's target is the action's own.
    plain = make_env("Foosball-Block-v0")
    plain.reset(seed=0, options=STILL_BALL)
    assert sent_targets(plain, [[1.0]])[0][0] == pytest.approx(KEEPER_LIMIT)


def test_the_rod_gets_there_later_through_the_safety_layer(make_env):
    """What the play stack costs a keeper: the rod follows a target that moves."""
    after_three = {}
    for on in (False, True):
        env = make_env("Foosball-Block-v0", safety_layer=on)
        env.reset(seed=0, options=STILL_BALL)
        sent_targets(env, [[0.8]] * 3)
        after_three[on] = env.unwrapped.game.positions[0]
    # Measured: 82.1 mm against 74.9 mm, on the way to 98.4 mm.
    assert after_three[False] - after_three[True] > 0.004


def test_the_simulated_tables_limits_are_its_configurations():
    """The environment's limits are those ``foosball play --table sim`` configures its
    drives with, for every joint of every rod."""
    for rod in table.ROD_BY_NAME:
        for kind in ("slide", "spin"):
            joint = simulated_joint(rod, kind)
            assert JointLimits.simulated(rod, kind) == JointLimits.of(joint)


def test_calibration_offsets_are_shaped_as_the_table_reads_its_rods(make_env):
    """The limiter works on the table's readings: with the slide read 2 cm along, a target of
    the full stroke lands 2 cm short of the margin."""
    env = make_env("Foosball-Block-v0", safety_layer=True, slide_offset_range=(0.02, 0.02))
    env.reset(seed=0, options=STILL_BALL)
    targets = [t[0] for t in sent_targets(env, [[1.0]] * 30)]
    assert targets[-1] == pytest.approx(KEEPER_LIMIT - 0.005 - 0.02)


@pytest.mark.parametrize("value", ["yes", 1, "table.yaml"])
def test_bad_values_are_refused_naming_what_is_allowed(value):
    with pytest.raises(ValueError, match=r"safety_layer must be None \(on with estimated_state\)"):
        gym.make("Foosball-Block-v0", safety_layer=value)


def test_rewards_see_the_policys_own_action(make_env):
    """Action regularisation penalises what the policy did, not what the limiter made of it."""
    kwargs = {"action_regularisation_weight": 1.0}
    results = []
    for on in (False, True):
        env = make_env("Foosball-Block-v0", safety_layer=on, **kwargs)
        env.reset(seed=0, options=STILL_BALL)
        results.append(env.step(np.array([1.0], np.float32))[4]["reward_action_regularisation"])
    assert results[0] == results[1] != 0


# ------------------------------------------------------------------ the simulated table's serves


@pytest.mark.parametrize(
    ("env_id", "kwargs"),
    [
        ("Foosball-Block-v0", {"bank_share": 0.3, "rebound_share": 0.1}),
        ("Foosball-Score-v0", {"ball_start": "incoming", "ball_friction_range": (0.05, 0.2)}),
    ],
)
def test_the_simulated_table_serves_the_balls_of_the_seeded_episodes(make_env, env_id, kwargs):
    """``foosball play --seed S`` serves episode S + K's ball as its serve K, with the same
    drawn physics: play and eval meet the same shots."""
    from foosball_gym.real_table.virtual.simulated_table import SimulatedTable, virtual_table_config

    config = virtual_table_config(task_interface(env_id, kwargs))
    sim_table = SimulatedTable(env_id, kwargs, config, seed=7, camera_size=(64, 36))
    env = make_env(env_id, **kwargs)
    try:
        for k in range(4):
            sim_table.serve()
            _, info = env.reset(seed=7 + k)
            assert sim_table.game.ball == pytest.approx(env.unwrapped.game.ball, abs=0)
            assert sim_table.dynamics == info.get("dynamics", {})
    finally:
        sim_table.close()


@pytest.mark.parametrize(
    ("kwargs", "policy"),
    [({}, "builtin:score-resting"), ({"obstacles": True}, "builtin:score-obstacles")],
)
def test_play_brings_the_rods_to_each_episodes_start_before_its_ball(
    monkeypatch, make_env, kwargs, policy
):
    """After a shot the keeper's feet stood where the next ball at rest goes, and the table drew
    another ball (33 of 60 serves from rest). Play now brings the rods to where the episode
    starts them, at rest, and serves that episode's ball: the one eval plays."""
    from foosball_gym import load_policy
    from foosball_gym.real_table.play.stack import play_sim
    from foosball_gym.real_table.virtual import simulated_table

    served = []
    real_serve = simulated_table.SimulatedTable.serve

    def recorded_serve(table_self):
        real_serve(table_self)
        served.append((table_self.game.ball, list(table_self.sim.joint_states()[0])))

    monkeypatch.setattr(simulated_table.SimulatedTable, "serve", recorded_serve)
    env_id = "Foosball-Score-v0"
    report = play_sim(
        load_policy(policy), env_id, kwargs, episodes=6, seed=11, camera_size=(320, 180)
    )
    assert report.episodes == 6
    env = make_env(env_id, **kwargs)
    for k, (ball, joints) in enumerate(served):
        env.reset(seed=11 + k)
        assert ball == pytest.approx(env.unwrapped.game.ball, abs=0), f"serve {k}"
        positions, _ = env.unwrapped.rod_joint_values()
        n = len(positions) // 2
        assert joints[:n] == pytest.approx(positions[:n], abs=0.001), f"serve {k}"  # slides
        assert joints[n:] == pytest.approx(positions[n:], abs=0.02), f"serve {k}"  # spins


# ------------------------------------------------------------------ the simulated table's camera


def sim_table(env_id: str = "Foosball-KeeperVsKeeper-v0", **kwargs):
    from foosball_gym.real_table.virtual.simulated_table import SimulatedTable, virtual_table_config

    config = virtual_table_config(task_interface(env_id, kwargs))
    return SimulatedTable(env_id, kwargs, config, seed=3, camera_size=(320, 180))


def test_the_simulated_camera_pictures_the_ball_and_rods_with_the_models_errors():
    t = sim_table()
    try:
        t.serve()
        truth_pos, truth_ball = t.sim.scene()
        seen = [t.seen_scene() for _ in range(4000)]
    finally:
        t.close()
    balls = np.array([b for _, b in seen])
    hidden = balls[:, 2] < 0
    # Defaults: 2 % of frames miss the ball, the others place it within 2 mm (std).
    assert 0.012 < hidden.mean() < 0.03
    offsets = balls[~hidden, :2] - np.array(truth_ball[:2])
    assert offsets.std(axis=0) == pytest.approx([0.002, 0.002], rel=0.08)
    assert np.abs(offsets.mean(axis=0)).max() < 0.0002
    # KeeperVsKeeper: rods home_keeper, away_keeper; only the opponent's slide is off (3 mm).
    positions = np.array([p for p, _ in seen]) - np.array(truth_pos)
    assert positions[:, 1].std() == pytest.approx(0.003, rel=0.08)
    assert not positions[:, [0, 2, 3]].any()


def test_a_camera_without_errors_pictures_the_table_as_it_is():
    exact = {"position_std": 0.0, "rod_std": 0.0, "drop_rate": 0.0}
    t = sim_table(estimated_state=True, camera_noise=exact)
    try:
        t.serve()
        assert t.seen_scene() == t.sim.scene()
    finally:
        t.close()


def test_a_missed_frame_shows_no_ball_to_the_detector():
    from foosball_gym.real_table.vision import ColourBallDetector

    t = sim_table("Foosball-Block-v0", estimated_state=True, camera_noise={"drop_rate": 0.999})
    try:
        t.serve()
        positions, ball = t.sim.scene()
        detector = ColourBallDetector()
        shown = t.sim.render(320, 180, scene=(positions, ball))[:, :, ::-1]
        assert detector.detect(np.ascontiguousarray(shown)) is not None
        missed = t.frame()[:, :, ::-1]
        assert detector.detect(np.ascontiguousarray(missed)) is None
    finally:
        t.close()
