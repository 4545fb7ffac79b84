"""A learner that chooses the attacking team's shots instead of nudging its actions.

The attacking team (the top of the full game's scripted ladder) plays every rod; only where
one of its rods has a ball to shoot does a choice come up: which of a few shots to make, or
to hold the swing a moment. The chosen shot is carried out as the team carries out its own,
and held until the shot is made. So a learner explores by choosing differently, never by
shaking a precise kick (``benchmarks/full_game_noise.py`` has what that noise costs).

    python benchmarks/full_game_choice.py --matches 50             # each shot always made
    python benchmarks/full_game_choice.py --train 40000 --matches 50 --save runs/choice

The first plays each option on its own, and a choice at random, against the attacking team.
The second trains PPO (Stable-Baselines3) over the choices for that many decisions in two
processes, then plays its deterministic choices. Matches are continuous one-minute matches of
``Foosball-FullGame-v0``, seeds 5000 on; each prints goals for and against.
"""

from __future__ import annotations

import argparse
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
        self.team.choice = int(action)
        self._held, self._held_steps = self.team.shooter(self._obs), 0
        return self._play_on()

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


def play(choose: Any, matches: int) -> tuple[int, int, list[int]]:
    """Goals for and against, and how often each option was chosen, over ``matches``
    matches where ``choose(obs)`` picks each shot."""
    env = ShotChoiceEnv()
    goals_for = goals_against = 0
    counts = [0] * len(OPTIONS)
    for seed in range(FIRST_SEED, FIRST_SEED + matches):
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
    parser.add_argument("--save", type=Path, default=Path("runs/full_game_choice"))
    args = parser.parse_args()
    if args.train:
        train(args.train, args.matches, args.save)
    else:
        each_option(args.matches)


if __name__ == "__main__":
    main()
