"""Session logs of ``foosball play --log`` written by hand, in the format of
:mod:`foosball_gym.session_log`, for the tests of what reads them."""

from __future__ import annotations

ENV_ID = "Foosball-Block-v0"


def header(env_kwargs=None, interface="virtual", env_id=ENV_ID, rod="home_keeper", observation=()):
    joints = [
        {"rod": rod, "joint": kind, "node_id": i + 1, "increments_per_unit": 1000.0}
        for i, kind in enumerate(("slide", "spin"))
    ]
    return {
        "env_id": env_id,
        "env_kwargs": env_kwargs or {},
        "observation": list(observation),
        "action": [],
        "table": {"joints": joints, "bus": {"interface": interface}, "control_hz": 60.0},
        "started": 0.0,
    }


def record(k, ball, latency_steps=2):
    """Loop ``k`` of a hand-made log: the frame ``latency_steps`` loops old."""
    t = k / 60
    return {
        "t": t,
        "frame_time": max(0.0, t - latency_steps / 60),
        "detection_px": None,
        "ball_measured": None if ball is None else [float(ball[0]), float(ball[1])],
        "opponent_slides": {},
        "own_state": {"home_keeper.slide": [0.0, 0.0], "home_keeper.spin": [0.0, 0.0]},
        "observation": [],
        "action": [0.0],
        "targets": {"home_keeper.slide": 0.0, "home_keeper.spin": 0.0},
        "stage_ms": {},
        "late": False,
        "new_ball": k == 0,
        "frame_missed": False,
    }
