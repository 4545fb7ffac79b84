"""Time to skill: train Foosball-Block-v0 with the CLI defaults until the evaluated block rate
first reaches 95 %, and report the wall-clock time and timesteps it took.

    python benchmarks/time_to_skill.py [--seed N] [--out DIR] [--plot FILE.png]

The wall-clock time includes the periodic evaluations (50 seeded episodes every 10,000 steps),
as a user of `foosball train` would see it.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

from foosball_gym.training.config import TrainConfig
from foosball_gym.training.run import plot_curve, read_curve, train


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--target", type=float, default=0.95)
    parser.add_argument("--max-timesteps", type=int, default=2_000_000)
    parser.add_argument("--out", help="keep the run here (default: a temporary directory)")
    parser.add_argument("--plot", help="also write the evaluation curve to this PNG")
    args = parser.parse_args()

    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="time_to_skill_"))
    config = TrainConfig(
        "Foosball-Block-v0",
        seed=args.seed,
        timesteps=args.max_timesteps,
        target_success=args.target,
    )
    start = time.perf_counter()
    result = train(config, out)
    total = time.perf_counter() - start
    curve = read_curve(out / "eval.csv")
    if args.plot:
        plot_curve(out / "eval.csv", Path(args.plot), f"Foosball-Block-v0, seed {args.seed}")
    print(f"{'timesteps':>10s} {'wall s':>8s} {'block rate':>10s}")
    for row in curve:
        print(
            f"{int(row['timesteps']):10d} {row['wall_seconds']:8.0f} "
            f"{100 * row['success_rate']:9.0f}%"
        )
    if result.reached:
        print(
            f"\nblock rate {100 * args.target:.0f} % first reached after "
            f"{int(result.reached['timesteps']):,} timesteps and "
            f"{result.reached['wall_seconds']:.0f} s of training "
            f"({total:.0f} s including start-up), seed {args.seed}"
        )
    else:
        print(
            f"\nblock rate {100 * args.target:.0f} % not reached in "
            f"{args.max_timesteps:,} timesteps ({total:.0f} s)"
        )
    if not args.out:
        shutil.rmtree(out)


if __name__ == "__main__":
    main()
