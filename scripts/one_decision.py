"""Score with obstacles as one decision a serve, learned by a model of which decisions score.

    python scripts/one_decision.py [--layouts 8000] [--tries 10] [--rounds 1] [--keep 5]
        [--spin BACK,SWITCH,FORWARD] [--train-seed 10000] [--model-seed 0] [--episodes 200]
        [--seed 0] [--workers 2]

Not the per-step policy that PPO learns: here the keeper's whole serve is one decision, made on
the reset's observation and then played open loop. The decision is the slide, held at ``v`` in
[-1, 1] around the ball (``slide_around_ball`` 0.015 past ``slide_skip`` 0.009), and a
two-piece spin: the target ``back`` for the first ``switch`` steps, then ``forward``. Nothing in
it is scripted but that form.

1. **Trials.** On ``--layouts`` training balls (seeds ``train-seed ..``, apart from the
   development balls and the reserved ones), the keeper plays ``--tries`` decisions each, drawn
   at random: ``v`` uniform, the spin's three values from :data:`BACKS`, :data:`SWITCHES` and
   :data:`FORWARDS` (or the one ``--spin``). A trial is the ball's layout (its place and the
   three standing rods'), the decision, and whether it scored.
2. **Model.** A network of three layers of 256 learns the chance of a goal from the layout and
   the decision (cross-entropy, Adam), a tenth of the layouts held out to report its loss.
3. **Play.** On each of the balls ``seed .. seed + episodes - 1`` the keeper makes the decision
   with the highest predicted chance over a grid (81 values of ``v`` by each spin of the round)
   and plays it, counted as ``scripts/shot_lanes.py`` counts.

With ``--rounds`` above 1, each further round draws its trials on new training balls with only
the ``--keep`` spins that scored most often so far, and a new model learns from every trial;
each round is played. Last, the one decision that scored most often in the trials is played on
every ball, for comparison.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import foosball_gym  # noqa: F401  (registers the environments)
from foosball_gym.evaluation import wilson_interval

ENV_ID = "Foosball-Score-v0"
OPTIONS: dict[str, Any] = {
    "ball_start": "resting",
    "obstacles": True,
    "ball_to_goal_weight": 1000.0,
    "slide_around_ball": 0.015,
    "slide_skip": 0.009,
}
BACKS = (-0.6, -0.3, 0.0, 0.3, 0.6)  # spin targets, in units of 2 pi
SWITCHES = (4, 8)  # steps of the first piece
FORWARDS = (-0.6, -0.3, 0.0, 0.3, 0.6)
GRID_POINTS = 81  # held slide values tried in play
LAYOUT = ("ball_x", "ball_y", "away_keeper_slide_pos", "away_defense_slide_pos",
          "away_offense_slide_pos")  # fmt: skip


class OneDecision:
    """Plays ``decision`` (v, back, switch, forward) step by step: call :meth:`reset` between
    serves."""

    def __init__(self, decision: Sequence[float] | np.ndarray) -> None:
        v, back, switch, forward = (float(x) for x in decision)
        self.first = np.array([v, back], np.float32)
        self.second = np.array([v, forward], np.float32)
        self.switch = int(switch)
        self.steps = 0

    def reset(self) -> None:
        self.steps = 0

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        self.steps += 1
        return self.first if self.steps <= self.switch else self.second


def layout(names: Sequence[str], obs: np.ndarray) -> np.ndarray:
    """The ball's place and the standing rods' slides, and each slide less the ball's y (where
    the rod's figurines stand beside the ball)."""
    x, y, *slides = (float(obs[names.index(n)]) for n in LAYOUT)
    return np.array([x, y, *slides, *(s - y for s in slides)], np.float32)


def play(env: gym.Env, seed: int, decision: Sequence[float] | np.ndarray) -> tuple[bool, int]:
    """Whether ``decision`` scores on the ball of ``seed``, and in how many steps it ended."""
    keeper = OneDecision(decision)
    obs, _ = env.reset(seed=seed)
    done, info = False, dict[str, Any]()
    while not done:
        obs, _, terminated, truncated, info = env.step(keeper(obs))
        done = terminated or truncated
    return info.get("goal") == 1, keeper.steps


def all_spins() -> np.ndarray:
    """Every two-piece spin: (back, switch, forward) rows."""
    return np.array(list(itertools.product(BACKS, SWITCHES, FORWARDS)), np.float32)


def trials(
    first: int, layouts: int, tries: int, spins: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """``tries`` random decisions on each of ``layouts`` balls from seed ``first``, the slide
    uniform and the spin one of ``spins``: the layouts, the decisions, whether each scored,
    and the environment's steps in all."""
    env = gym.make(ENV_ID, **OPTIONS)
    names = list(env.unwrapped.obs_builder.names)  # type: ignore[attr-defined]
    rng = np.random.default_rng(first)
    rows, decisions, goals = [], [], []
    steps = 0
    for seed in range(first, first + layouts):
        obs, _ = env.reset(seed=seed)
        here = layout(names, obs)
        for _ in range(tries):
            decision = (rng.uniform(-1.0, 1.0), *spins[rng.integers(len(spins))])
            rows.append(here)
            decisions.append(decision)
            goal, length = play(env, seed, decision)
            goals.append(goal)
            steps += length
    env.close()
    return np.array(rows), np.array(decisions, np.float32), np.array(goals, np.float32), steps


def gather(
    first: int, layouts: int, tries: int, spins: np.ndarray, workers: int
) -> tuple[tuple[np.ndarray, ...], int]:
    """:func:`trials` split over ``workers`` processes by layout."""
    shares = [layouts // workers + (i < layouts % workers) for i in range(workers)]
    starts = [first + sum(shares[:i]) for i in range(workers)]
    with ProcessPoolExecutor(workers) as pool:
        parts = list(pool.map(trials, starts, shares, [tries] * workers, [spins] * workers))
    return tuple(np.concatenate([p[i] for p in parts]) for i in range(3)), sum(p[3] for p in parts)


class OutcomeModel:
    """The chance that a decision scores on a layout."""

    def __init__(self, rows: np.ndarray, decisions: np.ndarray, seed: int = 0) -> None:
        import torch

        torch.manual_seed(seed)
        self.mean, self.scale = rows.mean(0), rows.std(0) + 1e-8
        width = rows.shape[1] + decisions.shape[1]
        self.net = torch.nn.Sequential(
            torch.nn.Linear(width, 256), torch.nn.ReLU(),
            torch.nn.Linear(256, 256), torch.nn.ReLU(),
            torch.nn.Linear(256, 256), torch.nn.ReLU(),
            torch.nn.Linear(256, 1),
        )  # fmt: skip

    def inputs(self, rows: np.ndarray, decisions: np.ndarray) -> Any:
        import torch

        # The switch (4 or 8 steps) centred and scaled like the other entries of a decision.
        d = decisions * np.array([1.0, 1.0, 0.5, 1.0], np.float32) - np.array([0, 0, 3.0, 0])
        x = np.column_stack([(rows - self.mean) / self.scale, d]).astype(np.float32)
        return torch.from_numpy(x)

    def fit(
        self, rows: np.ndarray, decisions: np.ndarray, goals: np.ndarray, epochs: int, tries: int
    ) -> tuple[float, float]:
        """Train on nine layouts in ten; the loss on the last batch and on the tenth held out."""
        import torch
        from torch.nn.functional import binary_cross_entropy_with_logits as loss_of

        held = (np.arange(len(rows)) // tries) % 10 == 0
        x, y = self.inputs(rows, decisions), torch.from_numpy(goals.astype(np.float32))
        train = torch.from_numpy(np.flatnonzero(~held))
        optimiser = torch.optim.Adam(self.net.parameters(), 1e-3)
        loss = torch.zeros(())
        for _ in range(epochs):
            for batch in train[torch.randperm(len(train))].split(512):
                loss = loss_of(self.net(x[batch]).squeeze(1), y[batch])
                optimiser.zero_grad()
                loss.backward()
                optimiser.step()
        with torch.no_grad():
            kept = torch.from_numpy(np.flatnonzero(held))
            held_loss = loss_of(self.net(x[kept]).squeeze(1), y[kept]) if len(kept) else loss
        return loss.item(), held_loss.item()

    def best(self, row: np.ndarray, candidates: np.ndarray) -> np.ndarray:
        """The candidate decision most likely to score on ``row``'s layout."""
        import torch

        with torch.no_grad():
            logits = self.net(self.inputs(np.repeat(row[None], len(candidates), 0), candidates))
        return candidates[int(torch.argmax(logits))]


def candidates(spins: np.ndarray, points: int = GRID_POINTS) -> np.ndarray:
    """Every held slide value of a grid with every one of ``spins``."""
    grid = np.linspace(-1.0, 1.0, points)
    return np.array([(v, *spin) for v in grid for spin in spins], np.float32)


def best_spins(decisions: np.ndarray, goals: np.ndarray, keep: int) -> np.ndarray:
    """The ``keep`` spins that scored most often in ``decisions``' trials."""
    kinds, which = np.unique(decisions[:, 1:], axis=0, return_inverse=True)
    rates = np.bincount(which.ravel(), goals) / np.bincount(which.ravel())
    return kinds[np.argsort(-rates, kind="stable")[:keep]]


def most_scoring(decisions: np.ndarray, goals: np.ndarray) -> np.ndarray:
    """The spin that scored most often in the trials, with the held slide value (to 0.1) that
    scored most often with it."""
    spin = best_spins(decisions, goals, 1)[0]
    mine = (decisions[:, 1:] == spin).all(1)
    bins = np.round(decisions[mine, 0], 1)
    values = np.unique(bins)
    rates = [goals[mine][bins == v].mean() for v in values]
    return np.array([values[int(np.argmax(rates))], *spin], np.float32)


def spin_of(text: str) -> tuple[float, float, float]:
    """``BACK,SWITCH,FORWARD`` as :data:`BACKS`, :data:`SWITCHES` and :data:`FORWARDS` hold."""
    try:
        back, switch, forward = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"a spin is BACK,SWITCH,FORWARD, three numbers (e.g. -0.3,4,0.3), got {text!r}"
        ) from None
    if not (-1 <= back <= 1 and -1 <= forward <= 1 and switch >= 1 and switch == int(switch)):
        raise argparse.ArgumentTypeError(
            f"BACK and FORWARD are spin targets in [-1, 1] and SWITCH a whole number of steps "
            f"from 1, got {text!r}"
        )
    return back, switch, forward


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--layouts", type=int, default=8000, help="training balls a round")
    parser.add_argument("--tries", type=int, default=10, help="random decisions on each")
    parser.add_argument("--rounds", type=int, default=1, help="rounds of trials")
    parser.add_argument("--keep", type=int, default=5, help="spins kept after a round")
    parser.add_argument(
        "--spin",
        type=spin_of,
        help="one spin for every trial, BACK,SWITCH,FORWARD (e.g. -0.3,4,0.3)",
    )
    parser.add_argument("--train-seed", type=int, default=10_000, help="the first training ball")
    parser.add_argument("--model-seed", type=int, default=0, help="the network's first weights")
    parser.add_argument("--epochs", type=int, default=40)
    parser.add_argument("--episodes", type=int, default=200, help="balls played")
    parser.add_argument("--seed", type=int, default=0, help="the first ball played")
    parser.add_argument("--workers", type=int, default=2, help="processes for the trials")
    args = parser.parse_args(argv)
    for name in ("layouts", "tries", "rounds", "keep", "epochs", "episodes", "workers"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be at least 1, got {getattr(args, name)}")
    played = range(args.seed, args.seed + args.episodes)
    trained = range(args.train_seed, args.train_seed + args.layouts * args.rounds)
    if set(played) & set(trained):
        parser.error("the training balls (--train-seed on) overlap the balls played (--seed on)")
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import torch

    torch.set_num_threads(1)
    spins = all_spins() if args.spin is None else np.array([args.spin], np.float32)
    parts: list[tuple[np.ndarray, ...]] = []
    env = gym.make(ENV_ID, **OPTIONS)
    names = list(env.unwrapped.obs_builder.names)  # type: ignore[attr-defined]
    layouts = []
    for seed in played:
        obs, _ = env.reset(seed=seed)
        layouts.append(layout(names, obs))
    env.close()
    for round_ in range(args.rounds):
        start = time.perf_counter()
        first = args.train_seed + round_ * args.layouts
        part, steps = gather(first, args.layouts, args.tries, spins, args.workers)
        parts.append(part)
        print(
            f"round {round_ + 1}: {len(part[2])} trials of {len(spins)} spins on balls "
            f"{first}-{first + args.layouts - 1}, {part[2].mean():.1%} scored, {steps} steps, "
            f"{time.perf_counter() - start:.0f} s on {args.workers} processes"
        )
        rows, decisions, goals = (np.concatenate([p[i] for p in parts]) for i in range(3))
        model = OutcomeModel(rows, decisions, args.model_seed)
        start = time.perf_counter()
        last, held = model.fit(rows, decisions, goals, args.epochs, args.tries)
        print(
            f"model on {len(goals)} trials: {time.perf_counter() - start:.0f} s, "
            f"loss {last:.3f}, held-out layouts {held:.3f}"
        )
        grid = candidates(spins)
        decided = {seed: model.best(row, grid) for seed, row in zip(played, layouts, strict=True)}
        report("the model's decision", decided, args.seed, args.episodes)
        spins = best_spins(decisions, goals, args.keep)
    fixed = most_scoring(decisions, goals)
    one = f"v {fixed[0]:+.1f}, spin {fixed[1]:+.1f} for {int(fixed[2])} steps, then {fixed[3]:+.1f}"
    every = dict.fromkeys(played, fixed)
    report(f"one decision on every ball ({one})", every, args.seed, args.episodes)


def report(label: str, decisions: dict[int, np.ndarray], first: int, episodes: int) -> None:
    """Play each ball's decision and print the counts of ``scripts/shot_lanes.py``."""
    from shot_lanes import play as play_lanes  # a script beside this one
    from shot_lanes import summary

    keeper = Keeper(decisions, first)
    balls = play_lanes(keeper, OPTIONS, episodes, first, reset=keeper.next_ball)
    scored = sum(b.goal == 1 for b in balls)
    low, high = wilson_interval(scored, len(balls))
    print(f"{label}: {scored}/{len(balls)} scored (95 % {100 * low:.1f}-{100 * high:.1f} %)")
    print(summary(balls), flush=True)


class Keeper:
    """Plays each ball's decision in turn, the balls from ``first`` on."""

    def __init__(self, decisions: dict[int, np.ndarray], first: int) -> None:
        self.decisions, self.ball = decisions, first - 1
        self.now = OneDecision(decisions[first])

    def next_ball(self) -> None:
        self.ball += 1
        self.now = OneDecision(self.decisions[self.ball])

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return self.now(obs)


if __name__ == "__main__":
    main()
