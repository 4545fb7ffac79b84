"""The ``foosball`` command forgives little and says what it wants: no abbreviated options,
a suggestion for a misspelt subcommand, option or environment option, errors in one line,
and step counts written as ``1e5``."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

from foosball_gym.cli import build_parser, main

ROOT = Path(__file__).resolve().parent.parent


def error_line(argv, capsys, monkeypatch, tmp_path) -> str:
    """The one line ``foosball`` exits with, status 2, on ``argv``."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def command_parsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {"": parser, **sub.choices}


def test_no_parser_takes_abbreviated_options():
    for name, parser in command_parsers().items():
        assert parser.allow_abbrev is False, name


@pytest.mark.parametrize(
    "argv, expected",
    [
        # Taken for --env-kwarg before: "give an environment id", or a bad KEY=VALUE.
        (
            ["train", "--env", "Foosball-Score-v0", "--timesteps", "1000"],
            "foosball train: error: unrecognized arguments: --env; train takes the environment "
            "id without --env: foosball train ENV_ID",
        ),
        # Taken for --timesteps before, silently.
        (
            ["train", "Foosball-Block-v0", "--timestep", "1000"],
            "foosball train: error: unrecognized arguments: --timestep 1000; did you mean "
            "--timesteps?",
        ),
        (
            ["eval", "builtin:block", "--episode", "3"],
            "foosball eval: error: unrecognized arguments: --episode 3; did you mean --episodes?",
        ),
        (["trian", "Foosball-Block-v0"], "invalid choice: 'trian'; did you mean 'train'?"),
        (["train", "Foosball-Block-v0", "--algo", "spc"], "did you mean 'sac'?"),
    ],
)
def test_a_misspelt_or_abbreviated_name_is_refused_with_the_name_meant(
    argv, expected, capsys, monkeypatch, tmp_path
):
    assert expected in error_line(argv, capsys, monkeypatch, tmp_path)


@pytest.mark.parametrize(
    "argv",
    [
        ["eval", "--policy", "scripted", "Foosball-Score-v0"],
        ["train", "Foosball-Score-v0", "--no-progress"],
    ],
)
def test_a_misspelt_environment_option_names_the_option_meant_in_one_line(
    argv, capsys, monkeypatch, tmp_path
):
    line = error_line([*argv, "--env-kwarg", "obsticles=True"], capsys, monkeypatch, tmp_path)
    assert "ScoreEnv has no option 'obsticles'; did you mean 'obstacles'? allowed: " in line
    assert "stagnation_steps" in line  # the names allowed, all of them
    assert "environment creator" not in line  # Gymnasium's sentence, added to the names
    assert not list(tmp_path.iterdir())  # refused before a run directory is made


@pytest.mark.parametrize(
    "written, steps", [("1e5", 100_000), ("2.5e4", 25_000), ("100_000", 100_000), ("2048", 2048)]
)
def test_step_counts_take_the_forms_they_are_written_in(written, steps):
    from foosball_gym.cli.train import config_from_args

    argv = ["train", "Foosball-Block-v0", "--timesteps", written, "--eval-freq", written]
    config = config_from_args(build_parser().parse_args(argv))
    assert (config.timesteps, config.eval_freq) == (steps, steps)


@pytest.mark.parametrize(
    "option, value, message",
    [
        ("--timesteps", "1e-3", "argument --timesteps: expected a whole number, got '1e-3'"),
        ("--timesteps", "1e5x", "argument --timesteps: expected a whole number, got '1e5x'"),
        ("--timesteps", "inf", "argument --timesteps: expected a whole number, got 'inf'"),
        ("--n-steps", "0.5", "argument --n-steps: expected a whole number, got '0.5'"),
        ("--n-epochs", "2.5", "argument --n-epochs: expected a whole number, got '2.5'"),
        ("--pretrain-episodes", "-1", "argument --pretrain-episodes: must be 0 or more, got -1"),
    ],
)
def test_a_count_that_is_not_whole_is_refused_in_one_line(
    option, value, message, capsys, monkeypatch, tmp_path
):
    argv = ["train", "Foosball-Block-v0", option, value]
    assert error_line(argv, capsys, monkeypatch, tmp_path) == f"foosball train: error: {message}"


# A `foosball COMMAND ...` in a code span or block, up to the end of the command.
CODE = re.compile(r"```[^\n]*\n(.*?)```|`([^`]+)`", re.S)
COMMAND = re.compile(r"\bfoosball ([a-z]+)\b([^&|;\n]*(?:\\\n[^&|;\n]*)*)")


def doc_commands():
    for page in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        for block, span in CODE.findall(page.read_text()):
            code = block or span.replace("\n", " ")
            for name, rest in COMMAND.findall(code):
                yield page.relative_to(ROOT).as_posix(), name, rest.replace("\\\n", " ")


def test_the_commands_in_the_docs_give_only_options_their_command_takes():
    parsers = command_parsers()
    options = {
        name: {o for a in p._actions for o in a.option_strings} for name, p in parsers.items()
    }
    commands = list(doc_commands())
    assert len(commands) > 50  # the pattern finds the pages' commands
    wrong = [
        (page, name, token)
        for page, name, rest in commands
        if name in options
        for token in rest.split()
        if token.startswith("--") and token.partition("=")[0] not in options[name]
    ]
    assert not wrong
