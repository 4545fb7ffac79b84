"""scripts/baselines.py: a recipe trained over seeds, its checkpoints at the budgets evaluated on
the reserved seeds, one CSV row each, and the table's interquartile mean with its interval."""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import pytest
from scripts_loader import load_script


@pytest.fixture(scope="module")
def baselines():
    return load_script("baselines")


RECIPE = """\
env_id: Foosball-Block-v0
n_envs: 2
vec_env: dummy
n_steps: 64
batch_size: 64
n_epochs: 1
timesteps: 256
checkpoint_freq: 128
eval_freq: 128
eval_episodes: 1
"""


def test_train_writes_a_row_per_seed_and_budget_that_its_commands_reproduce(
    baselines, tmp_path: Path
) -> None:
    recipe = tmp_path / "tiny.yaml"
    recipe.write_text(RECIPE)
    tasks = {"tiny": baselines.Task("Foosball-Block-v0", str(recipe), (128, 256))}
    args = argparse.Namespace(
        csv=tmp_path / "baselines.csv",
        task=["tiny"],
        seeds=[3],
        runs=tmp_path / "runs",
        episodes=3,
    )
    baselines.train(args, tasks)
    with open(args.csv, newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(r["seed"], r["env_steps"]) for r in rows] == [("3", "128"), ("3", "256")]
    for row in rows:
        assert row.keys() >= {"env_id", "options", "algorithm", "config", "seed", "env_steps",
                              "wall_seconds", "success", "eval_seed", "eval_episodes"}  # fmt: skip
        assert row["eval_seed"] == str(baselines.EVAL_SEED)
        assert row["eval_episodes"] == "3"
        assert row["algorithm"] == "ppo" and json.loads(row["options"]) == {}
        assert row["learner"] == "jax"  # PPO's default update
        assert 0 <= float(row["success"]) <= 1
        assert float(row["wall_seconds"]) > 0
    # The budget's model is the checkpoint there; the last budget is the run's own end.
    run = baselines.run_dir(args.runs, "tiny", 3)
    assert baselines.budget_model(run, 128).name == "model_0000000128.zip"
    assert baselines.budget_model(run, 256).name in ("model_0000000256.zip", "model.zip")
    # A second call trains nothing more: the CSV already has that seed.
    mtime = args.csv.stat().st_mtime_ns
    baselines.train(args, tasks)
    assert args.csv.stat().st_mtime_ns == mtime


def test_the_table_gives_the_interquartile_mean_over_seeds_with_an_interval(baselines) -> None:
    rows = [
        {"task": "block", "env_steps": "300000", "success": str(s), "wall_seconds": str(w)}
        for s, w in [(0.98, 60), (0.99, 62), (1.0, 58), (0.5, 70), (0.99, 61)]
    ]
    cell = baselines.aggregate(rows, reps=500)[("block", 300000)]
    assert cell["seeds"] == 5
    # The interquartile mean leaves out the worst and the best seed: (0.98 + 0.99 + 0.99) / 3.
    assert cell["iqm"] == pytest.approx((0.98 + 0.99 + 0.99) / 3)
    assert cell["low"] <= cell["iqm"] <= cell["high"]
    assert cell["min"] == 0.5 and cell["median"] == 0.99 and cell["wall_median"] == 61


def test_every_task_names_a_recipe_that_loads_for_its_environment(baselines):
    pytest.importorskip("yaml")
    from foosball_gym.training.config_file import load_train_config

    for name, task in baselines.TASKS.items():
        assert load_train_config(task.recipe).env_id == task.env_id, name


def test_every_budget_is_a_step_its_run_writes_a_model_at(baselines):
    # A budget between two checkpoints would stop the table's evaluation (budget_model).
    pytest.importorskip("yaml")
    from foosball_gym.training.config_file import load_train_config

    for name, task in baselines.TASKS.items():
        config = load_train_config(task.recipe)
        options = list(task.options)
        end = config.timesteps
        if "--timesteps" in options:
            end = int(options[options.index("--timesteps") + 1])
        for steps in task.budgets:
            on_checkpoint = steps % config.checkpoint_freq == 0 and steps % config.n_envs == 0
            assert steps == end or on_checkpoint, (name, steps)


def test_a_task_s_options_go_into_its_command(baselines, tmp_path: Path) -> None:
    task = baselines.TASKS["block-torch"]
    command = baselines.train_command(task, 2, tmp_path)
    assert command[:5] == ["foosball", "train", "Foosball-Block-v0", "--config", task.recipe]
    assert command[5:7] == ["--learner", "torch"]


def test_runs_whose_steps_differ_by_a_serves_length_share_their_budgets_cell(baselines) -> None:
    rows = [
        {"task": "serves", "env_steps": str(n), "success": "0.8", "wall_seconds": "900"}
        for n in (10_886_578, 10_848_360, 10_912_004)
    ]
    rows.append({"task": "block", "env_steps": "300000", "success": "1", "wall_seconds": "30"})
    table = baselines.aggregate(rows, reps=50)
    assert sorted(table) == [("block", 300_000), ("serves", 11_000_000)]
    assert table[("serves", 11_000_000)]["seeds"] == 3
    budgets = (100_000, 500_000, 6_000_000, 30_000_000)
    assert [baselines.budget_of(n) for n in budgets] == list(budgets)


def test_a_task_train_does_not_run_is_titled_by_its_rows_command(baselines) -> None:
    rows = [{"task": "serves", "config": "python scripts/one_decision.py --spin=-0.3,4,0.3"}]
    assert baselines._title("serves", rows) == f"serves: {rows[0]['config']}"
    assert baselines._title("serves") == "serves"
    assert baselines._title("block").startswith("block: builtin:block-scratch")
