"""A league of a self-play run: every saved generation, the scripted side and any added model
play each other round-robin; the results give Elo ratings with their uncertainty.

Ratings say what self-play's own numbers cannot: each generation only ever met the one
before it, so a rising win rate may be a cycle (A beats B beats C beats A), while a league
rates every generation against the same field. :mod:`foosball_gym.ratings` fits them.

Every pair plays the same seeded serves (:mod:`~foosball_gym.training.selfplay.matches`), in
the game the run trained on (its draw for a still ball too, if it had one).
"""

from __future__ import annotations

import json
import math
import zipfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from foosball_gym.ratings import Ratings, fit_ratings
from foosball_gym.training.run_dir.files import (
    CONFIG_FILE,
    HISTORY_FILE,
    MODEL_FILE,
    RLLIB_BACKEND,
    SELFPLAY_DIR,
    atomic_write_text,
    read_json,
    read_latest,
)
from foosball_gym.training.run_dir.storage import read_entry
from foosball_gym.training.selfplay.history import read_history, snapshot_file
from foosball_gym.training.selfplay.matches import Arena, PairResult, Player, play_pair

SCRIPTED = "scripted"
LEAGUE_JSON = "league.json"
LEAGUE_PNG = "league.png"


@dataclass
class League:
    players: list[Player]
    env_id: str
    env_kwargs: dict[str, Any]
    games: int
    seed: int
    pairs: list[PairResult] = field(default_factory=list)
    ratings: Ratings | None = None

    def table(self) -> str:
        """The ratings, best first, with each player's record."""
        assert self.ratings is not None
        record = {i: [0, 0, 0, 0, 0] for i in range(len(self.players))}  # W D L GF GA
        for p in self.pairs:
            for me, won, lost, gf, ga in (
                (p.a, p.wins, p.losses, p.goals_a, p.goals_b),
                (p.b, p.losses, p.wins, p.goals_b, p.goals_a),
            ):
                r = record[me]
                r[0] += won
                r[1] += p.draws
                r[2] += lost
                r[3] += gf
                r[4] += ga
        order = np.argsort(-self.ratings.elo, kind="stable")
        rows = [
            ("rank", "player", "steps", "Elo", "95 % interval", "won", "drawn", "lost", "goals")
        ]
        for rank, i in enumerate(order, 1):
            player = self.players[i]
            won, drawn, lost, gf, ga = record[i]
            rows.append(
                (
                    str(rank),
                    player.name,
                    "" if player.timesteps is None else str(player.timesteps),
                    f"{self.ratings.elo[i]:+.0f}",
                    f"{self.ratings.low[i]:+.0f} .. {self.ratings.high[i]:+.0f}",
                    str(won),
                    str(drawn),
                    str(lost),
                    f"{gf}:{ga}",
                )
            )
        widths = [max(len(r[c]) for r in rows) for c in range(len(rows[0]))]
        lines = ["  ".join(cell.rjust(w) for cell, w in zip(row, widths)) for row in rows]
        lines.append(
            f"Elo relative to {self.ratings.anchor}; {self.games} games a pair on "
            f"{self.env_id}, seeds {self.seed}..{self.seed + self.games - 1}"
        )
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        assert self.ratings is not None
        return {
            "env_id": self.env_id,
            "env_kwargs": self.env_kwargs,
            "games_per_pair": self.games,
            "seed": self.seed,
            "anchor": self.ratings.anchor,
            "players": [
                {
                    "name": p.name,
                    "generation": p.generation,
                    "timesteps": p.timesteps,
                    "elo": float(self.ratings.elo[i]),
                    "elo_low": float(self.ratings.low[i]),
                    "elo_high": float(self.ratings.high[i]),
                }
                for i, p in enumerate(self.players)
            ],
            "pairs": [
                {
                    "a": self.players[p.a].name,
                    "b": self.players[p.b].name,
                    "wins_a": p.wins,
                    "draws": p.draws,
                    "wins_b": p.losses,
                    "goals_a": p.goals_a,
                    "goals_b": p.goals_b,
                }
                for p in self.pairs
            ],
        }


def run_league(
    players: Sequence[Player],
    env_id: str,
    env_kwargs: dict[str, Any] | None = None,
    games: int = 20,
    seed: int = 0,
    anchor: str | None = None,
    progress: Callable[[str], None] | None = None,
) -> League:
    """Play the round-robin and rate it.

    Args:
        players: at least two, with different names.
        games: games a pair plays (at least 1; even numbers give both sides equal home games).
        anchor: the player rated 0 (default: the scripted side if playing, else the first).
        progress: called with a line after each pair.
    """
    players = list(players)
    names = [p.name for p in players]
    if len(players) < 2:
        raise ValueError(f"a league needs at least two players, got {len(players)}")
    if len(set(names)) != len(names):
        raise ValueError(f"players need different names, got {names}")
    if games < 1:
        raise ValueError(f"games must be at least 1, got {games}")
    if anchor is None:
        anchor = SCRIPTED if SCRIPTED in names else names[0]
    if anchor not in names:
        raise ValueError(f"anchor {anchor!r} is not a player; players: {', '.join(names)}")
    env_kwargs = dict(env_kwargs or {})
    arena = Arena(env_id, env_kwargs)
    try:
        for p in players:
            expected = getattr(p.policy, "observation_size", None)
            if expected is not None and expected != arena.observation_size:
                raise ValueError(
                    f"{p.name} takes observations of size {expected}, but {env_id} with "
                    f"{env_kwargs or 'its defaults'} gives {arena.observation_size}"
                )
        league = League(players, env_id, env_kwargs, games, seed)
        total = len(players) * (len(players) - 1) // 2
        for i in range(len(players)):
            for j in range(i + 1, len(players)):
                pair = play_pair(arena, players[i], players[j], games, seed)
                pair.a, pair.b = i, j
                league.pairs.append(pair)
                if progress:
                    progress(
                        f"[{len(league.pairs)}/{total}] {names[i]} vs {names[j]}: "
                        f"{pair.wins} won, {pair.draws} drawn, {pair.losses} lost "
                        f"(goals {pair.goals_a}:{pair.goals_b})"
                    )
    finally:
        arena.close()
    results = {(p.a, p.b): (p.wins, p.draws, p.losses) for p in league.pairs}
    league.ratings = fit_ratings(names, results, anchor=names.index(anchor), seed=seed)
    return league


# -- a run's players -------------------------------------------------------------------


def read_run(run_dir: str | Path) -> dict[str, Any]:
    """A self-play run's ``config.json``; ValueError where ``run_dir`` is not one."""
    run_dir = Path(run_dir)
    config_path = run_dir / CONFIG_FILE
    history_path = run_dir / SELFPLAY_DIR / HISTORY_FILE
    if not config_path.is_file():
        raise ValueError(f"{run_dir} is not a run directory ({CONFIG_FILE} is missing)")
    if not history_path.is_file():
        raise ValueError(
            f"{run_dir} has no self-play generations ({SELFPLAY_DIR}/history.json is "
            "missing): a league needs a run trained with self-play"
        )
    config = read_json(config_path, dict, "a run's configuration")
    if not isinstance(config.get("env_id"), str) or not isinstance(
        config.get("env_kwargs", {}), dict
    ):
        raise ValueError(f"{config_path} is damaged: it needs an env_id and env_kwargs (an object)")
    return config


def pick_generations(generations: Sequence[int], most: int | None) -> list[int]:
    """At most ``most`` of ``generations``, evenly spread, the first and the last kept."""
    generations = sorted(generations)
    if most is None or len(generations) <= most:
        return generations
    if most < 2:
        return [generations[-1]]
    picks = np.linspace(0, len(generations) - 1, most)
    return sorted({generations[int(round(k))] for k in picks})


def run_players(
    run_dir: str | Path,
    most_generations: int | None = None,
    trust: bool = False,
    sampled: bool = False,
) -> tuple[list[Player], dict[str, Any]]:
    """The saved generations of a self-play run (at most ``most_generations`` of them) and its
    final policy, as players, with the run's configuration.

    ``sampled``: the players sample their actions from their policies, as the opponents of a
    run trained with ``selfplay_sampled`` did, instead of acting on the mean (SB3 runs only).
    Such a run's generations were judged and replaced as the stochastic policies they are; a
    policy's mean can play a different game (measured: the means of one run's generations,
    which never kicked a ball at each other, drew every game between them 0-0).
    """
    from foosball_gym.training.loading import load_policy
    from foosball_gym.training.loading.loader import whole_action_options, whole_action_policy
    from foosball_gym.training.loading.rllib_policy import RllibPolicy, load_rllib_snapshot
    from foosball_gym.training.loading.sb3_snapshot import PolicySnapshot

    run_dir = Path(run_dir)
    config = read_run(run_dir)
    if sampled and config.get("backend") == RLLIB_BACKEND:
        raise ValueError(
            f"{run_dir} was trained with the rllib backend, whose snapshots act on their mean "
            "only; rate it without sampling"
        )
    history = read_history(run_dir / SELFPLAY_DIR / HISTORY_FILE)
    # A residual run's players give whole actions (its final policy as loaded does too), and
    # a run's with slide_around_ball slide over the rods' travel, so its games are played
    # without the options.
    trained_kwargs = dict(config.get("env_kwargs") or {})
    played_kwargs = whole_action_options(trained_kwargs)
    config = {**config, "env_kwargs": played_kwargs}
    by_generation = {h["generation"]: h for h in history}
    players = []
    for g in pick_generations(list(by_generation), most_generations):
        path = snapshot_file(run_dir / SELFPLAY_DIR, g)
        if not path.is_file():
            raise ValueError(f"{run_dir}: generation {g} is in history.json but {path} is missing")
        if config.get("backend") == RLLIB_BACKEND:
            policy: PolicySnapshot | RllibPolicy = load_rllib_snapshot(path, config)
        else:
            policy = PolicySnapshot.load(path, trust=trust)
            policy.deterministic = not sampled
        player = whole_action_policy(policy, config["env_id"], trained_kwargs)[0]
        players.append(Player(f"gen {g}", player, g, by_generation[g].get("timesteps")))
    final = load_policy(run_dir, trust=trust)
    if isinstance(final.policy, PolicySnapshot):  # an RLlib policy acts on its mean only
        final.policy.deterministic = not sampled
    timesteps = _final_timesteps(run_dir)
    players.append(Player("final", final.whole_action(), None, timesteps))
    return players, config


def _final_timesteps(run_dir: Path) -> int | None:
    """The steps the run's final policy trained for, where the run says."""
    model = run_dir / MODEL_FILE
    if model.is_file():
        try:
            with zipfile.ZipFile(model) as archive:
                # SB3's "data" member is JSON: read without unpickling anything.
                return int(json.loads(read_entry(archive, "data"))["num_timesteps"])
        except (OSError, KeyError, ValueError, zipfile.BadZipFile):
            pass
    latest = read_latest(run_dir)
    return None if latest is None else latest.get("timesteps")


def write_league(league: League, out: str | Path) -> tuple[Path, Path | None]:
    """``league.json`` and (where matplotlib is installed) ``league.png`` in ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    json_path = out / LEAGUE_JSON
    atomic_write_text(json_path, json.dumps(league.to_dict(), indent=1))
    try:
        png = plot_league(league, out / LEAGUE_PNG)
    except ImportError:
        png = None
    return json_path, png


def plot_league(league: League, path: Path) -> Path:
    """Elo against training steps for the generations; other players as level lines (in a
    league without a run's generations, every player side by side)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = league.ratings
    assert r is not None
    fig, ax = plt.subplots(figsize=(7, 4))
    run = [i for i, p in enumerate(league.players) if p.timesteps is not None]
    if run:
        xs = [t for i in run if (t := league.players[i].timesteps) is not None]
        ys = r.elo[run]
        err = np.vstack([ys - r.low[run], r.high[run] - ys])
        ax.errorbar(xs, ys, yerr=err, fmt="o-", capsize=3, label="generations of the run")
        for i, x, y in zip(run, xs, ys):
            ax.annotate(
                league.players[i].name,
                (x, y),
                textcoords="offset points",
                xytext=(4, 4),
                fontsize=7,
            )
    others = [i for i in range(len(league.players)) if i not in run]
    if not run:
        # No run's generations to plot against their steps: the players side by side.
        order = [int(i) for i in np.argsort(r.elo, kind="stable")]
        places = np.arange(len(order))
        err = np.vstack([r.elo[order] - r.low[order], r.high[order] - r.elo[order]])
        ax.errorbar(places, r.elo[order], yerr=err, fmt="o", capsize=3)
        ax.set_xticks(places, [league.players[i].name for i in order])
        ax.set_xlabel("player")
        others = []
    else:
        ax.set_xlabel("training steps")
    for k, i in enumerate(others):
        line = ax.axhline(r.elo[i], linestyle="--", color=f"C{k + 1}", label=league.players[i].name)
        ax.axhspan(r.low[i], r.high[i], color=line.get_color(), alpha=0.12)
    ax.set_ylabel(f"Elo (relative to {r.anchor})")
    ax.set_title(f"League on {league.env_id}: {league.games} games a pair, 95 % intervals")
    ax.grid(alpha=0.3)
    if run or others:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def rising(league: League) -> float:
    """Spearman's rank correlation of the generations' ratings with their training steps
    (1: every generation rated above the one before); NaN with fewer than two."""
    r = league.ratings
    assert r is not None
    run = [i for i, p in enumerate(league.players) if p.timesteps is not None]
    if len(run) < 2:
        return math.nan
    steps = np.array([league.players[i].timesteps for i in run], dtype=float)
    elo = r.elo[run]
    rank = lambda x: np.argsort(np.argsort(x)).astype(float)  # noqa: E731
    a, b = rank(steps), rank(elo)
    if a.std() == 0 or b.std() == 0:
        return math.nan
    return float(np.corrcoef(a, b)[0, 1])
