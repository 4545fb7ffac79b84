"""A two-player task as a PettingZoo parallel game: the home and the away side both learn.

The single-agent environment of the task does the building, the checking of options, the
seeding, the serves, the randomisation and the rendering; its :class:`~foosball_gym.game.Game`
plays each step with the away agent's action in place of the opponent policy.
"""

from __future__ import annotations

import warnings
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.envs.registration import load_env_creator
from pettingzoo import ParallelEnv

from foosball_gym import table
from foosball_gym.envs.base import RENDER_MODES, FoosballEnv
from foosball_gym.envs.options import reset_options
from foosball_gym.envs.rewards import TERMS, RewardComputer, rod_joints
from foosball_gym.multiagent.state import TrueState
from foosball_gym.policy_io.observations import check_flag, mirrored_builder
from foosball_gym.policy_io.task import check_action
from foosball_gym.registration import ENV_IDS, TASKS

AGENTS = ("home", "away")
#: The registered ids whose task has an opponent: the ones :func:`parallel_env` plays.
GAME_IDS: tuple[str, ...] = tuple(i for i in ENV_IDS if TASKS[i]().layout.opponent)


def parallel_env(env_id: str, **env_kwargs: Any) -> FoosballParallelEnv:
    """The two-player task ``env_id`` as a PettingZoo parallel game.

    Args:
        env_id: one of :data:`GAME_IDS`.
        **env_kwargs: the single-agent environment's keyword arguments (not ``opponent``),
            and ``max_cycles``: steps before truncation (default: the registered
            ``max_episode_steps``).
    """
    return FoosballParallelEnv(env_id, **env_kwargs)


class FoosballParallelEnv(ParallelEnv):
    """Keeper against keeper or the full game with both sides learning.

    ## Description
    The single-agent task (``Foosball-KeeperVsKeeper-v0``, ``Foosball-FullGame-v0``) with its
    opponent replaced by a second agent. Agent ``"home"`` is the single-agent env's learner;
    agent ``"away"`` drives the away rods, which the single-agent env leaves to its opponent
    policy. Given the same seed and actions, the home agent's observations, rewards and info
    are the single-agent env's whose opponent replays the away agent's actions.

    ## Action Space
    Per agent, the single-agent env's ``Box(-1, 1, (n,), float32)``, over the agent's own
    rods in its own frame (the away agent's actions mean what the home agent's do).

    ## Observation Space
    Per agent, the single-agent env's layout seen from the agent's own goal: the home
    agent's is the single-agent observation; the away agent's is the mirrored one the
    single-agent env gives its opponent (its own rods first, ball coordinates negated).

    ## State
    ``state()``, in ``state_space``: the full true state for a centralised critic, whatever
    the observation options: each rod's slide and spin position, then their velocities, then
    the ball's x, y, z, vx, vy, vz, in the world (home) frame (``state_names`` names them).

    ## Rewards
    Each agent gets the single-agent terms of its own side: ``out_of_table``,
    ``ball_to_goal``, ``figurine_to_ball``, ``ball_aim``, ``ball_lane``, ``ball_threat`` and
    ``action_regularisation`` are computed for the away agent on the mirrored state, as the
    single-agent env computes them for its learner.
    The ``goal`` term is zero-sum: ``+goal_reward`` to the scorer, ``-goal_reward`` to the
    other side. Every term is also in ``infos[agent]["reward_<name>"]``.

    ## Starting State
    As the single-agent task's; ``reset(options=...)`` takes its reset options in the world
    (home) frame.

    ## Episode End
    Both agents together: terminated as the single-agent env is (a goal, the ball off the
    table, a dead ball; with ``continuous=True`` only when a side has its ``first_to`` goals),
    truncated after ``max_cycles`` steps (the registered ``max_episode_steps``) or the match's
    ``match_seconds``. ``infos[agent]``: ``goal`` (+1: this agent
    scored), ``is_success``, ``goals_for``, ``goals_against`` (from the agent's side),
    ``out_of_table``, ``stagnated`` and the reward terms.

    ## Arguments
    ``env_id`` and every keyword of the single-agent env except ``opponent`` (the away agent
    is the opponent) and ``estimated_state=True`` (the away side has no simulated camera);
    ``max_cycles``.

    ## Copies
    A pickled or deep-copied game is a game of its own in the same state, which steps as this
    one would given the same actions (SuperSuit's vector envs copy the game so).
    """

    metadata = {
        "render_modes": list(RENDER_MODES),
        "render_fps": table.CONTROL_HZ,
        "is_parallelizable": True,
    }

    def __init__(self, env_id: str, *, max_cycles: int | None = None, **env_kwargs: Any) -> None:
        if env_id not in GAME_IDS:
            raise ValueError(f"{env_id!r} is not a two-player game; allowed: {', '.join(GAME_IDS)}")
        if "opponent" in env_kwargs:
            raise ValueError(
                "opponent is an option of the single-agent env only: here the away side is "
                "the 'away' agent, driven by the actions given to step()"
            )
        if check_flag("estimated_state", env_kwargs.get("estimated_state", False)):
            raise ValueError(
                "estimated_state=True is not supported in the two-player game: the away "
                "agent has no simulated camera, so only the home side would see estimates"
            )
        if env_kwargs.get("slide_around_ball"):
            raise ValueError(
                "slide_around_ball is not supported in the two-player game: both agents' "
                "slides here span the rods' travel (the single-agent environment reads its "
                "learner's around the ball)"
            )
        spec = gym.spec(env_id)
        if max_cycles is None:
            max_cycles = spec.max_episode_steps
        if not isinstance(max_cycles, (int, np.integer)) or max_cycles <= 0:
            raise ValueError(f"max_cycles must be a positive integer, got {max_cycles!r}")
        self.max_cycles = int(max_cycles)
        assert isinstance(spec.entry_point, str)  # registered as "module:Class"
        env = load_env_creator(spec.entry_point)(**{**spec.kwargs, **env_kwargs})
        assert isinstance(env, FoosballEnv)  # GAME_IDS are this package's environments
        self._env: FoosballEnv = env
        # A match's own length ends it sooner (the limit caps it: a longer one is refused).
        match = env.task.match_steps(env.sim.control_hz)
        if match is not None and match > self.max_cycles:
            env.close()
            raise ValueError(
                f"the match lasts {match} steps (match_seconds), longer than "
                f"max_cycles={self.max_cycles}: give max_cycles={match} or more"
            )
        self._match_steps = self.max_cycles if match is None else match
        self._closed = False
        layout = env.layout
        self.possible_agents = list(AGENTS)
        self.agents: list[str] = []
        self.render_mode = env.render_mode
        self.metadata = {**self.metadata, "name": env_id, "render_fps": env.metadata["render_fps"]}
        self.observation_spaces = {
            "home": env.observation_space,
            "away": mirrored_builder(env.obs_builder).space,
        }
        n = env.action_space.shape[0]
        self.action_spaces = {
            agent: spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32) for agent in AGENTS
        }
        self._n_act = n
        # The away side's terms are the single-agent terms of the mirrored state: its rods
        # seen as the home rods they mirror (figurine_y flips sign with the team), the ball
        # turned about the centre of the table.
        # The rods a side does not drive stand in its ball's lanes (the away side's seen as the
        # rods they mirror).
        lanes = bool(env.weights.ball_lane)
        self._blocking = {
            agent: [i for i, r in enumerate(layout.rods) if lanes and r not in own]
            for agent, own in (("home", layout.controlled), ("away", layout.opponent))
        }
        self._rewards = {
            "home": RewardComputer(
                env.weights,
                [table.rod(r) for r in layout.controlled],
                [table.rod(layout.rods[i]) for i in self._blocking["home"]],
            ),
            "away": RewardComputer(
                env.weights,
                [_mirrored(r) for r in layout.opponent],
                [_mirrored(layout.rods[i]) for i in self._blocking["away"]],
            ),
        }
        n_home = len(layout.controlled)
        self._slides = {
            "home": slice(0, n_home),
            "away": slice(n_home, n_home + len(layout.opponent)),
        }
        self._steps = 0
        self._true_state = TrueState(layout.rods)
        #: The space of :meth:`state`.
        self.state_space = self._true_state.space

    # ------------------------------------------------------------------ spaces

    def observation_space(self, agent: str) -> spaces.Box:
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        return self.action_spaces[agent]

    @property
    def single_agent_env(self) -> FoosballEnv:
        """The single-agent env that builds, serves and renders this game."""
        return self._env

    # ------------------------------------------------------------------ PettingZoo API

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        options = reset_options(options, self._env.task.reset_options)
        unknown = sorted(set(options) - set(self._env.task.reset_options))
        if unknown:
            # PettingZoo's API test resets with an option no game knows; its environments
            # pass over what they do not know, so this one warns instead of failing.
            warnings.warn(
                f"ignoring unknown reset option(s) {unknown}; allowed: "
                f"{', '.join(self._env.task.reset_options)}",
                stacklevel=2,
            )
            options = {k: v for k, v in options.items() if k not in unknown}
        home_obs, home_info = self._env.reset(seed=seed, options=options)
        self._reset_rewards()
        self._steps = 0
        self.agents = list(self.possible_agents)
        observations = {"home": home_obs, "away": self._env.game.opponent_observation()}
        return observations, {"home": home_info, "away": self._away_info(home_info)}

    def step(
        self, actions: dict[str, Any]
    ) -> tuple[
        dict[str, np.ndarray],
        dict[str, float],
        dict[str, bool],
        dict[str, bool],
        dict[str, dict[str, Any]],
    ]:
        if self._closed:
            raise gym.error.ClosedEnvironmentError("the environment is closed; make a new one")
        if not self.agents:
            raise gym.error.ResetNeeded(
                "call reset() before step(): the game is over or has not begun"
            )
        if not isinstance(actions, dict) or set(actions) != set(AGENTS):
            got = sorted(actions) if isinstance(actions, dict) else actions
            raise ValueError(f"step() needs a dict with an action for 'home' and 'away', got {got}")
        act = {a: check_action(actions[a], self._n_act, f"{a} action") for a in AGENTS}
        env = self._env
        game = env.game
        game.command(act["home"], act["away"])
        outcome = game.advance()
        continuous = outcome.ended and env.task.continues_after_goal
        # A first-to-N match is over once a side has its goals.
        decided = continuous and env.task.match_over(game.goals_for, game.goals_against)
        terminal = outcome.ended and (not continuous or decided)
        self._steps += 1
        ball = game.ball
        mirrored = tuple(-v for v in ball)
        positions = game.positions
        terms = {
            "home": self._rewards["home"].step(
                outcome.goal,
                outcome.out_of_table,
                positions[self._slides["home"]],
                ball,
                act["home"],
                terminal,
                self._blocking_joints("home"),
            ),
            "away": self._rewards["away"].step(
                -outcome.goal,
                outcome.out_of_table,
                positions[self._slides["away"]],
                mirrored,
                act["away"],
                terminal,
                self._blocking_joints("away"),
            ),
        }
        # The single-agent env's info, which has the keys and types of its reset's.
        home_info = env.step_info(outcome, terms["home"])
        infos = {"home": home_info, "away": self._away_info(home_info)}
        infos["away"].update(("reward_" + name, float(terms["away"][name])) for name in TERMS)
        if continuous and not decided:
            goals = game.goals_for, game.goals_against
            game.start(env.task.sample_start(env.np_random))
            self._reset_rewards()
            game.goals_for, game.goals_against = goals
        observations = {
            "home": env.obs_builder.build(game.positions, game.velocities, game.ball),
            "away": game.opponent_observation(),
        }
        rewards = {agent: float(sum(terms[agent].values())) for agent in AGENTS}
        truncated = self._steps >= self._match_steps
        terminations = dict.fromkeys(AGENTS, terminal)
        truncations = dict.fromkeys(AGENTS, truncated)
        if terminal or truncated:
            self.agents = []
        if self.render_mode == "human":
            env.render()
        return observations, rewards, terminations, truncations, infos

    def state(self) -> np.ndarray:
        """The full true state, the same for both agents: every joint of the rods in play and
        the ball in three dimensions, in the world frame (names: ``state_names``)."""
        game = self._env.game
        return self._true_state.build(game.positions, game.velocities, self._env.sim.ball_state())

    @property
    def state_names(self) -> tuple[str, ...]:
        """What each entry of :meth:`state` is, e.g. ``"home_keeper_slide_vel"``, ``"ball_z"``."""
        return self._true_state.names

    def render(self) -> np.ndarray | None:
        return self._env.render()

    def close(self) -> None:
        self._closed = True
        self.agents = []
        self._env.close()

    # ------------------------------------------------------------------ helpers

    def _reset_rewards(self) -> None:
        game = self._env.game
        for agent, sign in (("home", 1.0), ("away", -1.0)):
            self._rewards[agent].reset(
                game.positions[self._slides[agent]],
                [sign * v for v in game.ball],
                self._n_act,
                self._blocking_joints(agent),
            )

    def _blocking_joints(self, agent: str) -> list[float]:
        """The slides then the spins of the rods ``agent``'s aim looks past."""
        rods = self._blocking[agent]
        if not rods:
            return []
        return rod_joints(self._env.game.positions, len(self._env.layout.rods), rods)

    def _away_info(self, home_info: dict[str, Any]) -> dict[str, Any]:
        """The home side's info as the away side sees it: the score turned round."""
        info = dict(home_info)
        info["goal"] = -home_info["goal"]
        info["goals_for"], info["goals_against"] = (
            home_info["goals_against"],
            home_info["goals_for"],
        )
        info["is_success"] = self._env.task.success(info["goals_for"], info["goals_against"])
        return info


def _mirrored(name: str) -> table.Rod:
    """The rod that the rod called ``name`` is seen as from the other goal: the other team's of
    the same role (its figurines' y and its x turn round with the team)."""
    rod = table.rod(name)
    other = table.AWAY if rod.team == table.HOME else table.HOME
    return table.rod(f"{other}_{rod.role}")
