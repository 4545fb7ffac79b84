"""The shipped policies load by name and still beat the scripted baselines.

A change to the environments that silently breaks a shipped policy fails here.
"""

from __future__ import annotations

import pytest

pytest.importorskip("stable_baselines3")

from foosball_gym.training.builtin import builtin_names  # noqa: E402
from foosball_gym.training.evaluation import evaluate  # noqa: E402
from foosball_gym.training.models import load_policy  # noqa: E402

SHIPPED = {"block", "score-resting", "score-incoming", "keeper-vs-keeper"}


def test_every_promised_policy_is_shipped():
    assert SHIPPED <= set(builtin_names())


@pytest.mark.parametrize(
    "name, episodes",
    [
        ("block", 40),
        ("score-resting", 40),
        ("score-incoming", 40),
    ],
)
def test_a_shipped_policy_does_at_least_as_well_as_the_scripted_baseline(name, episodes):
    import gymnasium as gym

    loaded = load_policy(f"builtin:{name}")
    env = gym.make(loaded.env_id, **loaded.env_kwargs)
    scripted = env.unwrapped.scripted_policy()
    env.close()
    trained = evaluate(loaded.policy, loaded.env_id, loaded.env_kwargs, episodes, seed=7000)
    baseline = evaluate(scripted, loaded.env_id, loaded.env_kwargs, episodes, seed=7000)
    assert trained.success_rate >= baseline.success_rate, (trained, baseline)


def test_the_shipped_keeper_beats_the_scripted_keeper():
    loaded = load_policy("builtin:keeper-vs-keeper")
    result = evaluate(loaded.policy, loaded.env_id, loaded.env_kwargs, episodes=20, seed=7000)
    assert result.goals_for > result.goals_against


def test_cli_evaluates_a_builtin_policy_by_name(tmp_path, capsys):
    from foosball_gym.cli import main

    out = tmp_path / "eval.json"
    assert main(["eval", "builtin:block", "--episodes", "5", "--json", str(out)]) == 0
    assert "Foosball-Block-v0" in capsys.readouterr().out
