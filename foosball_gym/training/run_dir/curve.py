"""A run's evaluation curve, ``eval.csv`` and ``eval.png``, written alike by both backends.

Each row is one evaluation of the policy of the moment on the same seeded episodes
(:data:`EVAL_SEED` on), against the env's scripted opponent in two-player tasks.
"""

from __future__ import annotations

import csv
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from foosball_gym.training.run_dir.files import EVAL_CSV, EVAL_PNG

# The first seed of every evaluation's episodes.
EVAL_SEED = 1_000_000
EVAL_FIELDS = (
    "timesteps",
    "wall_seconds",
    "success_rate",
    "ci_low",
    "ci_high",
    "mean_reward",
    "mean_length",
    "goals_for",
    "goals_against",
)


def eval_row(result: Any, timesteps: int, wall_seconds: float) -> dict[str, Any]:
    """The row of ``eval.csv`` for an :class:`~foosball_gym.evaluation.EvalResult` after
    ``timesteps`` steps and ``wall_seconds`` of training."""
    return {
        "timesteps": int(timesteps),
        "wall_seconds": round(wall_seconds, 2),
        "success_rate": result.success_rate,
        "ci_low": round(result.ci_low, 4),
        "ci_high": round(result.ci_high, 4),
        "mean_reward": round(result.mean_reward, 3),
        "mean_length": result.mean_length,
        "goals_for": result.goals_for,
        "goals_against": result.goals_against,
    }


class EvalCurve:
    """The curve of the run in ``run``: its rows so far, and a row added and drawn."""

    def __init__(self, run: Path, title: str) -> None:
        self.csv = Path(run) / EVAL_CSV
        self.png = Path(run) / EVAL_PNG
        self.title = title

    def rows(self) -> list[dict[str, float]]:
        """The rows written so far (none before the first evaluation)."""
        return read_curve(self.csv) if self.csv.exists() else []

    def wall_seconds(self) -> float:
        """The training time of the last row: where a resumed run's clock goes on from."""
        rows = self.rows()
        return rows[-1]["wall_seconds"] if rows else 0.0

    def append(self, row: Mapping[str, Any]) -> None:
        """Add ``row`` to ``eval.csv`` and draw ``eval.png`` again (where matplotlib is
        installed: the CSV is the record)."""
        new = not self.csv.exists()
        with self.csv.open("a", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=EVAL_FIELDS)
            if new:
                writer.writeheader()
            writer.writerow(row)
        try:
            plot_curve(self.csv, self.png, self.title)
        except ImportError:
            pass


def read_curve(csv_path: Path) -> list[dict[str, float]]:
    with Path(csv_path).open() as f:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def plot_curve(csv_path: Path, png_path: Path, title: str) -> None:
    """Success rate (with its 95 % interval) and mean reward against timesteps, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = read_curve(csv_path)
    t = [r["timesteps"] for r in rows]
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(6, 5), sharex=True)
    ax1.plot(t, [100 * r["success_rate"] for r in rows], marker="o", ms=3)
    ax1.fill_between(
        t, [100 * r["ci_low"] for r in rows], [100 * r["ci_high"] for r in rows], alpha=0.2
    )
    ax1.set_ylabel("success rate (%)")
    ax1.set_ylim(-2, 102)
    ax1.grid(alpha=0.3)
    ax1.set_title(title)
    ax2.plot(t, [r["mean_reward"] for r in rows], color="tab:orange", marker="o", ms=3)
    ax2.set_ylabel("mean episode reward")
    ax2.set_xlabel("timesteps")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    tmp = png_path.with_name(png_path.name + ".tmp.png")
    fig.savefig(tmp, dpi=100)
    plt.close(fig)
    tmp.replace(png_path)
