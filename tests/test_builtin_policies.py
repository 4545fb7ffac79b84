"""The shipped policies load by name and still beat the scripted baselines.

A change to the environments that silently breaks a shipped policy fails here.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings

import gymnasium as gym
import pytest

from foosball_gym import table

pytest.importorskip("stable_baselines3")

from foosball_gym.evaluation import evaluate  # noqa: E402
from foosball_gym.training.loading import (  # noqa: E402
    PhysicsMismatchWarning,
    builtin_names,
    builtin_path,
    load_policy,
)
from foosball_gym.training.run_dir.physics import recorded_physics_revision  # noqa: E402

EPISODES = 100
# Measured over 500 seeded episodes each shipped policy does at least as well as its baseline
# (docs/results/index.md); on 100 it may trail by a shot or two, which is not what this test is for:
# it catches a broken policy.
MARGIN = 0.02
# builtin:score-obstacles is level with its baseline (70.2 % against 68.6 % over 500 layouts)
# and corner kicks make 100 seeds a noisy sample: on seeds 7000-7099 it scores 63 to 67.
MARGINS = {"score-obstacles": 0.06}


# What each shipped policy must keep on EPISODES seeded episodes (500 measured:
# docs/results/index.md).
# builtin:block plays its own options there: any shot, through the camera, the filter and the
# safety layer (92.0 % of 500, 86 % on these 100); its true-state floors are below.
FLOORS = {"block": 0.84, "score-resting": 0.95, "score-obstacles": 0.6, "score-incoming": 0.9}
# The opponent a two-player policy is measured against, where it is not the kicking keeper.
OPPONENTS = {"keeper-vs-keeper": "scripted", "keeper-vs-keeper-scratch": "scripted"}


def test_the_promised_policies_are_shipped():
    promised = {"block", "score-resting", "score-obstacles", "score-incoming", "keeper-vs-keeper"}
    promised |= {
        "keeper-vs-keeper-selfplay",
        "keeper-vs-keeper-teacher",
        "keeper-vs-keeper-scratch",
    }
    assert promised <= set(builtin_names())


def _revision(name: str) -> int:
    config = json.loads((builtin_path(name) / "config.json").read_text())
    return recorded_physics_revision(config)


@pytest.mark.parametrize("name", builtin_names())
def test_a_shipped_policy_says_which_physics_it_was_trained_on(name):
    # One trained on other physics than the current may have lost its skill: loading it says so.
    if _revision(name) == table.PHYSICS_REVISION:
        with warnings.catch_warnings():
            warnings.simplefilter("error", PhysicsMismatchWarning)
            load_policy(f"builtin:{name}")
    else:
        with pytest.warns(PhysicsMismatchWarning, match=f"revision {_revision(name)}"):
            load_policy(f"builtin:{name}")


@pytest.mark.parametrize("name", builtin_names())
def test_a_shipped_policy_does_at_least_as_well_as_the_scripted_baseline(name):
    loaded = load_policy(f"builtin:{name}")
    env = gym.make(loaded.env_id, **loaded.env_kwargs)
    two_player = bool(env.unwrapped.layout.opponent)
    # Only a one-player task is measured against its scripted twin; a two-player policy plays
    # the ladder below (and one whose slide is read around the ball has no twin on its options).
    scripted = None if two_player else env.unwrapped.scripted_policy()
    env.close()
    # keeper-vs-keeper learned against the attacking keeper, the top of the scripted ladder;
    # the earlier keepers against the kicking keeper, rung 1 (the env's default opponent
    # before the ladder). All play single serves here: a continuous match is 1,800 steps.
    opponent = OPPONENTS.get(name, "scripted:1") if two_player else None
    env_kwargs = {**loaded.env_kwargs, "continuous": False} if two_player else loaded.env_kwargs
    trained = evaluate(loaded, loaded.env_id, env_kwargs, EPISODES, seed=7000, opponent=opponent)
    if name == "keeper-vs-keeper":
        # 442 goals for, 98 against over 500 matches (its REPRODUCE.md); 10 and 2 on these
        # 100 serves. The attacking keeper in its place scored 26 and conceded 45 over 200.
        assert trained.goals_for >= 5 and trained.goals_for >= 1.5 * trained.goals_against
    elif name == "keeper-vs-keeper-scratch":
        # Learned from nothing: 51 goals for, 12 against over 500 serves kept apart (its
        # REPRODUCE.md), 10 and 3 on these 100. Against the kicking keeper it scores a few in
        # 500, too few for 100 serves to tell. A broken keeper concedes dozens.
        assert trained.goals_for >= 5 and trained.goals_for >= trained.goals_against, trained
    elif two_player:
        # The earlier keepers play level with the kicking keeper (keeper-vs-keeper-selfplay: 28
        # goals for, 13 against over 500 games, 2 and 2 on these 100; its teacher 13 and 14, 3
        # and 5 here): they must go on scoring and stay within a few goals of it. A broken
        # keeper concedes dozens.
        assert trained.goals_for >= 1, trained
        assert trained.goals_against <= trained.goals_for + 3, trained
    else:
        baseline = evaluate(scripted, loaded.env_id, loaded.env_kwargs, EPISODES, seed=7000)
        margin = MARGINS.get(name, MARGIN)
        assert trained.success_rate >= baseline.success_rate - margin, (trained, baseline)
        assert trained.success_rate >= FLOORS.get(name, 0.9)


def test_cli_evaluates_a_builtin_policy_by_name(tmp_path, capsys):
    from foosball_gym.cli import main

    out = tmp_path / "eval.json"
    assert main(["eval", "builtin:score-resting", "--episodes", "5", "--json", str(out)]) == 0
    assert "Foosball-Score-v0" in capsys.readouterr().out


def test_load_policy_is_offered_by_the_package_itself():
    import numpy as np

    import foosball_gym

    policy = foosball_gym.load_policy("builtin:block")
    env = gym.make(policy.env_id)
    obs, _ = env.reset(seed=0)
    action = np.asarray(policy(obs))
    assert action.shape == env.action_space.shape and env.action_space.contains(
        action.astype(np.float32)
    )
    env.close()


@pytest.mark.parametrize(
    "shots, estimated, floor",
    [
        ("paper", False, 0.98),  # 100.0 % of 500
        ("paper", True, 0.96),  # through the camera, filter and safety layer: 99.2 %; 100 here
        ("any", False, 0.97),  # 99.8 %
    ],
)
def test_block_holds_on_the_true_state_and_the_papers_shots(shots, estimated, floor):
    # builtin:block was trained on any shot a player plays, through the camera and filter; it
    # must hold on the simulator's own state and on the paper's direct shots too, with the whole
    # policy: its correction and the keeper under it.
    loaded = load_policy("builtin:block")
    assert loaded.env_kwargs.get("rebound_share") == 0.1
    assert loaded.env_kwargs.get("estimated_state") is True
    assert loaded.trained_residual == 0.5
    options = dict(loaded.env_kwargs) if shots == "any" else {}
    options["estimated_state"] = estimated
    trained = evaluate(loaded, "Foosball-Block-v0", options, EPISODES, seed=7000)
    assert trained.success_rate >= floor, trained


def test_a_residual_policy_gives_the_whole_action_wherever_it_plays():
    # builtin:score-obstacles learned a correction to the scripted keeper. Loaded, it must act
    # alone (a real table has no scripted keeper to add to it): on an environment without the
    # residual option it plays exactly what its raw correction plays on one with it.
    loaded = load_policy("builtin:score-obstacles")
    assert loaded.trained_residual == 0.1 and "residual" not in loaded.env_kwargs
    whole = evaluate(loaded, loaded.env_id, loaded.env_kwargs, 20, seed=300)
    raw = evaluate(
        loaded.policy, loaded.env_id, {**loaded.env_kwargs, "residual": 0.1}, 20, seed=300
    )
    assert (whole.goals_for, whole.goals_against, whole.mean_length) == (
        raw.goals_for,
        raw.goals_against,
        raw.mean_length,
    )


def test_a_residual_plays_over_the_baseline_of_the_state_it_is_given():
    # builtin:score-incoming corrects the deflecting keeper, on the true state. On estimated
    # state the scripted keeper volleys instead, as a deflection needs the ball's path to a
    # millimetre: over the deflecting keeper it scored 17.0 % there, over the volleying one
    # 59.0 % (seeds 0-199), and its correction (scale 0.02) is small beside either.
    from foosball_gym.cli import build_parser
    from foosball_gym.cli.play import _policy

    loaded = load_policy("builtin:score-incoming")
    assert loaded.baseline.deflect and loaded.trained_residual == 0.02
    estimated = {**loaded.env_kwargs, "estimated_state": True}
    on_estimate = loaded.with_baseline_for(loaded.env_id, estimated)
    assert on_estimate.policy is loaded.policy and on_estimate.baseline.volley
    assert not on_estimate.baseline.deflect
    assert loaded.with_baseline_for(loaded.env_id, loaded.env_kwargs).baseline.deflect
    # gymnasium.make's own keywords pass by.
    longer = {**estimated, "max_episode_steps": 400}
    assert not loaded.with_baseline_for(loaded.env_id, longer).baseline.deflect
    # evaluate() gives it the baseline of the environment it plays.
    given = evaluate(loaded, loaded.env_id, estimated, 4, seed=0)
    by_hand = evaluate(lambda obs: on_estimate(obs), loaded.env_id, estimated, 4, seed=0)
    trained = evaluate(lambda obs: loaded(obs), loaded.env_id, estimated, 4, seed=0)
    played = [(r.goals_for, r.goals_against, r.mean_length) for r in (given, by_hand, trained)]
    assert played[0] == played[1] != played[2]
    # foosball play gives it the baseline for a table's camera and filter.
    args = build_parser().parse_args(["play", "builtin:score-incoming", "--table", "sim"])
    played_policy, _, _, _ = _policy(args)
    assert not played_policy.baseline.deflect
    # One that is not a residual is itself wherever it plays.
    resting = load_policy("builtin:score-resting")
    assert resting.with_baseline_for(resting.env_id, {"estimated_state": True}) is resting


def _torch_threads_after(code: str, **env: str) -> tuple[int, int]:
    """PyTorch's threads in a fresh interpreter before and after ``code``, with the thread
    variables of this process left out and ``env`` added."""
    clean = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    script = f"import torch\nbefore = torch.get_num_threads()\n{code}\n"
    script += "print(before, torch.get_num_threads())"
    result = subprocess.run(
        [sys.executable, "-c", script],
        env={**clean, **env},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    before, after = result.stdout.split()[-2:]
    return int(before), int(after)


LOAD = "import foosball_gym\nfoosball_gym.load_policy('builtin:block')"
EVAL = "from foosball_gym.cli import main\nmain(['eval', 'builtin:block', '--episodes', '1'])"


@pytest.mark.parametrize("code", [LOAD, EVAL], ids=["load_policy", "foosball eval"])
def test_a_policy_plays_on_one_torch_thread(code):
    before, after = _torch_threads_after(code)
    if before == 1:
        pytest.skip("PyTorch has one thread here anyway")
    assert after == 1


def test_omp_num_threads_still_gives_a_policy_more_threads():
    assert _torch_threads_after(LOAD, OMP_NUM_THREADS="2") == (2, 2)
