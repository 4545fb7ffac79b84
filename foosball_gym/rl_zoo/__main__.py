"""``python -m foosball_gym.rl_zoo SCRIPT [ARGS]``: run ``rl_zoo3.SCRIPT`` with the
environment ids registered.

RL Zoo's ``record_video`` looks the id up in Gymnasium's registry before it makes an
environment and has no ``--gym-packages`` to import the package first, so on its own it fails
with a KeyError. Started from here, the package is imported before the script runs.
"""

from __future__ import annotations

import runpy
import sys
from collections.abc import Sequence

import foosball_gym  # noqa: F401  (registers the ids)

# Scripts that run in this process: record_training starts record_video in a new one, which
# would not see the ids.
SCRIPTS = ("train", "enjoy", "record_video")
USAGE = (
    "usage: python -m foosball_gym.rl_zoo {" + ",".join(SCRIPTS) + "} [ARGS]\n"
    "Runs rl_zoo3.SCRIPT with the foosball_gym environment ids registered; ARGS are the "
    "script's own (python -m rl_zoo3.SCRIPT --help)."
)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the RL Zoo script named by ``argv[0]`` with the rest of ``argv`` as its arguments.

    Args:
        argv: the script's name and its arguments (default: the process's arguments).

    Returns:
        0 after ``--help``, 2 for a missing or unknown script; otherwise the script's own exit.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] in (["-h"], ["--help"]):
        print(USAGE)
        return 0
    if not argv or argv[0] not in SCRIPTS:
        given = f"unknown script {argv[0]!r}" if argv else "no script given"
        print(f"{USAGE}\nerror: {given}; one of {', '.join(SCRIPTS)}", file=sys.stderr)
        return 2
    try:
        import rl_zoo3  # noqa: F401
    except ImportError:
        print(
            'error: RL Zoo is missing; install it with: pip install -e ".[zoo]" '
            '(in a checkout: pip install -e ".[zoo]")',
            file=sys.stderr,
        )
        return 2
    module = f"rl_zoo3.{argv[0]}"
    sys.argv = [module, *argv[1:]]
    runpy.run_module(module, run_name="__main__", alter_sys=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
