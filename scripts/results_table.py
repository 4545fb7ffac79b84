"""Markdown rows for the README's results table from `foosball eval --json` files.

    python scripts/results_table.py TRAINED.json SCRIPTED.json PAPER [TRAINED.json ...]

Each triple is one row: the trained policy's result, the scripted baseline's, and the paper's
reported figure (text).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def cell(path: str) -> str:
    r = json.loads(Path(path).read_text())
    return (f"{100 * r['success_rate']:.1f} % ({100 * r['ci_low']:.1f}-{100 * r['ci_high']:.1f}), "
            f"goals {r['goals_for']}/{r['goals_against']}")


def main() -> None:
    args = sys.argv[1:]
    if len(args) % 3:
        sys.exit(__doc__)
    for trained, scripted, paper in zip(args[::3], args[1::3], args[2::3]):
        r = json.loads(Path(trained).read_text())
        task = r["env_id"] + "".join(f" {k}={v}" for k, v in r["env_kwargs"].items()
                                     if k in ("ball_start", "obstacles"))
        print(f"| {task} | {cell(trained)} | {cell(scripted)} | {paper} |")


if __name__ == "__main__":
    main()
