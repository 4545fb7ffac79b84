"""How soon Ctrl-C ends an evaluation inside training: a SIGINT is sent ``--after`` seconds
into the first evaluation of ``--episodes`` episodes (Block, PPO, 2 environments); printed are
the seconds from the signal to the evaluation's end, the policy steps it still played, and the
seconds to ``train()``'s return with its checkpoint written.

    python benchmarks/eval_interrupt.py [--episodes N] [--after S] [--out DIR]
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import tempfile
import time
from pathlib import Path

import foosball_gym.training.sb3.callbacks as callbacks
from foosball_gym.training.config import TrainConfig
from foosball_gym.training.sb3.trainer import train


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--after", type=float, default=2.0)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp()) / "run"
    shutil.rmtree(out, ignore_errors=True)
    real = callbacks.evaluate
    marks: dict[str, float] = {}

    def evaluate(policy, *a, **k):
        def acting(obs):
            now = time.perf_counter()
            marks.setdefault("first", now)
            if "sent" in marks:
                marks["steps_after"] = marks.get("steps_after", 0) + 1
            elif now - marks["first"] > args.after:
                marks["sent"] = now
                os.kill(os.getpid(), signal.SIGINT)
            return policy(obs)

        try:
            return real(acting, *a, **k)
        finally:
            marks["ended"] = time.perf_counter()

    callbacks.evaluate = evaluate
    config = TrainConfig(
        "Foosball-Block-v0",
        timesteps=2048,
        n_envs=2,
        n_steps=256,
        batch_size=128,
        eval_freq=512,
        eval_episodes=args.episodes,
        checkpoint_freq=100_000,
    )
    result = train(config, out)
    back = time.perf_counter()
    if "sent" not in marks:
        print(f"the evaluation ended before {args.after} s: give more --episodes")
        return
    print(
        f"SIGINT {args.after:g} s into an evaluation of {args.episodes} episodes: it ended "
        f"{marks['ended'] - marks['sent']:.3f} s later, after {int(marks.get('steps_after', 0))} "
        f"more policy steps; train() returned {back - marks['sent']:.3f} s after the signal "
        f"(stopped by {signal.Signals(result.signal).name if result.signal else 'nothing'} at "
        f"{result.timesteps} steps)"
    )


if __name__ == "__main__":
    main()
