"""Where a resting ball goes when the keeper strikes it off the middle of its foot.

The keeper stands with its figurine ``offset`` millimetres beside the ball (read around the
ball, ``slide_around_ball``), swings back and strikes; the ball's direction, as it first passes
1 m/s, is printed for each offset over several serves. The flat of the foot, 9 mm either side of
its middle, sends the ball straight; past it, the foot's rounded edge (3 mm round) turns the
ball by asin((offset - 9 mm) / (3 mm + the ball's radius)), about 3 degrees a millimetre.

    python benchmarks/kick_angle.py [--offsets 0,4,8,9,10,11,12,14,18,-12] [--serves 3]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

BAND = 0.02  # m: an action of 1 puts the figurine 2 cm beside the ball


def first_shot_angle(env: object, offset: float, seed: int) -> float | None:
    """Degrees from the table's axis of the ball's first shot, None where it never left."""
    obs, _ = env.reset(seed=seed)  # type: ignore[attr-defined]
    vx_at = env.unwrapped.obs_builder.names.index("ball_vx")  # type: ignore[attr-defined]
    for t in range(90):
        spin = -0.06 if t < 30 else 0.15  # a back-swing, then the strike
        action = np.array([offset / BAND, spin], dtype=np.float32)
        obs, *_ = env.step(action)  # type: ignore[attr-defined]
        vx, vy = float(obs[vx_at]), float(obs[vx_at + 1])
        if math.hypot(vx, vy) > 1.0:
            return math.degrees(math.atan2(vy, vx))
    return None


def main() -> None:
    import gymnasium as gym

    import foosball_gym  # noqa: F401  (registers the environments)
    from foosball_gym import table

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--offsets", default="0,4,8,9,10,11,12,14,18,-12", help="mm, commas")
    parser.add_argument("--serves", type=int, default=3)
    args = parser.parse_args()
    flat = table.FIGURINE_LEG_FLAT_HALF_WIDTH
    edge = table.FIGURINE_LEG_HALF_WIDTH - flat
    env = gym.make("Foosball-Score-v0", ball_start="resting", slide_around_ball=BAND)
    print("offset (mm) | first shots (degrees) | asin((|offset| - flat) / (edge + ball))")
    for mm in (float(v) for v in args.offsets.split(",")):
        angles = [first_shot_angle(env, mm / 1000, s) for s in range(args.serves)]
        past = max(abs(mm) / 1000 - flat, 0.0) / (edge + table.BALL_RADIUS)
        model = -math.copysign(math.degrees(math.asin(min(past, 1.0))), mm)
        shots = " ".join("missed" if a is None else f"{a:+6.1f}" for a in angles)
        print(f"{mm:+6.1f} | {shots} | {model:+6.1f}")
    env.close()


if __name__ == "__main__":
    main()
