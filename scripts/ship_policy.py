"""Copy a finished training run into the package as a built-in policy (``builtin:NAME``).

    python scripts/ship_policy.py RUN_DIR NAME --command "foosball train ..."

Ships the model (which holds its normalisation statistics; a run from before kept them beside
it in vecnormalize.json), the resolved configuration, the evaluation curve and a REPRODUCE.md
with the command and seed that made it.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

BUILTIN = Path(__file__).resolve().parents[1] / "foosball_gym" / "builtin"
FILES = ("model.zip", "vecnormalize.json", "config.json", "eval.csv", "eval.png")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("name")
    parser.add_argument("--command", required=True, help="the command that trained the run")
    parser.add_argument(
        "--note", default="", help="what else to know: wall time, machine, measured results"
    )
    args = parser.parse_args()
    target = BUILTIN / args.name
    target.mkdir(parents=True, exist_ok=True)
    for name in FILES:
        if (args.run / name).exists():
            shutil.copy2(args.run / name, target / name)
        else:  # the policy shipped there before had it: it is not this one's
            (target / name).unlink(missing_ok=True)
    config = json.loads((args.run / "config.json").read_text())
    (target / "REPRODUCE.md").write_text(
        f"# builtin:{args.name}\n\n"
        f"Trained on `{config['env_id']}` with seed {config['seed']}:\n\n"
        f"```bash\n{args.command}\n```\n\n"
        f"`config.json` is the resolved configuration of that run, `eval.csv` and `eval.png` its "
        f"evaluation curve ({config.get('eval_episodes', 50)} seeded episodes per point).\n"
        + (f"\n{args.note.strip()}\n" if args.note.strip() else "")
    )
    print(f"shipped {args.run} as builtin:{args.name} in {target}")


if __name__ == "__main__":
    main()
