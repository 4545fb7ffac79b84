"""A run's evaluation curve (``eval.csv``): read it, and plot it as a PNG."""

from __future__ import annotations

import csv
from pathlib import Path


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
