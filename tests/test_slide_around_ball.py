"""The option slide_around_ball: a slide action spans a band around the observed ball, so that
the figurine's place under the ball is one value of the action wherever the ball lies."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import table

KEEPER = table.rod("home_keeper")
BAND = 0.04


def _keeper_under(ball_y: float, action: tuple[float, float], **options) -> tuple[float, float]:
    """Where the keeper's figurine stands, and the ball's y, after 40 steps of ``action``
    with the ball at rest at ``ball_y`` (out of the keeper's reach, so that no kick moves it)."""
    env = gym.make("Foosball-Score-v0", ball_start="resting", **options)
    try:
        env.reset(seed=0, options={"ball_position": (0.0, ball_y)})
        for _ in range(40):
            obs, *_ = env.step(np.array(action, dtype=np.float32))
        names = env.unwrapped.obs_builder.names
        slide = float(obs[names.index("home_keeper_slide_pos")])
        return KEEPER.figurine_y(slide)[0], float(obs[names.index("ball_y")])
    finally:
        env.close()


@pytest.mark.parametrize("ball_y", [-0.08, 0.0, 0.05])
def test_a_slide_action_of_zero_puts_the_figurine_under_the_ball(ball_y):
    figurine, seen = _keeper_under(ball_y, (0.0, 0.0), slide_around_ball=BAND)
    assert seen == pytest.approx(ball_y, abs=2e-3)
    assert figurine == pytest.approx(seen, abs=2e-3)
    # Without the option the same action holds the rod at the middle of its travel.
    plain, _ = _keeper_under(ball_y, (0.0, 0.0))
    assert plain == pytest.approx(0.0, abs=2e-3)


def test_a_slide_action_spans_the_band_either_side_of_the_ball():
    for action in (-1.0, -0.25, 0.5, 1.0):
        figurine, seen = _keeper_under(0.02, (action, 0.0), slide_around_ball=BAND)
        assert figurine == pytest.approx(seen + action * BAND, abs=2e-3)


def test_the_band_stops_where_the_rod_does():
    figurine, _ = _keeper_under(0.1, (1.0, 0.0), slide_around_ball=BAND)
    assert figurine == pytest.approx(KEEPER.figurine_y(KEEPER.slide_limit)[0], abs=2e-3)


@pytest.mark.parametrize("value", [-0.01, 0.7, True, "wide", float("nan"), None])
def test_a_band_that_is_not_a_width_on_the_table_is_refused(value):
    with pytest.raises(ValueError, match=r"slide_around_ball must be a number of metres in \[0, "):
        gym.make("Foosball-Score-v0", slide_around_ball=value)


def test_the_band_does_not_go_with_a_residual():
    with pytest.raises(ValueError, match="cannot go with residual"):
        gym.make("Foosball-Score-v0", slide_around_ball=BAND, residual=0.5)


def _keepers_off_the_ball(offset: float, opponent) -> tuple[float, float]:
    """Keeper against keeper with the band, the learner sending ``offset`` for its slide and
    ``opponent`` playing the away side: each keeper's figurine less the ball's y (table frame)
    after 15 steps of a serve."""
    env = gym.make("Foosball-KeeperVsKeeper-v0", slide_around_ball=BAND)
    try:
        base = env.unwrapped
        base.set_opponent(opponent(base.interface))
        env.reset(seed=3)
        for _ in range(15):
            env.step(np.array([offset, 0.0], dtype=np.float32))
        ball_y = base.game.ball[1]
        home, away = (float(f[1]) - ball_y for f in base.sim.figurine_positions())
        return home, away
    finally:
        env.close()


@pytest.mark.parametrize("offset", [0.0, 0.5, -0.5])
def test_in_a_game_each_side_slides_around_the_ball_it_sees(offset):
    from foosball_gym.policy_io.around_ball import AroundBallPlayer

    def copy(interface):  # the learner's copy on the away side, sending the same action
        return AroundBallPlayer(lambda obs: np.array([offset, 0.0], np.float32), interface)

    home, away = _keepers_off_the_ball(offset, copy)
    assert home == pytest.approx(offset * BAND, abs=2e-3)
    # The away side sees the table turned round: its offset is the home side's mirrored.
    assert away == pytest.approx(-offset * BAND, abs=2e-3)


def test_a_scripted_opponent_slides_over_the_rods_travel_beside_a_learner_with_the_band():
    home, away = _keepers_off_the_ball(0.0, lambda interface: "scripted:0")
    assert home == pytest.approx(0.0, abs=2e-3)
    # The still rung holds its rod at the middle, its figurine at y = 0, not under the ball
    # (served 6 cm off the middle).
    assert away - home == pytest.approx(-0.0603, abs=2e-3)


def test_a_copy_of_the_learner_plays_the_away_side_through_its_band():
    from foosball_gym.policy_io.around_ball import AroundBallPlayer
    from foosball_gym.training.loading.loader import LoadedPolicy, whole_action_policy

    env_id, options = (
        "Foosball-KeeperVsKeeper-v0",
        {"slide_around_ball": BAND, "stagnation_steps": 60},
    )
    env = gym.make(env_id, **options)
    try:
        obs = np.stack([env.reset(seed=s)[0] for s in range(4)])
    finally:
        env.close()
    player, played = whole_action_policy(
        lambda o: np.full((*np.shape(o)[:-1], 2), 0.3), env_id, options
    )
    assert isinstance(player, AroundBallPlayer) and played == {"stagnation_steps": 60}
    one_by_one = np.stack([player(o) for o in obs])
    np.testing.assert_allclose(player(obs), one_by_one)
    ball_y = obs[:, player.interface.builder.names.index("ball_y")]
    slides = one_by_one[:, 0] * KEEPER.slide_limit
    figurines = [KEEPER.figurine_y(s)[0] for s in slides]
    np.testing.assert_allclose(figurines, ball_y + 0.3 * BAND, atol=1e-6)
    # A loaded policy does the same where it plays the away side (foosball eval, a league).
    loaded = LoadedPolicy(policy=player.player, env_id=env_id, env_kwargs=options)
    assert isinstance(loaded.whole_action(), AroundBallPlayer)
    assert LoadedPolicy(policy=player.player, env_id=env_id).whole_action().env_id == env_id


def test_where_both_sides_give_actions_over_the_rods_travel_the_band_is_refused():
    from foosball_gym.multiagent import parallel_env
    from foosball_gym.training.config import TrainConfig
    from foosball_gym.training.rllib.ray_config import check_rllib_config

    with pytest.raises(ValueError, match="not supported in the two-player game"):
        parallel_env("Foosball-KeeperVsKeeper-v0", slide_around_ball=BAND)
    config = TrainConfig(
        "Foosball-KeeperVsKeeper-v0", self_play=True, env_kwargs={"slide_around_ball": BAND}
    )
    with pytest.raises(ValueError, match="train self-play with slide_around_ball"):
        check_rllib_config(config, 1)


def test_the_rewards_see_the_policys_own_action():
    env = gym.make("Foosball-Block-v0", slide_around_ball=BAND, action_regularisation_weight=1.0)
    try:
        env.reset(seed=0)
        # The ball moves, so the slide sent moves with it; the action the policy gave does not.
        rewards = [env.step(np.zeros(1, dtype=np.float32))[1] for _ in range(5)]
    finally:
        env.close()
    assert rewards[1:] == [0.0] * 4


def test_no_scripted_policy_plays_with_the_band():
    from foosball_gym.registration import scripted_policy

    env = gym.make("Foosball-Score-v0", slide_around_ball=BAND)
    try:
        with pytest.raises(ValueError, match="slide over the rod's travel, not around the ball"):
            env.unwrapped.scripted_policy()
    finally:
        env.close()
    with pytest.raises(ValueError, match="slide over the rod's travel, not around the ball"):
        scripted_policy("Foosball-Score-v0", {"slide_around_ball": BAND})


def _keeper_off_the_ball(tmp_path, **options) -> float:
    """The mean distance (m) between the keeper's figurine and the ball over a session on the
    simulated table, each as the loop observed them, played by a policy that sends 0."""
    pytest.importorskip("canopen")
    from foosball_gym.real_table.play.stack import play_sim
    from foosball_gym.session_log import read_session_log

    log = tmp_path / f"session-{len(options)}.jsonl"
    play_sim(
        lambda obs: np.zeros(1, dtype=np.float32),
        "Foosball-Block-v0",
        options,
        episodes=2,
        seed=3,
        log_path=str(log),
        camera_size=(320, 180),
    )
    read = read_session_log(log)
    names = read.header["observation"]
    slide, ball = names.index("home_keeper_slide_pos"), names.index("ball_y")
    return float(
        np.mean(
            [
                abs(KEEPER.figurine_y(r["observation"][slide])[0] - r["observation"][ball])
                for r in read.records[10:]
            ]
        )
    )


def test_a_table_plays_the_band_as_the_environment_does(tmp_path):
    # The keeper follows the ball the loop estimates (2.4 cm off on average, the drive
    # trailing a shot), where without the band it stays in the middle (16 cm off).
    assert _keeper_off_the_ball(tmp_path, slide_around_ball=BAND) < 0.05
    assert _keeper_off_the_ball(tmp_path) > 0.1


def test_a_self_play_run_with_the_band_is_rated_and_evaluated_against_itself(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    from foosball_gym.cli import main
    from foosball_gym.policy_io.around_ball import AroundBallPlayer
    from foosball_gym.training.selfplay.league import run_players

    run = tmp_path / "run"
    argv = ["train", "Foosball-KeeperVsKeeper-v0", "--timesteps", "1024", "--n-envs", "2"]
    argv += ["--n-steps", "256", "--batch-size", "128", "--eval-freq", "100000"]
    argv += ["--eval-episodes", "1", "--env-kwarg", "stagnation_steps=20"]
    argv += ["--env-kwarg", f"slide_around_ball={BAND}", "--selfplay-window", "2"]
    argv += ["--selfplay-rule", "net_score", "--selfplay-threshold", "-1"]
    assert main([*argv, "--out", str(run), "--no-progress"]) == 0
    players, config = run_players(run)
    # Every generation and the final policy slide over the rods' travel in the league's games.
    assert len(players) >= 3
    assert all(isinstance(p.policy, AroundBallPlayer) for p in players)
    assert "slide_around_ball" not in config["env_kwargs"]
    assert main(["league", str(run), "--games", "2", "--out", str(tmp_path / "league")]) == 0
    capsys.readouterr()
    # The learner meets a copy of itself: its own slides read by the environment, the copy's
    # converted by the copy.
    eval_argv = ["eval", str(run), "--opponent", str(run), "--episodes", "2", "--seed", "0"]
    assert main(eval_argv) == 0
    assert "episodes" in capsys.readouterr().out
