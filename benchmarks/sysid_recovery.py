"""Does ``foosball sysid`` find a table's physics? Logs from simulated tables whose answer is
known, fitted, and the figures printed.

Two tables: one with the physics of issue "Fit the simulator to a real table" (rolling
resistance 0.02, restitution 0.4, drive gain factor 0.7) and the default one. On each, the
scripted keeper of Foosball-Block-v0 plays calibration serves (``--serves calibration``) for at
most ``--minutes`` of logged play through the whole real-table stack in lock-step (camera
frames rendered and detected, Kalman filter, CAN drives), and the logs are fitted. For each
parameter: the true value, the fitted one with its uncertainty, and the error in per cent.

The play is logged as several sessions (``--serves-per-log`` serves each): on a busy machine a
lock-step session can be stopped by its own drive supervision, and what it logged until then is
kept. The logs stay in ``--folder`` for ``foosball sysid`` to be run on them again.

    python benchmarks/sysid_recovery.py [--minutes 5] [--folder sysid-logs] [--table altered]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from foosball_gym.real_table.hardware.safety import SafetyError
from foosball_gym.real_table.play.stack import play_sim
from foosball_gym.real_table.sysid.excitation import CALIBRATION_SERVE_S
from foosball_gym.real_table.sysid.fit import fit_logs
from foosball_gym.registration import scripted_policy
from foosball_gym.table import CONTROL_HZ

ENV_ID = "Foosball-Block-v0"
TABLES = {
    "altered": (
        {
            "rolling_resistance": 0.02,
            "ball_restitution_range": (0.4, 0.4),
            "drive_gain_range": (0.7, 0.7),
        },
        {
            "rolling_resistance": 0.02,
            "ball_restitution": 0.4,
            "ball_friction": 0.1,
            "drive_gain": 0.7,
        },
    ),
    "default": (
        {},
        {
            "rolling_resistance": 0.01,
            "ball_restitution": 0.5,
            "ball_friction": 0.1,
            "drive_gain": 1.0,
        },
    ),
}


def record(folder: Path, env_kwargs: dict, minutes: float, serves: int) -> list[Path]:
    """Calibration sessions on the simulated table until most of ``minutes`` of play are
    logged, never more; logs already in ``folder`` are counted first, not played again."""
    folder.mkdir(parents=True, exist_ok=True)
    policy = scripted_policy(ENV_ID, env_kwargs, on_table=True)
    serve_loops = round(CALIBRATION_SERVE_S * CONTROL_HZ)
    limit = round(minutes * 60 * CONTROL_HZ)
    logs, loops = [], 0
    for seed in range(1, 1000):
        if loops >= limit - serve_loops:
            break
        path = folder / f"session-{seed}.jsonl"
        if not path.exists():
            try:
                play_sim(
                    policy,
                    ENV_ID,
                    env_kwargs,
                    episodes=min(serves, (limit - loops) // serve_loops),
                    seed=seed,
                    log_path=str(path),
                    serves="calibration",
                )
            except SafetyError as err:
                print(f"  session {seed} stopped early ({err}); its log is kept")
        count = sum(1 for _ in path.open()) - 1
        if loops + count > limit:  # a log left from a longer run than this one
            break
        logs.append(path)
        loops += count
    print(f"  {len(logs)} logs, {loops} loops: {loops / CONTROL_HZ / 60:.2f} min of play")
    return logs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=5.0)
    parser.add_argument("--folder", default="sysid-logs")
    parser.add_argument("--serves-per-log", type=int, default=10)
    parser.add_argument("--table", choices=(*TABLES, "both"), default="both")
    args = parser.parse_args()
    names = list(TABLES) if args.table == "both" else [args.table]
    for name in names:
        env_kwargs, truth = TABLES[name]
        print(f"{name} table: {json.dumps(env_kwargs)}")
        start = time.perf_counter()
        logs = record(Path(args.folder) / name, env_kwargs, args.minutes, args.serves_per_log)
        print(f"  recorded in {time.perf_counter() - start:.0f} s")
        start = time.perf_counter()
        fit = fit_logs([str(p) for p in logs])
        print(f"  fitted in {time.perf_counter() - start:.0f} s: {fit.summary()}")
        print(f"  {'parameter':20s} {'true':>8s} {'fitted':>9s} {'+-':>8s} {'error':>8s}")
        for key, true in truth.items():
            value, std = fit.values[key], fit.std[key]
            error = 100 * (value - true) / true
            print(f"  {key:20s} {true:8.4f} {value:9.4f} {std:8.4f} {error:+7.1f} %")
        print(fit.residual_table())


if __name__ == "__main__":
    main()
