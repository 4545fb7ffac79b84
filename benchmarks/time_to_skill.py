"""Time to skill: how long `foosball train` takes to reach a task's skill, median over seeds.

    python benchmarks/time_to_skill.py [--task block|score] [--recipe config|defaults]
                                       [--seeds 0 1 2] [--eval-episodes 200] [--plot FILE.png]

``--task block`` trains Foosball-Block-v0 until the evaluated block rate first reaches 98 %;
``--task score`` trains Foosball-Score-v0 with the ball at rest until 95 % score. Each
evaluation plays ``--eval-episodes`` seeded episodes (200: on 50, a 98 % crossing is mostly
noise). ``--recipe config`` trains with the task's shipped settings file
(``foosball train --config builtin:ENV_ID``: PPO from a behaviour-cloned copy of the scripted
keeper), ``--recipe defaults`` with the CLI's defaults (PPO from scratch).

The wall time to skill is what a user waits from the start of training: the demonstrations
and the clone (``pretrain.json``'s seconds) plus the training up to the evaluation that
crossed, evaluations included. Prints one line per seed, then the medians.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import statistics
import tempfile
import time
from pathlib import Path

from foosball_gym.training.config import TrainConfig
from foosball_gym.training.config_file import load_train_config
from foosball_gym.training.run_dir.curve import plot_curve
from foosball_gym.training.sb3.trainer import train

TASKS = {
    "block": ("Foosball-Block-v0", 0.98, {}),
    "score": ("Foosball-Score-v0", 0.95, {"ball_start": "resting"}),
}


def run_one(task: str, recipe: str, seed: int, episodes: int, budget: int, out: Path) -> dict:
    env_id, target, env_kwargs = TASKS[task]
    if recipe == "config":
        config = load_train_config(f"builtin:{env_id}")
    else:
        config = TrainConfig(env_id, env_kwargs=dict(env_kwargs))
    config = dataclasses.replace(
        config,
        seed=seed,
        timesteps=budget,
        eval_episodes=episodes,
        target_success=target,
    )
    start = time.perf_counter()
    result = train(config, out)
    total = time.perf_counter() - start
    pretrain = out / "pretrain.json"
    cloning = json.loads(pretrain.read_text()).get("seconds", 0.0) if pretrain.exists() else 0.0
    row = {"seed": seed, "reached": result.reached is not None, "total_s": total}
    if result.reached:
        row["timesteps"] = int(result.reached["timesteps"])
        row["wall_s"] = cloning + result.reached["wall_seconds"]
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", choices=sorted(TASKS), default="block")
    parser.add_argument("--recipe", choices=("config", "defaults"), default="config")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--eval-episodes", type=int, default=200)
    parser.add_argument("--max-timesteps", type=int, default=2_000_000)
    parser.add_argument("--out", help="keep the runs here, one folder per seed")
    parser.add_argument("--plot", help="also write the first seed's evaluation curve here")
    args = parser.parse_args()

    env_id, target, _ = TASKS[args.task]
    root = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="time_to_skill_"))
    print(
        f"{env_id} to {100 * target:.0f} %, recipe {args.recipe}, "
        f"{args.eval_episodes} episodes per evaluation"
    )
    print(f"{'seed':>4s} {'timesteps':>10s} {'wall s':>8s}")
    rows = []
    for seed in args.seeds:
        out = root / f"seed{seed}"
        row = run_one(args.task, args.recipe, seed, args.eval_episodes, args.max_timesteps, out)
        rows.append(row)
        if row["reached"]:
            print(f"{seed:4d} {row['timesteps']:10,d} {row['wall_s']:8.0f}", flush=True)
        else:
            print(
                f"{seed:4d} not reached in {args.max_timesteps:,} steps ({row['total_s']:.0f} s)",
                flush=True,
            )
        if args.plot and seed == args.seeds[0]:
            plot_curve(out / "eval.csv", Path(args.plot), f"{env_id}, seed {seed}")
    reached = [r for r in rows if r["reached"]]
    if len(reached) * 2 > len(rows):
        # Seeds that never reached count as slower than every one that did.
        steps = sorted(
            [r["timesteps"] for r in reached] + [float("inf")] * (len(rows) - len(reached))
        )
        walls = sorted([r["wall_s"] for r in reached] + [float("inf")] * (len(rows) - len(reached)))
        print(
            f"\nmedian over {len(rows)} seeds: {statistics.median_low(steps):,.0f} timesteps, "
            f"{statistics.median_low(walls):.0f} s of wall time to {100 * target:.0f} %"
        )
    else:
        print(f"\n{100 * target:.0f} % not reached by most seeds: no median")
    if not args.out:
        shutil.rmtree(root)


if __name__ == "__main__":
    main()
