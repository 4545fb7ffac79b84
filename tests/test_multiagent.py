"""The two-player tasks as PettingZoo parallel games: the API, seeding, agreement with the
single-agent env, each side's rewards, the true state, copies (and SuperSuit's vector envs,
which make them) and the optional dependency."""

from __future__ import annotations

import ast
import copy
import pickle
import subprocess
import sys
import warnings
from pathlib import Path

import cloudpickle
import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("pettingzoo", reason="the multi-agent games need the 'distributed' extra")

from pettingzoo.test import parallel_api_test, parallel_seed_test, state_test  # noqa: E402
from pettingzoo.utils.conversions import parallel_to_aec  # noqa: E402

from foosball_gym import table  # noqa: E402
from foosball_gym.envs.rewards import (  # noqa: E402
    SOLES_UP_SPIN,
    TERMS,
    ball_aim_potential,
    ball_to_goal_potential,
    figurine_to_ball_potential,
)
from foosball_gym.multiagent import AGENTS, GAME_IDS, parallel_env  # noqa: E402

PACKAGE = Path(__file__).resolve().parents[1] / "foosball_gym"
# The full game steps at about 1,300 steps/s: enough steps to meet goals and re-serves,
# few enough to keep the file quick.
CYCLES = {"Foosball-KeeperVsKeeper-v0": 300, "Foosball-FullGame-v0": 150}
# Long enough that every agreement run below meets a goal or a dead ball.
AGREEMENT_STEPS = {"Foosball-KeeperVsKeeper-v0": 300, "Foosball-FullGame-v0": 250}
SHAPED = {
    "ball_to_goal_weight": 1.0,
    "figurine_to_ball_weight": 1.0,
    "ball_aim_weight": 1.0,
    "ball_lane_weight": 1.0,
    "ball_threat_weight": 1.0,
    "action_regularisation_weight": 0.5,
}


@pytest.fixture
def make_game():
    """parallel_env that closes what it made at the end of the test."""
    made = []

    def make(env_id: str, **kwargs):
        game = parallel_env(env_id, **kwargs)
        made.append(game)
        return game

    yield make
    for game in made:
        game.close()


def random_actions(game, rng: np.random.Generator) -> dict[str, np.ndarray]:
    n = game.action_space("home").shape[0]
    return {a: rng.uniform(-1.0, 1.0, n).astype(np.float32) for a in AGENTS}


def test_the_two_player_games_are_the_tasks_with_an_opponent():
    assert GAME_IDS == ("Foosball-KeeperVsKeeper-v0", "Foosball-FullGame-v0")


@pytest.mark.parametrize("env_id", GAME_IDS)
def test_passes_the_pettingzoo_parallel_api_test(env_id, make_game):
    with pytest.warns(UserWarning, match="unknown reset option"):
        parallel_api_test(make_game(env_id), num_cycles=CYCLES[env_id])


@pytest.mark.parametrize("env_id", GAME_IDS)
def test_passes_the_pettingzoo_seed_test(env_id):
    parallel_seed_test(lambda: parallel_env(env_id, **SHAPED), num_cycles=CYCLES[env_id] // 2)


@pytest.mark.parametrize(
    "env_id, kwargs",
    [
        ("Foosball-KeeperVsKeeper-v0", SHAPED),
        ("Foosball-KeeperVsKeeper-v0", {"opponent_prismatic_only": False, "shaping": "potential"}),
        ("Foosball-FullGame-v0", {**SHAPED, "continuous": True}),
        ("Foosball-FullGame-v0", {"observe_figurines": True, "ball_mass_range": (0.02, 0.03)}),
    ],
)
def test_home_agent_is_the_single_agent_env_whose_opponent_replays_the_away_actions(
    env_id, kwargs, make_game, make_env
):
    replay: list[np.ndarray] = []
    single = make_env(env_id, opponent=lambda obs: replay[-1], **kwargs)
    game = make_game(env_id, **kwargs)
    rng = np.random.default_rng(3)
    seed, dead_balls = 11, 0
    obs, info = game.reset(seed=seed)
    s_obs, s_info = single.reset(seed=seed)
    for _ in range(AGREEMENT_STEPS[env_id]):
        np.testing.assert_array_equal(obs["home"], s_obs)
        assert info["home"] == s_info
        # The single-agent env's opponent sees exactly what the away agent sees.
        np.testing.assert_array_equal(obs["away"], single.unwrapped.opponent_observation())
        actions = random_actions(game, rng)
        replay.append(actions["away"])
        obs, rewards, terminated, truncated, info = game.step(actions)
        s_obs, s_reward, s_terminated, s_truncated, s_info = single.step(actions["home"])
        assert rewards["home"] == s_reward
        assert terminated["home"] == terminated["away"] == s_terminated
        assert truncated["home"] == truncated["away"] == s_truncated
        dead_balls += bool(s_info["goal"] or s_info["stagnated"] or s_info["out_of_table"])
        if s_terminated or s_truncated:
            seed += 1
            obs, info = game.reset(seed=seed)
            s_obs, s_info = single.reset(seed=seed)
    assert info["home"].keys() == s_info.keys()
    assert dead_balls > 0, "the run should meet a goal or a dead ball, and what follows it"


@pytest.mark.parametrize("env_id", GAME_IDS)
def test_the_goal_term_is_zero_sum_and_the_score_is_seen_from_each_side(env_id, make_game):
    game = make_game(env_id, continuous=True) if "FullGame" in env_id else make_game(env_id)
    goals = {1: 0, -1: 0}
    still = {a: np.zeros(game.action_space(a).shape, np.float32) for a in AGENTS}
    for seed, (position, velocity) in enumerate(
        (((0.57, 0.0), (3.0, 0.0)), ((-0.57, 0.0), (-3.0, 0.0)))
    ):
        game.reset(seed=seed, options={"ball_position": position, "ball_velocity": velocity})
        for _ in range(120):
            _, rewards, terminated, truncated, info = game.step(still)
            home, away = info["home"], info["away"]
            assert home["reward_goal"] == -away["reward_goal"]
            assert home["goal"] == -away["goal"]
            assert (home["goals_for"], home["goals_against"]) == (
                away["goals_against"],
                away["goals_for"],
            )
            if home["goal"]:
                goals[home["goal"]] += 1
                assert home["reward_goal"] == 1000.0 * home["goal"]
                assert home["is_success"] == (home["goal"] == 1)
                assert away["is_success"] == (away["goal"] == 1)
                break
            if terminated["home"] or truncated["home"]:
                break
    assert goals == {1: 1, -1: 1}, "one shot each way should score"


@pytest.mark.parametrize("env_id", GAME_IDS)
def test_each_side_gets_its_own_shaping_and_out_of_table_terms(env_id, make_game):
    game = make_game(env_id, **SHAPED)
    u = game.single_agent_env
    layout = u.layout
    away_rods = [table.rod(r) for r in layout.opponent]
    home_rods = [table.rod(r) for r in layout.controlled]
    n_home = len(layout.controlled)
    n_rods = len(layout.rods)
    blocked = False

    def away_potentials():
        nonlocal blocked
        x, y, vx, vy = u.game.ball
        positions = u.game.positions
        slides = positions[n_home : n_home + len(away_rods)]
        # The home side's figurines stand in the away side's lanes: seen from the away goal,
        # at -x and -y, unless their rod is spun up.
        blockers = [
            (-rod.x, [-fy for fy in rod.figurine_y(positions[i])])
            for i, rod in enumerate(home_rods)
            if abs(positions[n_rods + i]) < SOLES_UP_SPIN
        ]
        aim = ball_aim_potential(-x, -y, -vx, -vy)
        lane = ball_aim_potential(-x, -y, -vx, -vy, blockers)
        blocked |= lane == 0.0 and aim > 0.0
        # In the world frame: distance to the home goal, the away rods' own figurines, the
        # aim at the home goal, the lane to it, the aim at the away goal negated.
        return (
            ball_to_goal_potential(-x, -y),
            figurine_to_ball_potential(y, [rod.figurine_y(s) for rod, s in zip(away_rods, slides)]),
            aim,
            lane,
            -ball_aim_potential(x, y, vx, vy),
        )

    rng = np.random.default_rng(5)
    # The ball served towards the home goal, so that the away side's aim term counts, at first
    # straight at the home keeper's figurine.
    game.reset(seed=2, options={"ball_position": (0.0, 0.02), "ball_velocity": (-2.0, 0.0)})
    phi_goal, phi_fig, phi_aim, phi_lane, phi_threat = away_potentials()
    last = np.zeros(game.action_space("away").shape)
    differs = aimed = threatened = False
    for _ in range(60):
        actions = random_actions(game, rng)
        _, rewards, terminated, truncated, info = game.step(actions)
        away = info["away"]
        new_goal, new_fig, new_aim, new_lane, new_threat = away_potentials()
        assert away["reward_ball_to_goal"] == pytest.approx(new_goal - phi_goal, abs=1e-12)
        assert away["reward_figurine_to_ball"] == pytest.approx(new_fig - phi_fig, abs=1e-12)
        assert away["reward_ball_aim"] == pytest.approx(new_aim - phi_aim, abs=1e-12)
        assert away["reward_ball_lane"] == pytest.approx(new_lane - phi_lane, abs=1e-12)
        assert away["reward_ball_threat"] == pytest.approx(new_threat - phi_threat, abs=1e-12)
        threatened |= new_threat < 0
        a = actions["away"].astype(float)
        assert away["reward_action_regularisation"] == pytest.approx(
            -0.5 * np.mean((a - last) ** 2)
        )
        assert away["reward_out_of_table"] == info["home"]["reward_out_of_table"]
        for agent in AGENTS:
            assert rewards[agent] == pytest.approx(
                sum(info[agent]["reward_" + name] for name in TERMS)
            )
        differs |= away["reward_figurine_to_ball"] != info["home"]["reward_figurine_to_ball"]
        aimed |= new_aim > 0
        phi_goal, phi_fig, phi_aim, phi_lane, last = new_goal, new_fig, new_aim, new_lane, a
        phi_threat = new_threat
        if terminated["home"] or truncated["home"]:
            break
    assert differs, "the two sides' rods are apart: their figurine terms should differ"
    assert aimed, "the ball should have headed for the home goal: the away aim term untested"
    assert threatened, "the ball should have headed for the away goal: the threat untested"
    assert blocked, "a home figurine should have stood in the ball's lane: the lane term untested"


@pytest.mark.parametrize("env_id", GAME_IDS)
def test_the_away_observation_is_the_home_one_seen_from_the_other_goal(env_id, make_game):
    game = make_game(env_id, opponent_prismatic_only=False)
    home_names = game.single_agent_env.obs_builder.names
    swap = {table.HOME: table.AWAY, table.AWAY: table.HOME}
    away_names = [
        n if n.startswith("ball_") else f"{swap[n.split('_', 1)[0]]}_{n.split('_', 1)[1]}"
        for n in home_names
    ]
    rng = np.random.default_rng(0)
    obs, _ = game.reset(seed=4)
    for _ in range(30):
        obs, *_ = game.step(random_actions(game, rng))
        if not game.agents:
            obs, _ = game.reset()
        home = dict(zip(home_names, obs["home"]))
        for name, value in zip(away_names, obs["away"]):
            # Joints are mirrored by construction; the ball's world coordinates turn round.
            expected = -home[name] if name.startswith("ball_") else home[name]
            assert value == expected, name
    assert game.observation_space("away").shape == game.observation_space("home").shape
    assert game.observation_space("away").contains(obs["away"])


@pytest.mark.parametrize("env_id", GAME_IDS)
def test_truncates_at_the_registered_episode_length_or_max_cycles(env_id, make_game):
    assert make_game(env_id).max_cycles == gym.spec(env_id).max_episode_steps
    game = make_game(env_id, max_cycles=5)
    game.reset(seed=0, options={"ball_position": (0.0, 0.2), "ball_velocity": (0.0, 0.0)})
    still = {a: np.zeros(game.action_space(a).shape, np.float32) for a in AGENTS}
    for step in range(1, 6):
        _, _, terminated, truncated, _ = game.step(still)
        assert truncated == dict.fromkeys(AGENTS, step == 5)
        assert not any(terminated.values())
    assert game.agents == []
    with pytest.raises(gym.error.ResetNeeded):
        game.step(still)


def test_renders_rgb_arrays_as_the_single_agent_env(make_game):
    game = make_game("Foosball-KeeperVsKeeper-v0", render_mode="rgb_array", render_width=64)
    game.reset(seed=0)
    frame = game.render()
    assert frame.shape == (180, 64, 3) and frame.dtype == np.uint8


@pytest.mark.parametrize(
    "env_id, kwargs, error, match",
    [
        ("Foosball-Block-v0", {}, ValueError, "not a two-player game"),
        ("Foosball-KeeperVsKeeper-v0", {"opponent": None}, ValueError, "'away' agent"),
        ("Foosball-FullGame-v0", {"opponent": lambda o: o}, ValueError, "'away' agent"),
        ("Foosball-KeeperVsKeeper-v0", {"estimated_state": True}, ValueError, "estimated_state"),
        ("Foosball-KeeperVsKeeper-v0", {"estimated_state": "no"}, ValueError, "True or False"),
        ("Foosball-KeeperVsKeeper-v0", {"speed_range": (1, 2)}, TypeError, "no option"),
        ("Foosball-FullGame-v0", {"joint_velocities": 1}, ValueError, "joint_velocities"),
        ("Foosball-FullGame-v0", {"render_mode": "video"}, ValueError, "render_mode"),
        ("Foosball-FullGame-v0", {"goal_reward": float("nan")}, ValueError, "finite"),
        ("Foosball-KeeperVsKeeper-v0", {"max_cycles": 0}, ValueError, "max_cycles"),
    ],
)
def test_bad_options_are_refused_with_a_clear_error(env_id, kwargs, error, match):
    with pytest.raises(error, match=match):
        parallel_env(env_id, **kwargs)


def test_bad_actions_and_reset_options_are_refused(make_game):
    game = make_game("Foosball-KeeperVsKeeper-v0")
    still = np.zeros(2, np.float32)
    with pytest.raises(gym.error.ResetNeeded):
        game.step({"home": still, "away": still})
    game.reset(seed=0)
    with pytest.raises(ValueError, match="'home' and 'away'"):
        game.step({"home": still})
    with pytest.raises(ValueError, match="away action"):
        game.step({"home": still, "away": np.zeros(3)})
    with pytest.raises(ValueError, match="home action must be finite"):
        game.step({"home": [np.nan, 0.0], "away": still})
    with pytest.raises(ValueError, match="off the field"):
        game.reset(options={"ball_position": (2.0, 0.0)})
    with pytest.warns(UserWarning, match="unknown reset option"):
        game.reset(options={"serve": "left"})
    with pytest.raises(ValueError, match="reset options must be a dict"):
        game.reset(options=[("ball_position", (0.0, 0.0))])
    game.close()
    with pytest.raises(gym.error.ClosedEnvironmentError):
        game.step({"home": still, "away": still})


def test_only_the_distributed_modules_import_pettingzoo_and_ray():
    """The distributed extra stays optional: the rest of the package never needs it."""
    users: dict[str, set[str]] = {"pettingzoo": set(), "ray": set()}
    for path in PACKAGE.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module]
                if isinstance(node, ast.ImportFrom) and node.module and node.level == 0
                else []
            )
            for name in names:
                if name.split(".")[0] in users:
                    users[name.split(".")[0]].add(path.relative_to(PACKAGE).as_posix())
    allowed = {"multiagent/", "training/rllib/"}
    for module, where in users.items():
        folded = {next((a for a in allowed if p.startswith(a)), p) for p in where}
        assert folded <= allowed, module
    assert any(p.startswith("multiagent/") for p in users["pettingzoo"])


def test_without_pettingzoo_the_import_error_names_the_extra():
    code = (
        "import sys; sys.modules['pettingzoo'] = None\n"
        "import foosball_gym, foosball_gym.envs\n"
        "try:\n"
        "    import foosball_gym.multiagent\n"
        "except ImportError as err:\n"
        "    print(err)\n"
        "else:\n"
        "    raise SystemExit('imported without pettingzoo')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert 'pip install -e ".[distributed]"' in out.stdout


def test_the_game_refuses_an_away_action_where_there_is_no_away_side(make_env):
    env = make_env("Foosball-Block-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="no opponent to command"):
        env.unwrapped.game.command([0.0], [0.0])


# ------------------------------------------------------------------ the true state


@pytest.mark.parametrize("env_id", GAME_IDS)
def test_passes_the_pettingzoo_state_test_without_a_warning(env_id, make_game):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        state_test(parallel_to_aec(make_game(env_id)), make_game(env_id), num_cycles=100)


def test_the_state_is_the_true_state_whatever_the_observation_options(make_game):
    env_id = "Foosball-FullGame-v0"
    plain = make_game(env_id)
    other = make_game(env_id, observe_figurines=True, joint_velocities=False)
    names = plain.state_names
    assert other.state_names == names and len(names) == 4 * 8 + 6
    assert plain.state_space == other.state_space
    rng = np.random.default_rng(1)
    plain.reset(seed=5)
    other.reset(seed=5)
    for _ in range(60):
        actions = random_actions(plain, rng)
        plain.step(actions)
        other.step(actions)
        state = plain.state()
        np.testing.assert_array_equal(other.state(), state)
        assert plain.state_space.contains(state)
        env = plain.single_agent_env
        positions, velocities = env.rod_joint_values()
        ball = env.sim.ball_state()
        value = dict(zip(names, state.tolist()))
        for i, rod in enumerate(env.layout.rods):
            assert value[f"{rod}_slide_pos"] == np.float32(positions[i])
            assert value[f"{rod}_spin_vel"] == np.float32(velocities[8 + i])
        assert [value[f"ball_{a}"] for a in ("x", "y", "z", "vx", "vy", "vz")] == [
            np.float32(v) for v in (*ball.position, *ball.velocity)
        ]
        if not plain.agents:
            break


# ------------------------------------------------------------------ copies

COPIERS = {
    "pickle": lambda game: pickle.loads(pickle.dumps(game)),
    "cloudpickle": lambda game: cloudpickle.loads(cloudpickle.dumps(game)),
    "deepcopy": copy.deepcopy,
}


def assert_same_step(a: tuple, b: tuple) -> None:
    for agent in AGENTS:
        np.testing.assert_array_equal(a[0][agent], b[0][agent])
    assert a[1:] == b[1:]


@pytest.mark.parametrize("how", list(COPIERS))
@pytest.mark.parametrize("env_id", GAME_IDS)
def test_a_copied_game_plays_as_the_original_would_and_apart_from_it(env_id, how, make_game):
    game = make_game(env_id, max_cycles=50)
    rng = np.random.default_rng(2)
    game.reset(seed=2)
    for _ in range(20):
        game.step(random_actions(game, rng))
    twin = COPIERS[how](game)
    try:
        np.testing.assert_array_equal(twin.state(), game.state())
        for seed in range(40, 43):
            while game.agents:
                actions = random_actions(game, rng)
                assert_same_step(twin.step(actions), game.step(actions))
                np.testing.assert_array_equal(twin.state(), game.state())
            assert twin.agents == []
            assert_same_step(twin.reset(seed=seed), game.reset(seed=seed))
        game.close()
        twin.step(random_actions(twin, rng))
    finally:
        twin.close()


def supersuit_seeds(seed: int, copies: int, num_cpus: int) -> list[int]:
    """The seed each copy of SuperSuit's vector env is reset with by ``reset(seed=seed)``:
    each process adds its index to the seed, and each copy within it its own."""
    if num_cpus <= 1:
        return [seed + k for k in range(copies)]
    per_process = -(-copies // num_cpus)
    return [seed + k // per_process + k % per_process for k in range(copies)]


@pytest.mark.parametrize("num_cpus", [1, 2])
def test_the_supersuit_recipe_plays_each_copy_as_a_game_of_its_own(num_cpus):
    """PettingZoo's Stable-Baselines3 recipe: SuperSuit copies the game by pickling it, then
    steps the copies in this process or in others. Each copy's rows must be what a game made
    apart gives for the same seed and actions, through the resets that end its episodes."""
    import supersuit as ss

    env_id, copies, cycles, seed = "Foosball-KeeperVsKeeper-v0", 4, 25, 7
    game = parallel_env(env_id, max_cycles=cycles)
    game.reset(seed=123)  # the copies are of a game in play
    vec = ss.concat_vec_envs_v1(
        ss.pettingzoo_env_to_vec_env_v1(game),
        copies,
        num_cpus=num_cpus,
        base_class="stable_baselines3",
    )
    apart = [parallel_env(env_id, max_cycles=cycles) for _ in range(copies)]
    try:
        # SB3's reset(seed) does not reach SuperSuit's copies; its own vector env's does.
        obs, _ = vec.venv.reset(seed=seed)
        expected = [
            g.reset(seed=s)[0] for g, s in zip(apart, supersuit_seeds(seed, copies, num_cpus))
        ]
        rng = np.random.default_rng(0)
        ended = 0
        for _ in range(2 * cycles + 10):
            for k, agent in enumerate(AGENTS * copies):
                np.testing.assert_array_equal(obs[k], expected[k // 2][agent])
            actions = rng.uniform(-1, 1, (2 * copies, 2)).astype(np.float32)
            obs, rewards, dones, _ = vec.step(actions)
            expected = []
            for k, g in enumerate(apart):
                step = g.step({a: actions[2 * k + i] for i, a in enumerate(AGENTS)})
                done = not g.agents
                assert dones[2 * k : 2 * k + 2].tolist() == [done, done]
                assert rewards[2 * k : 2 * k + 2].tolist() == [
                    np.float32(step[1][a]) for a in AGENTS
                ]
                # SuperSuit restarts an ended game at once, from its own random generator.
                expected.append(g.reset()[0] if done else step[0])
                ended += done
        assert ended >= copies, "every copy should end an episode and start the next"
    finally:
        vec.close()
        for g in apart:
            g.close()
