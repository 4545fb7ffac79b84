"""``foosball train --config``: hyperparameters from a YAML file, the command line over them,
the shipped files, and errors that name the file and the key."""

from __future__ import annotations

import json
from dataclasses import asdict, fields
from importlib.util import find_spec
from pathlib import Path

import pytest

import foosball_gym
from foosball_gym import ENV_IDS
from foosball_gym.cli import build_parser, main
from foosball_gym.training.config import LEGACY_DEFAULTS, TrainConfig
from foosball_gym.training.config_file import config_path, load_train_config, shipped_configs

needs_train = pytest.mark.skipif(
    any(find_spec(m) is None for m in ("stable_baselines3", "torch", "yaml")),
    reason='needs the train extra: pip install -e ".[train]"',
)
pytestmark = pytest.mark.skipif(find_spec("yaml") is None, reason="needs PyYAML (the train extra)")

# 3e-4 without a dot is text to YAML 1.1 (PyYAML's), a number to anyone who writes one.
SCORE_FILE = """\
# a test's settings
env_id: Foosball-Score-v0
env_kwargs:
  ball_start: incoming
  goal_reward: 500
timesteps: 1234
n_envs: 3
learning_rate: 3e-4
net_arch: [64, 32]
gamma: 0.98
normalize: false
target_success: 0.9
"""


def config_of(argv: list[str]) -> TrainConfig:
    from foosball_gym.cli.train import config_from_args

    return config_from_args(build_parser().parse_args(["train", *argv]))


@pytest.fixture
def score_file(tmp_path):
    path = tmp_path / "score.yaml"
    path.write_text(SCORE_FILE)
    return str(path)


def test_the_files_values_reach_the_configuration(score_file):
    config = config_of(["--config", score_file])
    assert config.env_id == "Foosball-Score-v0"
    assert (config.timesteps, config.n_envs, config.learning_rate) == (1234, 3, 3e-4)
    assert (config.net_arch, config.gamma, config.normalize) == ((64, 32), 0.98, False)
    assert config.target_success == 0.9
    # What neither the file nor the command line sets is TrainConfig's.
    assert config.batch_size == TrainConfig("Foosball-Score-v0").batch_size


def test_an_option_given_overrides_the_file_and_one_left_out_does_not(score_file):
    config = config_of(
        ["Foosball-Score-v0", "--config", score_file, "--n-envs", "2", "--learning-rate", "1e-3"]
    )
    assert (config.n_envs, config.learning_rate) == (2, 1e-3)
    # --timesteps and --no-normalize were not given: the file's values stand, not the defaults.
    assert (config.timesteps, config.normalize) == (1234, False)


def test_env_kwargs_merge_key_by_key(score_file):
    config = config_of(["--config", score_file, "--env-kwarg", "goal_reward=10"])
    assert config.env_kwargs == {"ball_start": "incoming", "goal_reward": 10}


def test_the_file_may_set_every_field_of_the_configuration(tmp_path):
    """A file spells each field as TrainConfig holds it, also those without an option."""
    wanted = TrainConfig("Foosball-KeeperVsKeeper-v0", self_play=True, target_kl=0.02)
    path = tmp_path / "all.yaml"
    # JSON is YAML; asdict's tuple becomes a list, as a file writes net_arch.
    path.write_text(json.dumps(asdict(wanted)))
    assert load_train_config(str(path)) == wanted
    assert {f.name for f in fields(TrainConfig)} == set(asdict(wanted))


SHIPPED_TASKS = [
    "Foosball-Block-v0",
    "Foosball-FullGame-v0",
    "Foosball-KeeperVsKeeper-v0",
    "Foosball-Score-v0",
]


RECIPES = [
    "block-scratch",
    "score-incoming-aim-scratch",
    "score-incoming-scratch",
    "score-obstacles-paper-batch-scratch",
    "score-obstacles-scratch",
    "score-resting-scratch",
]
# Learned from nothing by self-play, the ladder's rungs among the opponents.
SELF_PLAY_RECIPES = ["full-game-scratch", "keeper-vs-keeper-scratch"]


def test_the_shipped_files_are_one_per_shipped_task_the_from_scratch_recipes_and_the_papers():
    # A new task needs no settings file (docs/add-a-task.md); one it ships names a registered id.
    assert set(SHIPPED_TASKS) <= set(ENV_IDS)
    assert shipped_configs() == sorted([*SHIPPED_TASKS, *RECIPES, *SELF_PLAY_RECIPES, "paper-ppo"])


def test_the_defaults_are_the_block_recipe_that_learns_from_scratch():
    recipe = load_train_config("builtin:block-scratch")
    defaults = TrainConfig(env_id="Foosball-Block-v0")
    # As they train: checked, the options they leave to the algorithm resolved.
    recipe.check()
    defaults.check()
    assert defaults == recipe


def test_paper_ppo_holds_the_defaults_the_recipe_replaced():
    config = load_train_config("builtin:paper-ppo", env_id="Foosball-Score-v0")
    assert config == TrainConfig(env_id="Foosball-Score-v0", **LEGACY_DEFAULTS)
    assert config.net_arch == (256, 128, 64) and config.adam_eps is None


def test_every_shipped_policys_training_command_names_its_settings():
    # A command that leaves settings to the defaults would train something else once they change.
    commands = [
        line
        for path in (Path(foosball_gym.__file__).parent / "builtin").glob("*/REPRODUCE.md")
        for line in path.read_text().splitlines()
        if line.startswith("foosball train")
    ]
    assert len(commands) >= 7
    assert all("--config builtin:" in line for line in commands), commands


@pytest.mark.parametrize("name", RECIPES)
def test_a_from_scratch_recipe_has_no_demonstrations_teacher_or_residual(name):
    config = load_train_config(f"builtin:{name}")  # checked with TrainConfig.check
    assert config_path(f"builtin:{name}").read_text().startswith(f"# {config.env_id}")
    assert config.pretrain_episodes == 0 and config.teacher_steps == 0
    assert not config.env_kwargs.get("residual")
    assert not config.self_play


@pytest.mark.parametrize("name", SELF_PLAY_RECIPES)
def test_a_self_play_recipe_from_nothing_has_no_teacher_and_meets_the_ladder_in_training(name):
    config = load_train_config(f"builtin:{name}")
    assert config_path(f"builtin:{name}").read_text().startswith(f"# {config.env_id}")
    assert config.pretrain_episodes == 0 and config.teacher_steps == 0
    assert not config.env_kwargs.get("residual")
    assert config.self_play and config.selfplay_scripted_share > 0


def test_the_shipped_keeper_from_nothing_is_its_recipe_with_seed_3():
    # builtin:keeper-vs-keeper-scratch names this settings file in its REPRODUCE.md: a change to
    # the file that leaves the policy behind would make that command train something else.
    shipped = Path(foosball_gym.__file__).parent / "builtin" / "keeper-vs-keeper-scratch"
    argv = ["Foosball-KeeperVsKeeper-v0", "--config", "builtin:keeper-vs-keeper-scratch"]
    recipe = config_of([*argv, "--seed", "3"])
    recipe.check()  # picks the learner the run picked: JAX's update, with the train extra
    assert TrainConfig.load(shipped / "config.json") == recipe
    assert "--config builtin:keeper-vs-keeper-scratch --seed 3" in " ".join(
        (shipped / "REPRODUCE.md").read_text().split()
    )


def test_the_incoming_aim_recipe_is_the_settings_its_baselines_rows_were_trained_with():
    # scripts/baselines.py's task score-incoming-aim-entropy: the incoming recipe and options.
    options = ["--env-kwarg", "ball_aim_weight=300", "--worker-rollouts", "--ent-coef", "0.01"]
    given = ["--config", "builtin:score-incoming-scratch", *options, "--timesteps", "6000000"]
    trained = config_of(["Foosball-Score-v0", *given])
    shipped = config_of(["Foosball-Score-v0", "--config", "builtin:score-incoming-aim-scratch"])
    assert shipped == trained
    assert shipped != config_of(["Foosball-Score-v0", *given[:-2]])


@pytest.mark.parametrize("env_id", SHIPPED_TASKS)
def test_each_shipped_file_loads_into_a_valid_configuration(env_id):
    path = config_path(f"builtin:{env_id}")
    assert path.read_text().startswith(f"# {env_id}"), "a shipped file says what it is for"
    config = load_train_config(f"builtin:{env_id}")  # checked with TrainConfig.check
    assert config.env_id == env_id
    assert config_of([env_id, "--config", f"builtin:{env_id}"]) == config


def test_the_block_file_holds_the_readmes_main_job():
    config = load_train_config("builtin:Foosball-Block-v0")
    assert (config.pretrain_episodes, config.target_success) == (200, 0.95)


def write(tmp_path, text: str) -> str:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    return str(path)


BLOCK = "env_id: Foosball-Block-v0\n"


@needs_train
@pytest.mark.parametrize(
    "text, argv, message",
    [
        (BLOCK + "n_env: 3\n", [], "unknown key 'n_env'; allowed: env_id, env_kwargs, algo"),
        (BLOCK + "n_envs: eight\n", [], "n_envs: takes a whole number, got 'eight'"),
        (BLOCK + "net_arch: 64\n", [], "net_arch: takes a list of whole numbers, got 64"),
        (BLOCK + "target_kl: yes\n", [], "target_kl: takes a number or null, got True"),
        (BLOCK + "timesteps: 0\n", [], "timesteps must be at least 1, got 0"),
        (
            BLOCK + "batch_size: 5000\n",
            [],
            "batch_size 5000 is more than a rollout holds: n_steps x n_envs = 128 x 16 = 2048",
        ),
        (BLOCK + "algo: dqn\n", [], "algo: unknown algorithm 'dqn'; allowed: ppo, sac"),
        (BLOCK + "target_success: 2.0\n", [], "target_success must lie in (0, 1]"),
        (BLOCK + "self_play: true\n", [], "self_play: Foosball-Block-v0 has no opponent"),
        (BLOCK + "env_kwargs: {warp: 3}\n", [], "env_kwargs: BlockEnv has no option 'warp'"),
        ("env_id: Foosball-Nothing-v0\n", [], "env_id: unknown environment 'Foosball-Nothing"),
        (BLOCK, ["Foosball-Score-v0"], "env_id: is 'Foosball-Block-v0', but the command line"),
        ("n_envs: 2\n", [], "names no env_id"),
        (BLOCK + "n_envs: 2\nn_envs: 3\n", [], "line 3, column 1: key 'n_envs' is given twice"),
        (BLOCK + "n_envs: [2\n", [], "is not valid YAML: line 3"),
        ("- n_envs\n", [], "must be a mapping of TrainConfig fields"),
    ],
)
def test_a_bad_file_exits_with_status_2_and_one_line_naming_the_file_and_the_key(
    text, argv, message, tmp_path, capsys
):
    path = write(tmp_path, text)
    with pytest.raises(SystemExit) as exit_info:
        main(["train", *argv, "--config", path, "--no-progress", "--out", str(tmp_path / "r")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if ": error: " in line]
    assert len(errors) == 1, err
    assert f"--config {path}: " in errors[0] and message in errors[0], err
    assert not (tmp_path / "r").exists()


@needs_train
@pytest.mark.parametrize(
    "argv, message",
    [
        (["--config", "missing.yaml"], "--config missing.yaml: no such file"),
        (
            ["--config", "Foosball-Block-v0"],
            "no such file (the shipped one is builtin:Foosball-Block-v0)",
        ),
        (
            ["--config", "builtin:Foosball-Nothing-v0"],
            "no shipped configuration; shipped: builtin:Foosball-Block-v0, builtin:Foosball-",
        ),
        (["--config", "builtin:Foosball-Block-v0", "--resume", "runs/x"], "leave --config out"),
    ],
)
def test_a_file_that_cannot_be_used_exits_with_status_2_naming_it(
    argv, message, tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_info:
        main(["train", *argv, "--no-progress"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if ": error: " in line]
    assert len(errors) == 1 and message in errors[0], err


@needs_train
def test_an_option_out_of_range_with_a_file_is_the_command_lines_error(score_file, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "--config", score_file, "--target-success", "2", "--no-progress"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "target_success must lie in (0, 1]" in err and "--config" not in err


@needs_train
def test_two_values_that_clash_are_the_error_not_a_value_the_rest_of_the_file_answers(
    tmp_path, capsys
):
    # batch_size 16384 alone is too big for the default rollout, but the file's n_steps and
    # n_envs hold it: what is wrong is the other two settings together.
    path = write(
        tmp_path,
        "env_id: Foosball-KeeperVsKeeper-v0\nn_envs: 32\nn_steps: 4096\nbatch_size: 16384\n"
        "self_play: true\nworker_rollouts: true\nselfplay_sampled: true\n",
    )
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "--config", path, "--no-progress", "--out", str(tmp_path / "r")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if ": error: " in line]
    assert len(errors) == 1, err
    assert "worker_rollouts" in errors[0] and "selfplay_sampled" in errors[0], err
    assert "batch_size" not in errors[0], err
    assert not (tmp_path / "r").exists()


@needs_train
def test_a_run_from_a_file_records_the_files_values_in_its_config_json(tmp_path, capsys):
    path = tmp_path / "small.yaml"
    path.write_text(
        "# kept small, as the CLI tests keep their runs\n"
        "env_id: Foosball-Block-v0\n"
        "env_kwargs: {goal_reward: 500}\n"
        "timesteps: 100000\n"
        "n_envs: 1\nn_steps: 128\nbatch_size: 64\n"
        "learning_rate: 3e-4\ngamma: 0.98\nnet_arch: [32, 32]\n"
        "eval_freq: 256\neval_episodes: 2\ncheckpoint_freq: 256\n"
    )
    run = tmp_path / "run"
    argv = ["train", "--config", str(path), "--timesteps", "256", "--no-progress"]
    assert main([*argv, "--out", str(run)]) == 0
    config = json.loads((run / "config.json").read_text())
    assert config["timesteps"] == 256  # the command line's
    assert (config["learning_rate"], config["gamma"], config["net_arch"]) == (3e-4, 0.98, [32, 32])
    assert (config["env_id"], config["env_kwargs"]) == ("Foosball-Block-v0", {"goal_reward": 500})
    assert (run / "model.zip").exists()


def test_a_run_from_before_a_setting_existed_keeps_the_value_it_trained_with(tmp_path):
    # A config.json of a run from before adam_eps and fused_adam trained with SB3's Adam.
    old = asdict(TrainConfig(env_id="Foosball-Block-v0", **LEGACY_DEFAULTS))
    del old["adam_eps"], old["fused_adam"]
    (tmp_path / "config.json").write_text(json.dumps(old))
    loaded = TrainConfig.load(tmp_path / "config.json")
    assert (loaded.adam_eps, loaded.fused_adam) == (None, False)
    assert loaded == TrainConfig(env_id="Foosball-Block-v0", **LEGACY_DEFAULTS)
    # One written now holds every field, the new defaults included.
    new = TrainConfig(env_id="Foosball-Block-v0")
    new.save(tmp_path / "config.json")
    assert TrainConfig.load(tmp_path / "config.json") == new


def test_the_rewards_scaled_by_default_can_be_left_as_they_are_from_the_command_line():
    assert config_of(["Foosball-Block-v0"]).normalize_reward
    assert not config_of(["Foosball-Block-v0", "--no-normalize-reward"]).normalize_reward
    papers = config_of(["Foosball-Block-v0", "--config", "builtin:paper-ppo", "--normalize-reward"])
    assert papers.normalize_reward and papers.net_arch == (256, 128, 64)
    with pytest.raises(SystemExit):
        config_of(["Foosball-Block-v0", "--normalize-reward", "--no-normalize-reward"])
