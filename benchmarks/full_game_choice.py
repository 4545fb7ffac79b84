"""A learner that chooses the attacking team's shots instead of nudging its actions.

The attacking team (the top of the full game's scripted ladder) plays every rod; only where
one of its rods has a ball to shoot does a choice come up: which of a few shots to make, or
to hold the swing a moment. The chosen shot is carried out as the team carries out its own,
and held until the shot is made. So a learner explores by choosing differently, never by
shaking a precise kick (``benchmarks/full_game_noise.py`` has what that noise costs).

    python benchmarks/full_game_choice.py --matches 50             # each shot always made
    python benchmarks/full_game_choice.py --train 40000 --matches 50 --save runs/choice
    python benchmarks/full_game_choice.py --oracle --matches 50 --save runs/oracle.npz
    python benchmarks/full_game_choice.py --imitate runs/oracle*.npz --matches 50 --seed 0
    python benchmarks/full_game_choice.py --sensitivity 50 --seed 0

The first plays each option on its own, and a choice at random, against the attacking team.
The second trains PPO (Stable-Baselines3) over the choices for that many decisions in two
processes, then plays its deterministic choices. The third bounds what any chooser over these
shots could gain: at each choice it plays every option out on a copy of the match (the
opponent's replies included) and makes the one that did best, saving each choice's observation
and the outcomes of its options. The fourth learns those outcomes from the observation and
plays the learned choices, with no lookahead. The fifth asks how far an outcome can be known
from the observation at all: how many outcomes a ball moved by 0.1 or 1 mm keeps. Matches are
continuous one-minute matches of ``Foosball-FullGame-v0``, seeds 5000 on (the last three:
from ``--seed``); each prints goals for and against.
"""

from __future__ import annotations

import argparse
import copy
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

import foosball_gym  # noqa: F401  (registers the environments)
from foosball_gym import table
from foosball_gym.policies import shots
from foosball_gym.policies.aiming import MAX_ANGLE
from foosball_gym.policies.attack import AttackingTeam

# The shots a rod with the ball may make: the team's own plan, the plan against defenders
# that do not move, straight ahead, a bank shot into the corner beside the goal, corner kicks
# to either side, or holding the swing (for WAIT_STEPS, then the choice comes up again).
OPTIONS = ("plan", "standing", "straight", "bank", "left", "right", "wait")
WAIT_STEPS = 6
# How far ahead the oracle plays each option out: 2 s of play, a shot's flight and the first
# reply to it.
LOOKAHEAD_STEPS = 120
SIDE_ANGLE = 0.6 * MAX_ANGLE
FIRST_SEED = 5000


class ChoosingTeam(AttackingTeam):
    """The attacking team, shooting the option ``choice`` names instead of its own plan."""

    def __init__(self, names: Sequence[str], rods: Sequence[str]) -> None:
        super().__init__(names, rods)
        self.choice = 0

    def shot_angle(
        self, x: float, y: float, defenders: Sequence[tuple[table.Rod, float]]
    ) -> float | None:
        option = OPTIONS[self.choice]
        if option == "plan":
            return super().shot_angle(x, y, defenders)
        if option == "standing":
            return shots.plan_reacting_shot(x, y, defenders, react=False)[0]
        if option == "bank":
            last, slide = max(defenders, key=lambda d: d[0].x)
            return shots.corner_shot(x, y, last, slide)
        if option == "wait":
            return None
        return {"straight": 0.0, "left": SIDE_ANGLE, "right": -SIDE_ANGLE}[option]


class ShotChoiceEnv(gym.Env):
    """Continuous one-minute matches against the attacking team in which a step is one choice.

    Between choices the home team plays on by itself. The observation is the full game's,
    with the shooting rod one-hot after it (keeper, defence, midfield, offence); the reward
    is goals for less goals against since the last choice.
    """

    def __init__(self) -> None:
        self.game = gym.make("Foosball-FullGame-v0", continuous=True)
        names = self.game.unwrapped.obs_builder.names
        self.team = ChoosingTeam(names, [f"{table.HOME}_{role}" for role in table.ROLES])
        size = self.game.observation_space.shape[0] + len(table.ROLES)
        self.observation_space = spaces.Box(-np.inf, np.inf, (size,), np.float32)
        self.action_space = spaces.Discrete(len(OPTIONS))
        self._obs: np.ndarray = np.zeros(0)
        self._held: int | None = None
        self._held_steps = 0
        self._score = (0, 0)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self._obs, info = self.game.reset(seed=seed)
        self._held, self._held_steps, self._score = None, 0, (0, 0)
        rod = self._choice_due()
        if rod is not None:
            return self._view(rod), info
        obs, _, _, _, info = self._play_on()
        return obs, info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        self._choose(int(action))
        return self._play_on()

    def _choose(self, choice: int) -> None:
        """Makes ``choice`` for the rod that has the ball now, held until it has shot."""
        self.team.choice = choice
        self._held, self._held_steps = self.team.shooter(self._obs), 0

    def _play_on(self) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Plays until a choice comes up or the match ends."""
        reward = 0.0
        while True:
            self._obs, _, terminated, truncated, info = self.game.step(self.team(self._obs))
            score = (info["goals_for"], info["goals_against"])
            reward += (score[0] - self._score[0]) - (score[1] - self._score[1])
            self._score = score
            if terminated or truncated:
                return self._view(None), reward, terminated, truncated, info
            rod = self._choice_due()
            if rod is not None:
                return self._view(rod), reward, False, False, info

    def _choice_due(self) -> int | None:
        """The rod whose shot is to be chosen now: one that has a new ball to shoot, or whose
        held swing has waited long enough."""
        rod = self.team.shooter(self._obs)
        waited = OPTIONS[self.team.choice] == "wait" and self._held_steps >= WAIT_STEPS
        if rod is not None and (rod != self._held or waited):
            return rod
        self._held = rod
        self._held_steps += 1
        return None

    def _view(self, rod: int | None) -> np.ndarray:
        shooter = np.zeros(len(table.ROLES), np.float32)
        if rod is not None:
            shooter[rod] = 1.0
        return np.concatenate([np.asarray(self._obs, np.float32), shooter])

    def close(self) -> None:
        self.game.close()


def play(choose: Any, matches: int, first_seed: int = FIRST_SEED) -> tuple[int, int, list[int]]:
    """Goals for and against, and how often each option was chosen, over ``matches``
    matches where ``choose(obs)`` picks each shot."""
    env = ShotChoiceEnv()
    goals_for = goals_against = 0
    counts = [0] * len(OPTIONS)
    for seed in range(first_seed, first_seed + matches):
        obs, info = env.reset(seed=seed)
        done = False
        while not done:
            choice = int(choose(obs))
            counts[choice] += 1
            obs, _, terminated, truncated, info = env.step(choice)
            done = terminated or truncated
        goals_for += info["goals_for"]
        goals_against += info["goals_against"]
    env.close()
    return goals_for, goals_against, counts


def play_out(env: ShotChoiceEnv, choice: int, shift: float | None = None) -> int:
    """Goals for less against in the LOOKAHEAD_STEPS after making ``choice`` in a copy of
    ``env``, the team's plan for every later choice; stops at the first goal. ``shift`` (m)
    puts the copy's ball back first, moved that far across the table."""
    trial = copy.deepcopy(env)
    if shift is not None:
        sim = trial.game.unwrapped.sim
        (x, y, z), orientation, velocity, spin = sim._ball_full()
        sim._put_ball(((x, y + shift, z), orientation, velocity, spin))
    trial._choose(choice)
    start = trial._score
    for _ in range(LOOKAHEAD_STEPS):
        trial._obs, _, terminated, truncated, info = trial.game.step(trial.team(trial._obs))
        scored = info["goals_for"] - start[0] - (info["goals_against"] - start[1])
        if scored or terminated or truncated:
            break
        if trial._choice_due() is not None:
            trial._choose(0)
    trial.close()
    return scored


def oracle(matches: int, first_seed: int, save: Path) -> None:
    """Each choice made by playing every option out first (the plan wherever none does better),
    over ``matches`` matches; saves every choice's observation and its options' outcomes."""
    env = ShotChoiceEnv()
    observations, outcomes = [], []
    goals_for = goals_against = 0
    start = time.perf_counter()
    for seed in range(first_seed, first_seed + matches):
        obs, info = env.reset(seed=seed)
        done = False
        while not done:
            values = np.array([play_out(env, k) for k in range(len(OPTIONS))])
            observations.append(obs)
            outcomes.append(values)
            best = 0 if values[0] == values.max() else int(np.argmax(values))
            obs, _, terminated, truncated, info = env.step(best)
            done = terminated or truncated
        goals_for += info["goals_for"]
        goals_against += info["goals_against"]
        print(
            f"seed {seed}: {info['goals_for']}:{info['goals_against']}, so far "
            f"{goals_for}:{goals_against}, {len(outcomes)} choices, "
            f"{time.perf_counter() - start:.0f} s",
            flush=True,
        )
    env.close()
    save.parent.mkdir(parents=True, exist_ok=True)
    np.savez(save, observations=np.array(observations), outcomes=np.array(outcomes))
    scored, conceded = (np.array(outcomes) > 0).sum(0), (np.array(outcomes) < 0).sum(0)
    print(f"the oracle's choices, {matches} matches: {goals_for} for, {goals_against} against")
    print("choices where an option scored / conceded within the lookahead:")
    for k, name in enumerate(OPTIONS):
        print(f"  {name:9s} {scored[k]:5d} {conceded[k]:5d}")


def sensitivity(choices: int, first_seed: int) -> None:
    """How much of an option's outcome a ball moved by a fraction of a millimetre keeps: at
    ``choices`` choices of the attacking team's own play, each option played out with the ball
    put back where it was and moved 0.1 and 1 mm across (and, to check that putting it back
    changes nothing by itself, left alone)."""
    env = ShotChoiceEnv()
    shifts: tuple[float | None, ...] = (None, 0.0001, 0.001)
    same = np.zeros((len(shifts), len(OPTIONS)))
    kept = np.zeros(len(shifts))
    scoring = 0
    seed, done, seen = first_seed, True, 0
    while seen < choices:
        if done:
            env.reset(seed=seed)
            seed += 1
        base = np.array([play_out(env, k, 0.0) for k in range(len(OPTIONS))])
        scoring += int((base > 0).sum())
        for i, shift in enumerate(shifts):
            moved = np.array(
                [play_out(env, k, shift and shift * (-1) ** seen) for k in range(len(OPTIONS))]
            )
            same[i] += moved == base
            kept[i] += ((moved > 0) & (base > 0)).sum()
        seen += 1
        _, _, terminated, truncated, _ = env.step(0)
        done = terminated or truncated
    env.close()
    print(f"{choices} choices of the attacking team's play from seed {first_seed}:")
    print(f"  options scoring with the ball put back as it was: {scoring}")
    for i, shift in enumerate(shifts):
        agree = ", ".join(f"{name} {n / choices:.0%}" for name, n in zip(OPTIONS, same[i]))
        how = "left alone" if shift is None else f"moved {shift * 1000:.1f} mm"
        print(f"  {how}: still scoring {int(kept[i])}; same outcome: {agree}")


class OutcomeModel:
    """Predicts, from a choice's observation, the chance that each option scores and that it
    concedes within the lookahead; chooses the option whose chance to score less its chance to
    concede beats the plan's by more than ``margin``."""

    def __init__(self, size: int, margin: float = 0.0) -> None:
        import torch

        self.net = torch.nn.Sequential(
            torch.nn.Linear(size, 256),
            torch.nn.ReLU(),
            torch.nn.Linear(256, 256),
            torch.nn.ReLU(),
            torch.nn.Linear(256, 2 * len(OPTIONS)),
        )
        self.mean = np.zeros(size, np.float32)
        self.std = np.ones(size, np.float32)
        self.margin = margin

    def fit(self, obs: np.ndarray, outcomes: np.ndarray, epochs: int = 300) -> None:
        import torch

        self.mean, self.std = obs.mean(0), obs.std(0) + 1e-6
        x = torch.as_tensor((obs - self.mean) / self.std, dtype=torch.float32)
        y = torch.as_tensor(np.concatenate([outcomes > 0, outcomes < 0], 1), dtype=torch.float32)
        optimiser = torch.optim.Adam(self.net.parameters(), lr=1e-3, weight_decay=1e-4)
        generator = torch.Generator().manual_seed(0)
        for _ in range(epochs):
            for batch in torch.randperm(len(x), generator=generator).split(256):
                loss = torch.nn.functional.binary_cross_entropy_with_logits(
                    self.net(x[batch]), y[batch]
                )
                optimiser.zero_grad()
                loss.backward()
                optimiser.step()

    def values(self, obs: np.ndarray) -> np.ndarray:
        import torch

        with torch.no_grad():
            x = torch.as_tensor((obs - self.mean) / self.std, dtype=torch.float32)
            p = torch.sigmoid(self.net(x)).numpy()
        n = len(OPTIONS)
        return p[..., :n] - p[..., n:]

    def choose(self, obs: np.ndarray) -> int:
        values = self.values(np.asarray(obs, np.float32)[None])[0]
        best = int(np.argmax(values))
        return best if values[best] > values[0] + self.margin else 0


def load_outcomes(paths: Sequence[Path]) -> tuple[np.ndarray, np.ndarray]:
    data = [np.load(path) for path in paths]
    obs = np.concatenate([d["observations"] for d in data]).astype(np.float32)
    return obs, np.concatenate([d["outcomes"] for d in data])


def imitate(paths: Sequence[Path], matches: int, first_seed: int) -> None:
    """Learns the options' outcomes from the oracle's saved choices and plays the learned
    choices, no lookahead, on ``matches`` matches. The last fifth of the choices is held out
    first: models learned from a quarter, half and all of the rest say how the gain over the
    plan grows with the choices learned from, and pick the margin."""
    import torch

    obs, outcomes = load_outcomes(paths)
    cut = len(obs) * 4 // 5
    held, held_outcomes = obs[cut:], outcomes[cut:]
    plan = held_outcomes[:, 0].sum()
    best = held_outcomes.max(1).sum()
    print(f"{len(held)} choices held out: the plan {plan:+d}, the best option each time {best:+d}")
    margins = (0.0, 0.05, 0.1, 0.2, 0.3, 0.5)
    gains: dict[float, int] = {}
    for share in (4, 2, 1):
        torch.manual_seed(0)
        model = OutcomeModel(obs.shape[1])
        model.fit(obs[: cut // share], outcomes[: cut // share])
        values = model.values(held)
        for margin in margins:
            chosen = np.where(values.max(1) > values[:, 0] + margin, values.argmax(1), 0)
            gains[margin] = int(held_outcomes[np.arange(len(held)), chosen].sum())
        shown = ", ".join(f"{m:.2f}: {g:+d}" for m, g in gains.items())
        print(f"  learned from {cut // share} choices, by margin: {shown}")
    torch.manual_seed(0)
    model = OutcomeModel(obs.shape[1], margin=max(gains, key=lambda m: (gains[m], m)))
    model.fit(obs, outcomes)
    goals_for, goals_against, counts = play(model.choose, matches, first_seed)
    chosen_counts = ", ".join(f"{name} {n}" for name, n in zip(OPTIONS, counts))
    print(
        f"learned from {len(obs)} choices, margin {model.margin}, {matches} matches from seed "
        f"{first_seed}: {goals_for} for, {goals_against} against"
    )
    print(f"chosen: {chosen_counts}")


def each_option(matches: int) -> None:
    print(f"each shot always made, against the attacking team, {matches} one-minute matches")
    print(f"{'shot':10s} {'for':>5s} {'against':>8s} {'choices':>8s} {'s':>5s}")
    rng = np.random.default_rng(0)
    choosers: list[tuple[str, Any]] = [(name, lambda obs, k=k: k) for k, name in enumerate(OPTIONS)]
    choosers.append(("at random", lambda obs: rng.integers(len(OPTIONS))))
    for name, choose in choosers:
        start = time.perf_counter()
        goals_for, goals_against, counts = play(choose, matches)
        took = time.perf_counter() - start
        print(f"{name:10s} {goals_for:5d} {goals_against:8d} {sum(counts):8d} {took:5.0f}")


def train(decisions: int, matches: int, save: Path) -> None:
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecMonitor

    torch.set_num_threads(1)
    envs = VecMonitor(SubprocVecEnv([ShotChoiceEnv, ShotChoiceEnv]))
    model = PPO(
        "MlpPolicy",
        envs,
        n_steps=256,
        batch_size=128,
        n_epochs=5,
        gamma=0.9,
        gae_lambda=0.9,
        ent_coef=0.003,
        learning_rate=3e-4,
        seed=0,
        policy_kwargs={"net_arch": [128, 128]},
    )
    # Start near the team's own plan (chosen about 3 times in 4): the other shots on their
    # own score far less, and a learner that starts at random first has to find that out.
    with torch.no_grad():
        model.policy.action_net.bias[0] += 3.0
    save.mkdir(parents=True, exist_ok=True)
    start, done, chunk = time.perf_counter(), 0, 4096
    while done < decisions:
        model.learn(min(chunk, decisions - done), reset_num_timesteps=False)
        done = model.num_timesteps
        recent = [e["r"] for e in model.ep_info_buffer]
        print(
            f"{done:7d} decisions, {time.perf_counter() - start:6.0f} s: goals for less "
            f"against, last {len(recent)} matches, {np.mean(recent):+.2f} a match",
            flush=True,
        )
        model.save(save / f"choice_{done}")
    envs.close()
    goals_for, goals_against, counts = play(
        lambda obs: model.predict(obs, deterministic=True)[0], matches
    )
    chosen = ", ".join(f"{name} {n}" for name, n in zip(OPTIONS, counts))
    print(f"learned choices, {matches} matches: {goals_for} for, {goals_against} against")
    print(f"chosen: {chosen}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--matches", type=int, default=50)
    parser.add_argument("--train", type=int, default=0, metavar="DECISIONS")
    parser.add_argument("--oracle", action="store_true")
    parser.add_argument("--imitate", type=Path, nargs="+", metavar="ORACLE_NPZ")
    parser.add_argument("--sensitivity", type=int, default=0, metavar="CHOICES")
    parser.add_argument(
        "--seed",
        type=int,
        default=FIRST_SEED,
        help="the first match's seed for --oracle, --imitate and --sensitivity",
    )
    parser.add_argument("--save", type=Path, default=Path("runs/full_game_choice"))
    args = parser.parse_args()
    if args.sensitivity:
        sensitivity(args.sensitivity, args.seed)
    elif args.imitate:
        imitate(args.imitate, args.matches, args.seed)
    elif args.oracle:
        oracle(args.matches, args.seed, args.save)
    elif args.train:
        train(args.train, args.matches, args.save)
    else:
        each_option(args.matches)


if __name__ == "__main__":
    main()
