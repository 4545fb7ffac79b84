"""The simulated table in real time: what a camera frame costs, and how the stack keeps time.

Two parts:

- render: milliseconds per camera frame, drawn whole and layered (the field and walls drawn
  once, the rods and the ball laid over them by depth), for one rod and for all eight, at
  320 x 180 and 640 x 360, on one core;
- play: ``--sessions`` sessions of ``--episodes`` Block serves each, the scripted keeper
  through the whole stack on the wall clock (what ``foosball play scripted --env
  Foosball-Block-v0 --table sim`` runs), seeds 0, 1, ...: per session and pooled, the block
  rate with its 95 % interval, the loop period, the late loops and the frames that came too
  late to use; next to ``foosball eval``'s rate for the same keeper on ``estimated_state=True``
  over ``--eval-episodes``.

    python benchmarks/realtime_play.py [--sessions 5] [--episodes 30] [--eval-episodes 500]

Run it on an otherwise idle machine: the table runs on the wall clock, and other work on the
cores shows in the figures.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from foosball_gym import table
from foosball_gym.evaluation import evaluate, wilson_interval
from foosball_gym.real_table.hardware.safety import SafetyError
from foosball_gym.real_table.play.stack import play_sim
from foosball_gym.registration import scripted_policy
from foosball_gym.sim import TableSim

ENV = "Foosball-Block-v0"


def render_times(frames: int = 40) -> None:
    print("render, ms per frame (median)        whole  layered")
    rng = np.random.default_rng(0)
    for label, rods in (("1 rod ", ["home_keeper"]), ("8 rods", [r.name for r in table.RODS])):
        sim = TableSim(rods)
        for size in ((320, 180), (640, 360)):
            times = {True: [], False: []}
            for _ in range(frames):
                slides = [rng.uniform(-r.slide_limit, r.slide_limit) for r in sim.rods]
                spins = list(rng.uniform(-1.5, 1.5, len(sim.rods)))
                ball = [rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3), table.BALL_RADIUS]
                sim.show(slides + spins, ball)
                for layered in (False, True):
                    start = time.perf_counter()
                    sim.render(*size, layered=layered)
                    times[layered].append(1e3 * (time.perf_counter() - start))
            print(
                f"  {label} {size[0]:3d} x {size[1]:3d}            "
                f"{np.median(times[False]):6.1f}   {np.median(times[True]):6.1f}"
            )
        sim.close()


def rate(successes: int, n: int) -> str:
    low, high = wilson_interval(successes, n)
    return f"{100 * successes / n:5.1f} % ({100 * low:.1f}-{100 * high:.1f})"


def play(sessions: int, episodes: int) -> None:
    print(f"\nplay: {sessions} real-time sessions of {episodes} serves, scripted keeper")
    blocked = served = loops = late = missed = stopped = 0
    periods: list[float] = []
    for seed in range(sessions):
        try:
            report = play_sim(scripted_policy(ENV, {}), ENV, {}, episodes, seed=seed, realtime=True)
        except SafetyError as err:
            stopped += 1
            print(f"  seed {seed}: stopped: {err}")
            continue
        blocked += report.successes
        served += report.episodes
        loops += report.steps
        late += report.late
        missed += report.frames_missed
        periods += report.period_ms
        print(
            f"  seed {seed}: blocked {rate(report.successes, report.episodes)}; "
            f"{report.timing_summary()}"
        )
    if served:
        p = np.array(periods)
        print(
            f"  all: blocked {blocked} of {served}, {rate(blocked, served)}; period median "
            f"{np.median(p):.2f} ms, p99 {np.percentile(p, 99):.2f} ms; late {late} of "
            f"{loops} loops ({100 * late / loops:.2f} %); frames too late to use {missed}; "
            f"sessions stopped by the safety layer {stopped} of {sessions}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=5)
    parser.add_argument("--episodes", type=int, default=30)
    parser.add_argument("--eval-episodes", type=int, default=500)
    args = parser.parse_args()
    render_times()
    play(args.sessions, args.episodes)
    if args.eval_episodes:
        result = evaluate(
            scripted_policy(ENV, {"estimated_state": True}),
            ENV,
            {"estimated_state": True},
            episodes=args.eval_episodes,
        )
        print(f"\nfoosball eval, estimated_state=True: {rate(result.successes, result.episodes)}")


if __name__ == "__main__":
    main()
