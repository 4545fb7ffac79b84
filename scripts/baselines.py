"""The from-scratch baselines: each task's recipe trained over seeds, evaluated on reserved seeds.

    python scripts/baselines.py train  [--task NAME ...] [--seeds 1-5] [--runs runs/baselines]
    python scripts/baselines.py report [--csv docs/results/baselines.csv] [--images docs/images]

``train`` trains every task and seed that has no rows in the CSV yet, one run at a time, with
``foosball train ENV_ID --config builtin:RECIPE --seed S --out RUNS/TASK/seed-S`` (a folder that
holds an interrupted run is resumed), then evaluates the run's checkpoint at each budget on
:data:`EVAL_EPISODES` episodes from :data:`EVAL_SEED` on, which no development run looks at,
and appends a row per budget to the CSV. Any row is reproduced by the two commands it prints.

``report`` prints, for each task and budget, the interquartile mean of success over the seeds
with its 95 % stratified-bootstrap interval (rliable), and draws each task's curve.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import textwrap
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

# Episodes seeded from here on judge the baselines; development evaluates elsewhere (the
# training curves from 1,000,000, `foosball eval` by default from 0).
EVAL_SEED = 2_000_000
EVAL_EPISODES = 500
FIELDS = (
    "task",
    "env_id",
    "options",
    "algorithm",
    "config",
    "seed",
    "env_steps",
    "wall_seconds",
    "success",
    "ci_low",
    "ci_high",
    "eval_seed",
    "eval_episodes",
    "machine",
    "learner",
)
HERE = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class Task:
    env_id: str
    recipe: str
    budgets: tuple[int, ...]
    # Options given beside the recipe (foosball train's, e.g. --learner torch).
    options: tuple[str, ...] = ()


TASKS = {
    "block": Task(
        "Foosball-Block-v0", "builtin:block-scratch", (100_000, 200_000, 300_000, 500_000)
    ),
    # The Block recipe before its rollouts were played in the workers: SB3's rollout loop.
    "block-sb3-loop": Task(
        "Foosball-Block-v0",
        "builtin:block-scratch",
        (100_000, 200_000, 300_000, 500_000),
        ("--no-worker-rollouts",),
    ),
    # The Block recipe as its rows were first measured: SB3's rollout loop and PyTorch update.
    "block-torch": Task(
        "Foosball-Block-v0",
        "builtin:block-scratch",
        (100_000, 200_000, 300_000, 500_000),
        ("--learner", "torch", "--no-worker-rollouts"),
    ),
    "score-resting": Task(
        "Foosball-Score-v0",
        "builtin:score-resting-scratch",
        (500_000, 1_000_000, 2_000_000, 4_000_000),
    ),
    "score-incoming": Task(
        "Foosball-Score-v0", "builtin:score-incoming-scratch", (500_000, 1_000_000, 2_000_000)
    ),
    # The incoming recipe as its rows were first measured: joint velocities observed, SB3's
    # PyTorch update.
    "score-incoming-velocities": Task(
        "Foosball-Score-v0",
        "builtin:score-incoming-scratch",
        (500_000, 1_000_000, 2_000_000),
        ("--env-kwarg", "joint_velocities=True", "--learner", "torch"),
    ),
    # The incoming recipe exploring by gSDE (its development run 10).
    "score-incoming-gsde": Task(
        "Foosball-Score-v0",
        "builtin:score-incoming-scratch",
        (500_000, 1_000_000, 2_000_000),
        ("--use-sde", "--sde-sample-freq", "4", "--log-std-init", "-2"),
    ),
    # The incoming recipe with the ball's-aim reward, trained three times as long (its curve still
    # rose steeply at 2,000,000).
    "score-incoming-aim": Task(
        "Foosball-Score-v0",
        "builtin:score-incoming-scratch",
        (500_000, 1_000_000, 2_000_000, 4_000_000, 6_000_000),
        ("--env-kwarg", "ball_aim_weight=300", "--worker-rollouts", "--timesteps", "6000000"),
    ),
    # The same with an entropy bonus, which kept the policy exploring where two seeds stalled
    # (development runs 13 and 13a).
    "score-incoming-aim-entropy": Task(
        "Foosball-Score-v0",
        "builtin:score-incoming-scratch",
        (500_000, 1_000_000, 2_000_000, 4_000_000, 6_000_000),
        ("--env-kwarg", "ball_aim_weight=300", "--worker-rollouts", "--timesteps", "6000000")
        + ("--ent-coef", "0.01"),
    ),
    "score-obstacles": Task(
        "Foosball-Score-v0",
        "builtin:score-obstacles-scratch",
        (500_000, 1_000_000, 2_000_000, 4_000_000),
    ),
    # The obstacles recipe with the paper's batch, 131,072 samples an update (development run 15).
    "score-obstacles-paper-batch": Task(
        "Foosball-Score-v0",
        "builtin:score-obstacles-paper-batch-scratch",
        (2_000_000, 5_000_000, 10_000_000, 20_000_000, 30_000_000),
    ),
}


def machine() -> str:
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cores} cores, {model}"


def _foosball(*args: str) -> list[str]:
    return [sys.executable, "-m", "foosball_gym.cli", *args]


def run_dir(runs: Path, task: str, seed: int) -> Path:
    return runs / task / f"seed-{seed}"


def train_command(task: Task, seed: int, out: Path) -> list[str]:
    return ["foosball", "train", task.env_id, "--config", task.recipe, *task.options,
            "--seed", str(seed), "--out", str(out)]  # fmt: skip


def budget_model(run: Path, steps: int) -> Path:
    """The model a run had after ``steps`` steps: its checkpoint there, or its final model."""
    checkpoint = run / "checkpoints" / f"model_{steps:010d}.zip"
    if checkpoint.is_file():
        return checkpoint
    config = json.loads((run / "config.json").read_text())
    if int(config["timesteps"]) == steps and (run / "model.zip").is_file():
        return run / "model.zip"
    raise SystemExit(f"{run} has no model at {steps:,} steps (no {checkpoint.name})")


def eval_command(model: Path, episodes: int = EVAL_EPISODES) -> list[str]:
    return ["foosball", "eval", str(model), "--episodes", str(episodes),
            "--seed", str(EVAL_SEED)]  # fmt: skip


def wall_at(run: Path, steps: int) -> float:
    """The run's training time to ``steps``, from its curve (linear between its points)."""
    with open(run / "eval.csv", newline="") as f:
        rows = [(float(r["timesteps"]), float(r["wall_seconds"])) for r in csv.DictReader(f)]
    before = [(t, w) for t, w in rows if t <= steps]
    after = [(t, w) for t, w in rows if t >= steps]
    if not before or not after:
        return rows[-1][1] if rows else float("nan")
    (t0, w0), (t1, w1) = before[-1], after[0]
    return w0 if t1 == t0 else w0 + (w1 - w0) * (steps - t0) / (t1 - t0)


def train(args: argparse.Namespace, tasks: dict[str, Task] = TASKS) -> None:
    done = {(r["task"], int(r["seed"])) for r in _read(args.csv)}
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    for name in args.task:
        task = tasks[name]
        for seed in args.seeds:
            if (name, seed) in done:
                continue
            out = run_dir(args.runs, name, seed)
            command = train_command(task, seed, out)
            if (out / "config.json").is_file() and not (out / "model.zip").is_file():
                command = ["foosball", "train", "--resume", str(out)]
            print("+", shlex.join(command), flush=True)
            if not (out / "model.zip").is_file():
                start = time.perf_counter()
                subprocess.run(_foosball(*command[1:]), check=True, env=env)
                print(f"  trained in {time.perf_counter() - start:.0f} s", flush=True)
            rows = [
                evaluate_budget(name, task, seed, out, steps, env, args.episodes)
                for steps in task.budgets
            ]
            _append(args.csv, rows)


def evaluate_budget(
    name: str, task: Task, seed: int, run: Path, steps: int, env: dict[str, str], episodes: int
) -> dict[str, object]:
    model = budget_model(run, steps)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "result.json"
        command = eval_command(model, episodes)
        print("+", shlex.join(command), flush=True)
        subprocess.run(_foosball(*command[1:], "--json", str(path)), check=True, env=env,
                       stdout=subprocess.DEVNULL)  # fmt: skip
        result = json.loads(path.read_text())
    config = json.loads((run / "config.json").read_text())
    row = {
        "task": name,
        "env_id": task.env_id,
        "options": json.dumps(config.get("env_kwargs", {}), sort_keys=True),
        "algorithm": config["algo"],
        "config": task.recipe,
        "seed": seed,
        "env_steps": steps,
        "wall_seconds": round(wall_at(run, steps), 1),
        "success": result["success_rate"],
        "ci_low": round(result["ci_low"], 4),
        "ci_high": round(result["ci_high"], 4),
        "eval_seed": EVAL_SEED,
        "eval_episodes": episodes,
        "machine": machine(),
        # Runs from before the field existed updated with PyTorch.
        "learner": config.get("learner", "torch"),
    }
    print(f"  {name} seed {seed}, {steps:,} steps: {100 * row['success']:.1f} %", flush=True)
    return row


def _read(path: Path) -> list[dict[str, str]]:
    if not path.is_file():
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _append(path: Path, rows: list[dict[str, object]]) -> None:
    new = not path.is_file()
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=FIELDS)
        if new:
            writer.writeheader()
        writer.writerows(rows)


def budget_of(steps: int) -> int:
    """The budget a run's ``steps`` belong to: the steps to two significant figures, so that
    runs of a budget counted in serves, whose steps differ by the serves' lengths, share a cell
    (every budget of the PPO recipes is already so round)."""
    return int(float(f"{steps:.2g}"))


def aggregate(rows: list[dict[str, str]], reps: int = 2000) -> dict[tuple[str, int], dict]:
    """For each (task, :func:`budget_of` the steps): seeds, the interquartile mean of success
    and its 95 % stratified-bootstrap interval, median, min and wall seconds' median."""
    import numpy as np
    from rliable import library as rly
    from rliable import metrics

    cells: dict[tuple[str, int], list[dict[str, str]]] = {}
    for row in rows:
        cells.setdefault((row["task"], budget_of(int(row["env_steps"]))), []).append(row)
    out = {}
    for key, cell in sorted(cells.items()):
        scores = np.array([[float(r["success"])] for r in cell])
        with warnings.catch_warnings():
            # rliable hands the seeded generator to arch the way arch means to retire.
            warnings.simplefilter("ignore", FutureWarning)
            np.random.seed(0)  # the bootstrap draws from NumPy's global generator too
            point, interval = rly.get_interval_estimates(
                {"recipe": scores},
                lambda x: np.array([metrics.aggregate_iqm(x)]),
                reps=reps,
                # Seeded: the same CSV gives the same intervals, run after run.
                random_state=np.random.RandomState(0),
            )
        success = scores[:, 0]
        out[key] = {
            "seeds": len(cell),
            "iqm": float(point["recipe"][0]),
            "low": float(interval["recipe"][0, 0]),
            "high": float(interval["recipe"][1, 0]),
            "median": float(np.median(success)),
            "min": float(success.min()),
            "wall_median": float(np.median([float(r["wall_seconds"]) for r in cell])),
        }
    return out


def report(args: argparse.Namespace) -> None:
    rows = _read(args.csv)
    if not rows:
        raise SystemExit(f"{args.csv} holds no rows yet: run `train` first")
    table = aggregate(rows)
    print(f"{'task':>16s} {'env steps':>10s} {'seeds':>5s} {'IQM':>6s} {'95 % CI':>13s} "
          f"{'median':>6s} {'worst':>6s} {'wall (median)':>13s}")  # fmt: skip
    for (task, steps), cell in table.items():
        print(
            f"{task:>16s} {steps:>10,d} {cell['seeds']:>5d} {100 * cell['iqm']:5.1f}% "
            f"{100 * cell['low']:5.1f}-{100 * cell['high']:5.1f}% {100 * cell['median']:5.1f}% "
            f"{100 * cell['min']:5.1f}% {cell['wall_median']:11.0f} s"
        )
    _plot(table, rows, args.images)


def _plot(table: dict[tuple[str, int], dict], rows: list[dict[str, str]], images: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    images.mkdir(parents=True, exist_ok=True)
    for task in sorted({t for t, _ in table}):
        steps = sorted(s for t, s in table if t == task)
        cells = [table[(task, s)] for s in steps]
        fig, ax = plt.subplots(figsize=(5, 3.2))
        ax.fill_between(steps, [100 * c["low"] for c in cells], [100 * c["high"] for c in cells],
                        alpha=0.25, label="95 % stratified bootstrap CI")  # fmt: skip
        ax.plot(steps, [100 * c["iqm"] for c in cells], "o-", label="IQM over seeds")
        for n, seed in enumerate(sorted({r["seed"] for r in rows if r["task"] == task})):
            mine = sorted(
                (int(r["env_steps"]), 100 * float(r["success"]))
                for r in rows
                if r["task"] == task and r["seed"] == seed
            )
            label = "each seed" if n == 0 else None
            ax.plot(*zip(*mine), color="grey", lw=0.7, alpha=0.6, label=label)
        ax.set_xscale("log")
        # The budgets themselves, written short: log-scale minor ticks crowd one another.
        ax.set_xticks(steps, [_short(s) for s in steps])
        ax.minorticks_off()
        ax.set_xlabel("env steps")
        ax.set_ylabel(f"success, {EVAL_EPISODES} episodes (%)")
        ax.set_title(_title(task, rows), fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right", fontsize=8)
        fig.tight_layout()
        path = images / f"baselines-{task}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        print(f"wrote {path}")


def _short(steps: int) -> str:
    return f"{steps / 1e6:g}M" if steps >= 1_000_000 else f"{steps // 1000}k"


def _title(task: str, rows: Sequence[dict[str, str]] = ()) -> str:
    """The task and the whole command line of its recipe, wrapped to fit the plot: for a task
    that ``train`` does not run, its rows' ``config``."""
    if task in TASKS:
        recipe = " ".join((TASKS[task].recipe, *TASKS[task].options))
    else:
        recipe = next((r["config"] for r in rows if r["task"] == task and r.get("config")), "")
        if not recipe:
            return task
    return "\n".join(textwrap.wrap(f"{task}: {recipe}", 70))


def _seeds(text: str) -> list[int]:
    low, sep, high = text.partition("-")
    try:
        return list(range(int(low), int(high) + 1)) if sep else [int(s) for s in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seeds as 1-5 or 1,2,3; got {text!r}") from None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    parser.add_argument("--csv", type=Path, default=HERE / "docs/results/baselines.csv")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("train", help="train and evaluate what the CSV lacks", allow_abbrev=False)
    run.add_argument("--task", nargs="+", choices=sorted(TASKS), default=sorted(TASKS))
    run.add_argument("--seeds", type=_seeds, default=list(range(1, 6)), help="e.g. 1-5")
    run.add_argument("--runs", type=Path, default=Path("runs/baselines"))
    run.add_argument("--episodes", type=int, default=EVAL_EPISODES, help="evaluation episodes")
    rep = sub.add_parser("report", help="the table and the curves", allow_abbrev=False)
    rep.add_argument("--images", type=Path, default=HERE / "docs/images")
    args = parser.parse_args()
    train(args) if args.command == "train" else report(args)


if __name__ == "__main__":
    main()
