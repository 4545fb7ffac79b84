"""A run's evaluation curve, ``eval.csv`` and ``eval.png``, written alike by both backends.

Each row is one evaluation of the policy of the moment on the same seeded episodes
(:data:`EVAL_SEED` on), against the env's scripted opponent in two-player tasks.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from foosball_gym.training.run_dir.files import EVAL_CSV, EVAL_PNG, append_text, write_bytes

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
        """Add ``row`` to ``eval.csv`` (all of it or, where the disk is full, none of it) and
        draw ``eval.png`` again (where matplotlib is installed: the CSV is the record)."""
        append_text(self.csv, csv_text([row], header=not self.csv.exists()))
        try:
            plot_curve(self.csv, self.png, self.title)
        except ImportError:
            pass

    def cut(self, timesteps: int) -> list[dict[str, float]]:
        """Remove the rows after ``timesteps`` (a branch of the run that was lost), and
        return them."""
        rows = self.rows()
        kept = [r for r in rows if r["timesteps"] <= timesteps]
        if len(kept) < len(rows):
            write_bytes(self.csv, csv_text(kept, header=True).encode())
        return [r for r in rows if r["timesteps"] > timesteps]


def csv_text(rows: Sequence[Mapping[str, Any]], header: bool) -> str:
    """``rows`` as lines of ``eval.csv`` (its header first with ``header``)."""
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=EVAL_FIELDS, lineterminator="\n")
    if header:
        writer.writeheader()
    for row in rows:
        writer.writerow({k: _plain(v) for k, v in row.items()})
    return out.getvalue()


def _plain(value: Any) -> Any:
    # Rows read back are floats; the whole numbers among them are written as they were.
    return int(value) if isinstance(value, float) and value.is_integer() else value


def read_curve(csv_path: Path) -> list[dict[str, float]]:
    """The rows of ``eval.csv`` as numbers; ValueError naming the file and the row where it
    is damaged: a value that is no number, or a time (``timesteps``, ``wall_seconds``) that is
    no finite one, which no later step could be placed after (a resumed run's cut would lose
    that row without a word)."""
    try:
        with Path(csv_path).open(encoding="utf-8", newline="") as f:
            return _rows(csv_path, csv.DictReader(f))
    except UnicodeDecodeError as err:
        raise ValueError(
            f"{csv_path} is not an evaluation curve: not UTF-8 text (byte {err.start})"
        ) from None


def _rows(csv_path: Path, reader: csv.DictReader) -> list[dict[str, float]]:
    if reader.fieldnames is None:
        return []
    missing = [k for k in ("timesteps", "wall_seconds") if k not in reader.fieldnames]
    if missing:
        raise ValueError(f"{csv_path} is not an evaluation curve: it has no {missing[0]}")
    rows = []
    for line, row in enumerate(reader, start=2):
        try:
            values = {k: float(v) for k, v in row.items() if k is not None}
        except (TypeError, ValueError):
            raise ValueError(f"{csv_path}, line {line}: not a row of numbers") from None
        for key in ("timesteps", "wall_seconds"):
            if not math.isfinite(values[key]):
                raise ValueError(
                    f"{csv_path}, line {line}: its {key} is {row[key]}, not a finite number"
                )
        rows.append(values)
    return rows


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
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    plt.close(fig)
    write_bytes(png_path, buffer.getvalue())
