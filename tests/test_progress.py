"""Long commands show that they are going: a bar on a terminal, a plain line now and then
where their output goes to a file or a pipe, and a last line saying where they ended.

Progress is written to standard error; what scripts read on standard output stays as it was.
"""

from __future__ import annotations

import io
import re
from importlib.util import find_spec

import pytest

from foosball_gym.cli import main
from foosball_gym.progress import Progress

needs_train = pytest.mark.skipif(
    find_spec("stable_baselines3") is None,
    reason='needs the train extra: pip install -e ".[train]"',
)


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_count_off_a_terminal_writes_plain_lines_and_a_last_one():
    stream = io.StringIO()
    count = Progress(3, "eval", "episodes", stream=stream, every_s=0)
    for _ in range(3):
        count.update()
    count.set_note("success 66.7 %")
    count.close()
    lines = stream.getvalue().splitlines()
    assert lines[0].startswith("eval: 1/3 episodes (33 %), 0:00:00 elapsed, about ")
    assert lines[-1].startswith("eval: 3/3 episodes (100 %), success 66.7 %, 0:00:")
    assert len(lines) == 4 and "\r" not in stream.getvalue()


def test_a_count_off_a_terminal_writes_no_line_before_its_interval():
    stream = io.StringIO()
    count = Progress(3, "eval", "episodes", stream=stream, every_s=3600)
    count.update()
    assert stream.getvalue() == ""
    count.close()
    assert stream.getvalue().startswith("eval: ended at 1/3 episodes (33 %)")


@needs_train  # tqdm comes with the train extra
def test_a_count_on_a_terminal_draws_a_bar_and_clears_it():
    stream = Terminal()
    count = Progress(3, "eval", "episodes", stream=stream)
    for _ in range(3):
        count.update()
    count.close()
    drawn = stream.getvalue()
    # tqdm's bar (redrawn at most ten times a second), redrawn in place and cleared at the
    # end: no plain line.
    assert re.search(r"\reval: +\d+%\|.*\| \d/3 ", drawn), drawn
    assert "\n" not in drawn and drawn.endswith("\r")


def test_eval_shows_its_episodes_on_stderr_and_keeps_its_report_on_stdout(capsys):
    argv = ["eval", "--policy", "scripted", "Foosball-Block-v0", "--episodes", "3"]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert re.search(r"^eval: 3/3 episodes \(100 %\), success [\d.]+ %", captured.err, re.M)
    assert "success rate" in captured.out and "eval:" not in captured.out


TINY = ["--n-envs", "1", "--n-steps", "64", "--batch-size", "64", "--eval-freq", "64"]
TINY += ["--eval-episodes", "1", "--checkpoint-freq", "64"]


@needs_train
def test_training_counts_to_the_steps_it_runs_and_shows_the_last_evaluation(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["train", "Foosball-Block-v0", "--timesteps", "10", *TINY, "--out", str(run)]) == 0
    captured = capsys.readouterr()
    # Not "64/10": the rollout rounds the 10 steps up, and the command says so.
    assert "training to 64 steps, not 10: PPO collects 64 steps at a time" in captured.out
    assert re.search(r"^train: 64/64 steps \(100 %\), last evaluation [\d.]+ %", captured.err, re.M)
    assert "/10 " not in captured.err


@needs_train
def test_resume_says_which_step_it_continues_from(tmp_path, capsys):
    run = tmp_path / "run"
    argv = ["train", "Foosball-Block-v0", "--timesteps", "64", *TINY, "--out", str(run)]
    # A constant learning rate: a decaying one refuses to be extended.
    assert main([*argv, "--lr-schedule", "constant"]) == 0
    capsys.readouterr()
    assert main(["train", "--resume", str(run), "--timesteps", "128"]) == 0
    captured = capsys.readouterr()
    assert f"continuing {run} from its checkpoint at step 64, to 128" in captured.out
    # The count goes on from the checkpoint, with the evaluation the run made before.
    assert re.search(r"^train: 128/128 steps \(100 %\), last evaluation", captured.err, re.M)


@needs_train
def test_pretraining_shows_its_demonstrations_and_epochs(tmp_path, capsys):
    argv = ["train", "Foosball-Block-v0", "--timesteps", "64", *TINY, "--out", str(tmp_path)]
    assert main([*argv, "--pretrain-episodes", "2"]) == 0
    err = capsys.readouterr().err
    assert re.search(r"^demonstrations: 2/2 episodes \(100 %\)", err, re.M)
    assert re.search(r"^cloning: (\d+)/\1 epochs \(100 %\)", err, re.M)


@pytest.mark.skipif(find_spec("minari") is None, reason="needs the datasets extra")
def test_dataset_shows_the_episodes_it_records(tmp_path, capsys):
    argv = ["dataset", "--policy", "scripted", "Foosball-Block-v0", "--episodes", "2"]
    argv += ["--dataset-id", "foosball/block/progress-v0", "--data-path", str(tmp_path)]
    assert main(argv) == 0
    assert re.search(r"^dataset: 2/2 episodes \(100 %\)", capsys.readouterr().err, re.M)


def test_a_count_that_ends_short_says_where_it_ended_with_no_time_left_to_guess():
    # A training that reaches its target success stops at 2 % of its steps: its last line
    # must not read as a job stalled with minutes to go.
    stream = io.StringIO()
    count = Progress(500_736, "train", "steps", stream=stream, every_s=3600)
    count.update(10_000)
    count.close()
    line = stream.getvalue().strip()
    assert line.startswith("train: ended at 10,000/500,736 steps (2 %)"), line
    assert "left" not in line


def test_a_count_whose_work_grows_counts_to_its_new_total():
    # A fit that leaves out a stretch it cannot reproduce fits the rest again.
    stream = io.StringIO()
    count = Progress(4, "sysid", "stretch fits", stream=stream, every_s=0)
    count.update(4)
    count.set_total(7)
    count.update()
    count.close()
    lines = stream.getvalue().splitlines()
    assert lines[-2].startswith("sysid: 5/7 stretch fits (71 %), 0:00:00 elapsed, about "), lines
    assert lines[-1].startswith("sysid: ended at 5/7 stretch fits (71 %)"), lines
