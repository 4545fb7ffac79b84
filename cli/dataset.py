"""``foosball dataset``: record scripted or learned play of a task as a Minari dataset."""

from __future__ import annotations

import argparse
from typing import Any

from .common import (
    CliError,
    LibraryDefault,
    add_env_arguments,
    check_directory,
    check_model_fits,
    given,
    load_model,
    parse_env_kwargs,
    positive_int,
    scripted,
    seed,
)

RECORD = "foosball_gym.datasets:record_dataset"


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "dataset",
        help="record play of a task as a Minari dataset",
        description="Record seeded episodes of a trained model (a run dir, a .zip or "
        "builtin:NAME) or, with --policy scripted, of the scripted baseline of ENV_ID, as a "
        "Minari dataset for imitation learning and offline RL: observations, actions, rewards, "
        "ends and every step's info. Load it with minari.load_dataset(DATASET_ID) (setting "
        "MINARI_DATASETS_PATH to --data-path where one is given). Needs the datasets extra: "
        'pip install -e ".[datasets]".',
    )
    p.add_argument("target", help="MODEL, or ENV_ID with --policy scripted")
    p.add_argument(
        "--policy",
        choices=["scripted"],
        help="record the scripted baseline of the environment TARGET",
    )
    p.add_argument(
        "--dataset-id",
        required=True,
        metavar="NAMESPACE/NAME-vN",
        help="the dataset's id in Minari's form, e.g. foosball/block/scripted-v0",
    )
    add_env_arguments(p)
    p.add_argument(
        "--episodes",
        type=positive_int,
        default=LibraryDefault(RECORD, "episodes"),
        help="seeded episodes (%(default)s)",
    )
    p.add_argument(
        "--seed",
        type=seed,
        default=LibraryDefault(RECORD, "seed"),
        help="first episode's seed (%(default)s)",
    )
    p.add_argument(
        "--data-path",
        metavar="DIR",
        help="the folder of Minari's datasets to write into "
        "(default: $MINARI_DATASETS_PATH, or ~/.minari/datasets)",
    )
    p.add_argument("--author", help="the dataset's author, stored in its metadata")
    p.add_argument("--author-email", metavar="EMAIL", help="the author's contact")
    p.add_argument(
        "--description",
        help="what the dataset is (default: what played, where, with which seeds, and the "
        "package's version and physics revision)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace a dataset of the same id; it is removed only once the new one is recorded",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from foosball_gym.datasets import (
        check_dataset_id,
        check_replaceable,
        dataset_path,
        datasets_root,
        record_dataset,
        require_datasets_extra,
    )

    require_datasets_extra()
    try:
        check_dataset_id(args.dataset_id)
    except ValueError as err:
        raise CliError(f"--dataset-id: {err}") from None
    if args.data_path is not None:
        check_directory("--data-path", args.data_path)
    target = dataset_path(args.dataset_id, args.data_path)
    try:
        check_replaceable(target, args.dataset_id, args.force)
    except FileExistsError:
        raise CliError(
            f"dataset {args.dataset_id} exists already at {target}; give another id or "
            "version, or --force to replace it"
        ) from None
    except ValueError as err:
        raise CliError(str(err)) from None
    env_kwargs = parse_env_kwargs(args.env_kwarg)
    if args.policy == "scripted":
        if args.env is not None:
            raise CliError(
                "--env is for a MODEL; with --policy scripted, TARGET is the environment"
            )
        env_id = args.target
        policy, name = scripted(env_id, env_kwargs), "scripted"
    else:
        loaded = load_model(args.target, args.trust_model)
        env_id = args.env or loaded.env_id
        if env_id is None:
            raise CliError(
                f"{args.target} has no config.json naming its environment; give --env ENV_ID"
            )
        env_kwargs = {**loaded.env_kwargs, **env_kwargs}
        check_model_fits(loaded, env_id, env_kwargs)
        # A shipped policy by the name that finds it anywhere, not by where it lies here.
        name = args.target if args.target.startswith("builtin:") else loaded.source
        policy = loaded
    try:
        dataset = record_dataset(
            policy,
            env_id,
            args.dataset_id,
            env_kwargs,
            policy_name=name,
            author=args.author,
            author_email=args.author_email,
            description=args.description,
            data_path=args.data_path,
            overwrite=args.force,
            progress=True,
            **given(args, "episodes", "seed"),
        )
    except (ValueError, TypeError, FileExistsError) as err:
        raise CliError(str(err)) from None
    print(
        f"recorded {dataset.total_episodes} episodes ({dataset.total_steps} steps) of {env_id} "
        f"played by {name}"
    )
    print(f"dataset {args.dataset_id} in {target}")
    load = f'minari.load_dataset("{args.dataset_id}")'
    if args.data_path is not None:
        load += f" with MINARI_DATASETS_PATH={datasets_root(args.data_path)}"
    print(f"load it with {load}")
    return 0
