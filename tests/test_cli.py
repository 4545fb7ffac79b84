"""The ``foosball`` command: every command's help and bad-input errors, and a real run of each."""

from __future__ import annotations

import functools
import json
import re
from dataclasses import fields
from importlib.util import find_spec

import numpy as np
import pytest

import foosball_gym
from foosball_gym.cli import build_parser, main
from foosball_gym.training.config import TrainConfig

needs_train = pytest.mark.skipif(
    find_spec("stable_baselines3") is None or find_spec("torch") is None,
    reason='needs the train extra: pip install -e ".[train]"',
)
needs_hardware = pytest.mark.skipif(
    any(find_spec(m) is None for m in ("can", "canopen", "cv2", "yaml")),
    reason='needs python-can, canopen, OpenCV and PyYAML: pip install -e ".[hardware]"',
)

MAIN_OPTIONS = {
    "train": ["env_id", "--timesteps", "--n-envs", "--algo", "--out", "--resume", "--env-kwarg"],
    "eval": ["target", "--policy", "--episodes", "--seed", "--opponent", "--json", "--video"],
    "league": ["run", "--add", "--games", "--generations", "--no-scripted", "--out"],
    "play": [
        "model",
        "--table",
        "--env",
        "--episodes",
        "--camera",
        "--latency",
        "--log",
        "--serves",
    ],
    "calibrate": ["--table", "--frame", "--chessboard", "--pattern", "--square", "--home-side"],
    "sysid": ["LOG.jsonl", "--json", "--config", "--env", "--plot"],
    "envs": ["registered environments"],
    "migrate": ["RUN", "--trust-model"],
}


@pytest.mark.parametrize("command", list(MAIN_OPTIONS))
def test_every_command_has_help_naming_its_main_options(command, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([command, "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: foosball {command}")
    for option in MAIN_OPTIONS[command]:
        assert option in out, option
    assert "%%" not in out  # a description is printed as written, not %-formatted


def test_train_options_show_and_keep_the_defaults_of_the_training_configuration(
    capsys, monkeypatch
):
    monkeypatch.setenv("COLUMNS", "200")  # no help line wrapped
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    help_text = capsys.readouterr().out
    by_name = {f.name: f for f in fields(TrainConfig)}
    assert "--n-steps N_STEPS     PPO horizon per environment (128)" in help_text
    assert f"({by_name['timesteps'].default})" in help_text
    assert "(off)" in help_text  # target_kl's None

    parser = build_parser()
    assert config_of(parser, ["train", "Foosball-Block-v0"]) == TrainConfig("Foosball-Block-v0")
    chosen = config_of(
        parser,
        ["train", "Foosball-Block-v0", "--n-steps", "64", "--n-epochs", "5", "--no-normalize"]
        + ["--no-self-play"],
    )
    assert (chosen.n_steps, chosen.n_epochs) == (64, 5)
    assert (chosen.normalize, chosen.self_play) == (False, False)
    assert chosen.batch_size == by_name["batch_size"].default
    sampled = config_of(parser, ["train", "Foosball-KeeperVsKeeper-v0", "--selfplay-sampled"])
    assert sampled.selfplay_sampled and not by_name["selfplay_sampled"].default
    gated = config_of(parser, ["train", "Foosball-KeeperVsKeeper-v0", "--selfplay-gate", "40"])
    assert gated.selfplay_gate == 40 and by_name["selfplay_gate"].default == 0


def config_of(parser, argv):
    from foosball_gym.cli.train import config_from_args

    return config_from_args(parser.parse_args(argv))


@pytest.mark.parametrize(
    "argv, message",
    [
        pytest.param(
            ["train", "Foosball-Nothing-v0", "--no-progress"],
            "unknown environment 'Foosball-Nothing-v0'",
            marks=needs_train,
        ),
        (["train", "Foosball-Block-v0", "--timesteps", "0"], "argument --timesteps: must be"),
        (["train", "Foosball-Block-v0", "--algo", "dqn"], "argument --algo: invalid choice"),
        pytest.param(
            ["train", "Foosball-Block-v0", "--env-kwarg", "warp=3", "--no-progress"],
            "has no option 'warp'",
            marks=needs_train,
        ),
        (
            ["eval", "--policy", "scripted", "Foosball-Nothing-v0"],
            "unknown environment 'Foosball-Nothing-v0'",
        ),
        (
            ["eval", "--policy", "scripted", "Foosball-Block-v0", "--episodes", "0"],
            "argument --episodes: must be at least 1, got 0",
        ),
        (
            ["eval", "--policy", "scripted", "Foosball-Block-v0", "--env-kwarg", "warp=3"],
            "has no option 'warp'",
        ),
        (
            ["eval", "--policy", "scripted", "Foosball-Block-v0", "--env-kwarg", "warp"],
            "--env-kwarg takes KEY=VALUE",
        ),
        pytest.param(
            ["eval", "/nonexistent/model.zip"],
            "no model at /nonexistent/model.zip",
            marks=needs_train,
        ),
        (
            ["play", "scripted", "--env", "Foosball-Block-v0", "--table", "sim", "--camera", "640"],
            "argument --camera: expected WIDTHxHEIGHT",
        ),
        (
            ["play", "scripted", "--table", "sim", "--camera", "0x360"],
            "argument --camera: width and height must be positive",
        ),
        pytest.param(
            ["play", "scripted", "--env", "Foosball-Nothing-v0", "--table", "sim"],
            "unknown environment 'Foosball-Nothing-v0'",
            marks=needs_hardware,
        ),
        pytest.param(
            ["play", "scripted", "--table", "sim"],
            "the scripted policy needs --env ENV_ID",
            marks=needs_hardware,
        ),
        (
            ["calibrate", "--table", "missing.yaml"],
            "argument --table: no table configuration at missing.yaml",
        ),
        (
            ["calibrate", "--table", "table.yaml", "--pattern", "9by6"],
            "argument --pattern: expected COLUMNSxROWS",
        ),
        (["envs", "--all"], "unrecognized arguments: --all"),
        (["frobnicate"], "invalid choice"),
        (["train", "Foosball-Block-v0", "--env-kwarg", "speed"], "KEY=VALUE"),
        pytest.param(
            ["train", "Foosball-Block-v0", "--self-play", "--no-progress"],
            "no opponent",
            marks=needs_train,
        ),
        (["train", "Foosball-Block-v0", "--timesteps", "0"], "at least 1"),
        pytest.param(["train", "--resume", "/nonexistent/run"], "no run there", marks=needs_train),
        (
            ["train", "--resume", "runs/x", "--n-envs", "4"],
            "--n-envs with --resume runs/x: a run continues with the settings in its "
            "config.json; leave it out",
        ),
        (
            ["train", "Foosball-Block-v0", "--resume", "runs/x", "--no-normalize"],
            "ENV_ID, --no-normalize with --resume runs/x",
        ),
        pytest.param(["eval", "builtin:nothing"], "no built-in policy", marks=needs_train),
        (["train", "Foosball-Block-v0", "--seed", "-1"], "argument --seed: must be 0 or more"),
        (
            ["eval", "--policy", "scripted", "Foosball-Block-v0", "--seed", "-1"],
            "argument --seed: must be 0 or more",
        ),
        (
            ["play", "scripted", "--env", "Foosball-Block-v0", "--table", "sim", "--seed", "-1"],
            "argument --seed: must be 0 or more",
        ),
        (
            [
                "play",
                "scripted",
                "--env",
                "Foosball-Block-v0",
                "--table",
                "sim",
                "--latency",
                "nan",
            ],
            "argument --latency: must be 0, or 1 to 500 ms, got 'nan'",
        ),
        (
            ["play", "scripted", "--env", "Foosball-Block-v0", "--table", "sim", "--latency", "100"]
            + ["--latency", "5000"],
            "argument --latency: must be 0, or 1 to 500 ms, got '5000'",
        ),
        (
            [
                "play",
                "scripted",
                "--env",
                "Foosball-Block-v0",
                "--table",
                "sim",
                "--latency",
                "0.03",
            ],
            "argument --latency: is in milliseconds (0, or 1 to 500 ms); 0.03 ms is 30 µs: "
            "did you mean 30?",
        ),
        (
            ["train", "Foosball-Block-v0", "--learning-rate", "-1"],
            "argument --learning-rate: must be a finite number above 0",
        ),
        pytest.param(
            ["train", "Foosball-KeeperVsKeeper-v0", "--selfplay-scripted-share", "1.5"],
            "selfplay_scripted_share must be in [0, 1), got 1.5",
            marks=needs_train,
        ),
        pytest.param(
            ["train", "Foosball-Block-v0", "--out", "/dev/null/run", "--no-progress"],
            "--out /dev/null/run: /dev/null is a file, not a folder",
            marks=needs_train,
        ),
        (
            ["eval", "--policy", "scripted", "Foosball-Block-v0", "--json", "/dev/null/r.json"],
            "--json /dev/null/r.json: there is no folder /dev/null",
        ),
        (
            ["eval", "--policy", "scripted", "Foosball-Block-v0", "--video", "/dev/null/v.mp4"],
            "--video /dev/null/v.mp4: there is no folder /dev/null",
        ),
        (
            [
                "eval",
                "--policy",
                "scripted",
                "Foosball-Block-v0",
                "--env-kwarg",
                "render_mode=human",
            ],
            "render_mode=human needs a display",
        ),
        pytest.param(
            ["eval", "builtin:block", "--env", "Foosball-Score-v0"],
            "expects observations of size 6 of Foosball-Block-v0, but Foosball-Score-v0 gives 8",
            marks=needs_train,
        ),
        pytest.param(
            ["play", "builtin:block", "--env", "Foosball-Score-v0", "--table", "sim"],
            "expects observations of size 6 of Foosball-Block-v0, but Foosball-Score-v0 gives 8",
            marks=[needs_train, needs_hardware],
        ),
        pytest.param(["migrate", "/nonexistent/run"], "--trust-model", marks=needs_train),
        *(
            pytest.param(
                ["play", "scripted", "--env", "Foosball-Block-v0", "--table", "sim"]
                + ["--env-kwarg", kwarg],
                message,
                marks=needs_hardware,
            )
            for kwarg, message in (
                ("foo=1", "BlockEnv has no option 'foo'"),
                ("ball_restitution_range=(0.4,2)", "ball_restitution_range must satisfy"),
                ("goal_reward='lots'", "reward weight goal must be a finite number, got 'lots'"),
                ("rolling_resistance=-1", "rolling_resistance must be a number in [0.0, 0.5]"),
            )
        ),
    ],
)
def test_a_bad_input_exits_with_status_2_and_one_line_naming_it(
    argv, message, capsys, tmp_path, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("DISPLAY", raising=False)
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if ": error: " in line]
    assert len(errors) == 1 and message in errors[0], err
    assert errors[0].startswith("foosball") and "Traceback" not in err
    assert "usage:" not in err  # the line that says what is wrong is not buried under it


@needs_train
def test_train_runs_a_few_hundred_steps(tmp_path, capsys):
    run = tmp_path / "run"
    argv = ["train", "Foosball-Block-v0", "--timesteps", "256", "--n-envs", "1"]
    argv += ["--n-steps", "128", "--batch-size", "64", "--eval-freq", "256"]
    argv += ["--eval-episodes", "2", "--checkpoint-freq", "256", "--no-progress"]
    assert main([*argv, "--out", str(run)]) == 0
    assert re.fullmatch(
        rf"trained 256 steps in \d+ s; run in {re.escape(str(run))}\n", capsys.readouterr().out
    )
    config = json.loads((run / "config.json").read_text())
    assert (config["timesteps"], config["n_steps"]) == (256, 128)
    # What the options leave out is TrainConfig's, not a number of the CLI's.
    assert config["learning_rate"] == TrainConfig("Foosball-Block-v0").learning_rate
    assert (run / "model.zip").exists() and (run / "eval.csv").exists()


def test_eval_of_the_scripted_baseline_prints_the_lines_scripts_read(tmp_path, capsys):
    out = tmp_path / "eval.json"
    argv = ["eval", "--policy", "scripted", "Foosball-Block-v0", "--episodes", "3"]
    assert main([*argv, "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    result = json.loads(out.read_text())
    rate = re.search(r"success rate +([\d.]+) % \(95 % CI ([\d.]+) - ([\d.]+) %\)", printed)
    goals = re.search(r"goals for / against +(\d+) / (\d+)", printed)
    assert rate and goals, printed
    np.testing.assert_allclose(
        [float(v) for v in rate.groups()],
        [100 * result[k] for k in ("success_rate", "ci_low", "ci_high")],
        atol=0.05,
    )
    assert [int(v) for v in goals.groups()] == [result["goals_for"], result["goals_against"]]
    assert (result["episodes"], result["seed"], result["policy"]) == (3, 0, "scripted")
    assert printed.endswith(f"wrote {out}\n")


def test_eval_writes_nothing_it_was_not_asked_to(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    argv = ["eval", "--policy", "scripted", "Foosball-Block-v0", "--episodes", "2"]
    assert main(argv) == 0
    assert "wrote" not in capsys.readouterr().out
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("where", ["missing/eval.json", "."])
def test_eval_refuses_a_json_path_it_cannot_write_before_evaluating(
    tmp_path, where, monkeypatch, capsys
):
    import foosball_gym.cli.evaluate as command

    @functools.wraps(command.evaluate)  # the parser reads its defaults off the signature
    def evaluate(*args, **kwargs):
        raise AssertionError("evaluated although the results could not be written")

    monkeypatch.setattr(command, "evaluate", evaluate)
    argv = ["eval", "--policy", "scripted", "Foosball-Block-v0", "--episodes", "500"]
    with pytest.raises(SystemExit) as exit_:
        main([*argv, "--json", str(tmp_path / where)])
    assert exit_.value.code == 2
    assert "--json" in capsys.readouterr().err


@needs_train
@pytest.mark.parametrize("where", ["run", "config"])
def test_a_run_naming_an_unknown_environment_exits_with_status_2(tmp_path, where, capsys):
    import shutil

    from foosball_gym.training.loading import builtin_path

    run = tmp_path / "run"
    shutil.copytree(builtin_path("block"), run)
    config = json.loads((run / "config.json").read_text())
    (run / "config.json").write_text(json.dumps({**config, "env_id": "Foosball-Nothing-v0"}))
    argv = ["eval", str(run)] if where == "run" else ["train", "--resume", str(run)]
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, "--no-progress"] if where == "config" else argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "unknown environment 'Foosball-Nothing-v0'" in err and "Traceback" not in err


@needs_hardware
@pytest.mark.parametrize(
    "field, value, allowed",
    [
        ("watchdog_s", 10, "at most 0.1 s"),
        ("heartbeat_timeout_s", 60, "at most 0.5 s"),
        ("control_hz", 30, "40 to 1000 Hz"),
    ],
)
def test_play_refuses_a_table_configuration_outside_the_safe_limits(
    tmp_path, field, value, allowed, capsys
):
    import yaml

    from foosball_gym.real_table.hardware.config import shipped_table

    data = yaml.safe_load(shipped_table().read_text())
    data[field] = value
    path = tmp_path / "table.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(SystemExit) as exit_info:
        main(["play", "scripted", "--env", "Foosball-Block-v0", "--table", str(path)])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert field in err and allowed in err and "Traceback" not in err


def test_envs_lists_every_environment_with_its_options(capsys):
    assert main(["envs"]) == 0
    out = capsys.readouterr().out
    for env_id in foosball_gym.ENV_IDS:
        assert env_id in out
    # Each option with its type and default, and the values it takes where they are few.
    assert (
        "ball_start: Literal['resting', 'incoming'] = 'resting'  one of 'resting', 'incoming'"
    ) in out
    assert "continuous: bool = False" in out
    assert "rolling_resistance: float = 0.01" in out


@needs_hardware
def test_play_runs_the_scripted_keeper_on_the_simulated_table(capsys):
    # Lock-step: on the wall clock the suite's other worker can hold this process past the
    # watchdog, which stops the table as it should (tests/test_play.py covers that clock).
    argv = ["play", "scripted", "--env", "Foosball-Block-v0", "--table", "sim", "--lockstep"]
    assert main([*argv, "--episodes", "1", "--camera", "320x180", "--no-status"]) == 0
    out = capsys.readouterr().out
    assert "1 episodes of Foosball-Block-v0: success" in out
    assert "ball detection error" in out and "stage" in out


@needs_hardware
def test_play_and_calibrate_help_show_the_library_defaults(capsys):
    from foosball_gym.real_table.play.stack import LOCKSTEP_CAMERA, REALTIME_CAMERA, calibrate_table

    with pytest.raises(SystemExit):
        main(["play", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    (w, h), (lw, lh) = REALTIME_CAMERA, LOCKSTEP_CAMERA
    assert f"({w}x{h}; {lw}x{lh} with --lockstep and no window)" in out
    with pytest.raises(SystemExit):
        main(["calibrate", "--help"])
    pattern, square, home_side = calibrate_table.__defaults__[-3:]
    out = capsys.readouterr().out
    assert f"({pattern[0]}x{pattern[1]})" in out and f"({square})" in out
    assert f"({home_side})" in out


@needs_hardware
def test_calibrate_finds_the_intrinsics_from_chessboards_and_the_pose_from_the_field(
    tmp_path, capsys
):
    import cv2

    from foosball_gym.real_table.hardware.config import load_config, save_config, shipped_table
    from foosball_gym.real_table.virtual.simulated_table import SimulatedTable, virtual_table_config
    from foosball_gym.real_table.vision import CameraCalibration
    from foosball_gym.registration import task_interface

    table = SimulatedTable(
        "Foosball-Block-v0", {}, virtual_table_config(task_interface("Foosball-Block-v0"))
    )
    try:
        frame = cv2.cvtColor(table.frame(), cv2.COLOR_RGB2BGR)
        truth = CameraCalibration.from_camera_model(table.camera_model)
    finally:
        table.close()
    cv2.imwrite(str(tmp_path / "field.png"), frame)
    height, width = frame.shape[:2]
    for i, view in enumerate(chessboard_views(truth.K, (width, height), (9, 6), 0.03)):
        cv2.imwrite(str(tmp_path / f"board_{i}.png"), view)
    path = tmp_path / "table.yaml"
    save_config(load_config(shipped_table("keeper")), path)  # no camera.K: the boards give it

    argv = ["calibrate", "--table", str(path), "--frame", str(tmp_path / "field.png")]
    argv += ["--chessboard", str(tmp_path / "board_*.png"), "--pattern", "9x6", "--square", "0.03"]
    assert main(argv) == 0
    assert "chessboard_rms_px" in capsys.readouterr().out
    camera = load_config(path).camera
    np.testing.assert_allclose(camera["K"], truth.K, rtol=0.02, atol=3.0)
    saved = CameraCalibration.from_dict(camera["calibration"])
    np.testing.assert_allclose(saved.centre, truth.centre, atol=0.02)


def chessboard_views(K, size, pattern, square):
    """Views of a flat chessboard (``pattern`` inner corners, squares of ``square`` m) through
    a distortion-free camera ``K``, tilted a different way each, filling much of the image."""
    import cv2

    px = 40  # pixels per square of the flat board
    board = np.full(((pattern[1] + 3) * px, (pattern[0] + 3) * px), 255, np.uint8)
    for r in range(pattern[1] + 1):
        for c in range(pattern[0] + 1):
            if (r + c) % 2 == 0:
                board[(r + 1) * px : (r + 2) * px, (c + 1) * px : (c + 2) * px] = 0
    w, h = board.shape[1], board.shape[0]
    corners_px = np.array([[0, 0], [w, 0], [w, h], [0, h]], np.float32)
    corners_m = np.column_stack([(corners_px - 2 * px) * square / px, np.zeros(4)])
    views = []
    for rx, ry, tz in (
        (0.4, 0.0, 0.45),
        (-0.4, 0.2, 0.5),
        (0.1, -0.4, 0.45),
        (0.0, 0.0, 0.4),
        (0.2, 0.3, 0.5),
        (-0.2, -0.3, 0.45),
    ):
        uv, _ = cv2.projectPoints(
            corners_m, np.array([rx, ry, 0.05]), np.array([-0.15, -0.1, tz]), K, np.zeros(5)
        )
        M = cv2.getPerspectiveTransform(corners_px, uv.reshape(4, 2).astype(np.float32))
        views.append(cv2.warpPerspective(board, M, size, borderValue=255))
    return views


def test_envs_shows_one_environment_when_given_its_id(capsys):
    assert main(["envs", "Foosball-Score-v0"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("Foosball-Score-v0  (")
    assert "ball_start: Literal['resting', 'incoming'] = 'resting'" in out
    others = [env_id for env_id in foosball_gym.ENV_IDS if env_id != "Foosball-Score-v0"]
    assert not [env_id for env_id in others if env_id in out]


def test_envs_with_an_unknown_id_names_the_registered_ones(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["envs", "Foosball-Scor-v0"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "Foosball-Scor-v0" in err and "Foosball-Score-v0" in err and "usage" not in err


def test_envs_describes_each_option_without_sending_the_reader_to_another_environment(capsys):
    assert main(["envs"]) == 0
    out = capsys.readouterr().out
    # An option's description is the indented line under "name: type = default".
    described = re.findall(r"^    (\w+): .* = .*\n((?:        .*\n)+)", out, re.M)
    assert len(described) > 50, out[:500]
    for name, text in described:
        assert not re.search(r"\bas \w+'s\b", text), (name, text)
