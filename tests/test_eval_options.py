"""``foosball eval`` says what it plays: each environment option with where it came from (the
model's training config, the command line, the environment's defaults), and a shipped policy
by its name, ``builtin:NAME``, not a path inside the installed package."""

from __future__ import annotations

import json
from importlib.util import find_spec

import pytest

from foosball_gym.cli import main
from foosball_gym.evaluation import evaluate, option_sources


def summary(argv, tmp_path, capsys) -> tuple[list[str], dict]:
    out = tmp_path / "eval.json"
    assert main([*argv, "--episodes", "1", "--json", str(out)]) == 0
    return capsys.readouterr().out.splitlines(), json.loads(out.read_text())


def options_block(lines: list[str]) -> list[str]:
    """The summary's options: its "options" row and the rows under it without a name."""
    start = next(i for i, line in enumerate(lines) if line.startswith("options "))
    block = [lines[start].removeprefix("options")]
    for line in lines[start + 1 :]:
        if not line.startswith(" "):
            break
        block.append(line)
    return [" ".join(line.split()) for line in block]


def test_eval_of_the_scripted_baseline_says_it_plays_the_environment_s_defaults(tmp_path, capsys):
    lines, _ = summary(["eval", "--policy", "scripted", "Foosball-Block-v0"], tmp_path, capsys)
    assert options_block(lines) == ["every option: Foosball-Block-v0's default"]


def test_eval_names_the_options_given_on_the_command_line(tmp_path, capsys):
    argv = ["eval", "--policy", "scripted", "Foosball-Block-v0", "--env-kwarg", "bank_share=0.5"]
    lines, result = summary(argv, tmp_path, capsys)
    assert options_block(lines) == [
        "bank_share=0.5 (the command line)",
        "every other option: Foosball-Block-v0's default",
    ]
    assert result["option_sources"] == {"bank_share": "the command line"}


@pytest.mark.skipif(
    find_spec("stable_baselines3") is None,
    reason='needs the train extra: pip install -e ".[train]"',
)
def test_eval_of_a_model_says_which_options_are_its_training_s_and_names_it_builtin(
    tmp_path, capsys
):
    argv = ["eval", "builtin:block", "--env-kwarg", "estimated_state=False"]
    lines, result = summary([*argv, "--replay", str(tmp_path / "r.html")], tmp_path, capsys)
    block = options_block(lines)
    # The shots it was trained on, not the paper's: what made its 95 % differ from the README.
    assert "speed_range=[2.0, 12.0] (the model's training config)" in block
    assert "bank_share=0.3 (the model's training config)" in block
    assert "estimated_state=False (the command line, over the model's True)" in block
    assert (
        "residual=0.5 (the model's training config: it corrects the scripted baseline's actions)"
        in block
    )
    assert block[-1] == "every other option: Foosball-Block-v0's default"
    assert "policy               builtin:block" in lines
    assert result["policy"] == "builtin:block" and result["residual"] == 0.5
    page = (tmp_path / "r.html").read_text()
    assert "builtin:block on Foosball-Block-v0" in page and "foosball_gym/builtin" not in page


def test_a_library_evaluation_records_where_its_options_came_from():
    from foosball_gym.registration import scripted_policy

    trained, given = {"speed_range": (2.0, 3.0)}, {"bank_share": 0.0}
    sources = option_sources(trained, given)
    assert sources == {
        "speed_range": "the model's training config",
        "bank_share": "the command line",
    }
    policy = scripted_policy("Foosball-Block-v0", {**trained, **given})
    result = evaluate(
        policy, "Foosball-Block-v0", {**trained, **given}, episodes=1, option_sources=sources
    )
    assert result.option_sources == sources and result.residual is None
    assert "speed_range=(2.0, 3.0)  (the model's training config)" in result.table()
