"""A run's files as they are read back: a model never meets statistics not its own, damaged
files and oversized models are refused in one line before any work."""

from __future__ import annotations

import errno
import functools
import json
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

import foosball_gym.training.run_dir.files as run_files  # noqa: E402
from foosball_gym.cli import main  # noqa: E402
from foosball_gym.training.config import TrainConfig  # noqa: E402
from foosball_gym.training.loading import ModelLoadError, load_policy  # noqa: E402
from foosball_gym.training.run_dir import storage  # noqa: E402
from foosball_gym.training.run_dir.storage import (  # noqa: E402
    ZIP_RECORD,
    NormStats,
    read_model_zip,
    save_model,
    statistics_beside,
    zip_statistics,
)
from foosball_gym.training.sb3.trainer import train  # noqa: E402

TINY = {
    "timesteps": 128,
    "n_envs": 1,
    "n_steps": 64,
    "batch_size": 64,
    "n_epochs": 1,
    "eval_freq": 10_000,
    "eval_episodes": 1,
    "checkpoint_freq": 64,
    # The resumes below extend the run, which a decaying learning rate refuses.
    "lr_schedule": "constant",
}
CHECKPOINT = "checkpoints/model_0000000128"


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    run = tmp_path_factory.mktemp("files") / "run"
    train(TrainConfig("Foosball-Block-v0", **TINY), run)
    return run


@pytest.fixture
def run(trained, tmp_path):
    return Path(shutil.copytree(trained, tmp_path / "run"))


def rewrite_zip(path: Path, entries: dict[str, bytes | None]) -> None:
    """Replace (bytes) or remove (None) entries of a zip."""
    with zipfile.ZipFile(path) as archive:
        kept = {n: archive.read(n) for n in archive.namelist()}
    kept.update(entries)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, content in kept.items():
            if content is not None:
                archive.writestr(name, content)


def as_written_before(run: Path) -> None:
    """Rewrite ``run``'s model zips as runs wrote them before the statistics went into the
    zip: without the record, their statistics in ``vecnormalize.json`` beside them."""
    for path in sorted(run.rglob("*.zip")):
        _, stats = zip_statistics(path)
        rewrite_zip(path, {ZIP_RECORD: None})
        assert stats is not None
        stats.save(statistics_beside(path)[-1])


def refused(argv: list[str], capsys) -> str:
    """The one line ``foosball ARGV`` is refused with (exit 2, no traceback)."""
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    err = capsys.readouterr().err
    assert exit_info.value.code == 2, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err


# -- a model and its statistics ----------------------------------------------------------


def test_every_model_of_a_run_holds_the_statistics_it_was_saved_with(trained):
    zips = sorted(trained.rglob("*.zip"))
    assert {p.relative_to(trained).as_posix() for p in zips} >= {"model.zip", f"{CHECKPOINT}.zip"}
    for path in zips:
        recorded, stats = zip_statistics(path)
        assert recorded and stats is not None and stats.obs_count > 0, path
    assert not list(trained.rglob("*vecnormalize*")), "nothing beside a zip to disagree with it"
    _, stats = zip_statistics(trained / "model.zip")
    loaded = load_policy(trained).policy
    np.testing.assert_array_equal(loaded.obs_mean, stats.obs_mean)
    np.testing.assert_array_equal(loaded.obs_var, stats.obs_var)


def test_a_save_stopped_half_way_leaves_the_previous_model_with_its_own_statistics(
    run, monkeypatch
):
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    before = (run / "model.zip").read_bytes()
    venv = VecNormalize(make_vec_env("Foosball-Block-v0", n_envs=1))
    venv.obs_rms.mean += 5.0  # statistics that differ from the run's
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=64, device="cpu")

    def killed(path, data):
        with open(path, "wb") as f:
            f.write(data[: len(data) // 2])
        raise KeyboardInterrupt  # as a kill lands: half the file written

    monkeypatch.setattr(run_files, "_write_file", killed)
    with pytest.raises(KeyboardInterrupt):
        save_model(model, run / "model.zip")
    venv.close()
    assert (run / "model.zip").read_bytes() == before
    assert not list(run.rglob("*.tmp"))
    _, stats = zip_statistics(run / "model.zip")
    np.testing.assert_array_equal(load_policy(run).policy.obs_mean, stats.obs_mean)


def test_a_model_whose_statistics_are_missing_is_refused(run, capsys):
    as_written_before(run)
    (run / "vecnormalize.json").unlink()
    with pytest.raises(ModelLoadError, match="normalize: true.*statistics.*missing"):
        load_policy(run)
    assert "missing" in refused(["eval", str(run), "--episodes", "1"], capsys)
    (run / f"{CHECKPOINT}_vecnormalize.json").unlink()
    with pytest.raises(ModelLoadError, match="missing"):
        load_policy(run / f"{CHECKPOINT}.zip")
    # A run from before still loads with the statistics beside its zip.
    load_policy(run / "best" / "model.zip")


@pytest.mark.parametrize("model", ["model.zip", f"{CHECKPOINT}.zip", "best/model.zip"])
def test_a_model_recorded_without_statistics_in_a_normalising_run_is_refused_as_resume_does(
    run, capsys, model
):
    # Played as it is, the policy sees raw observations: 18 % where it blocks 100 % with them.
    for path in run.rglob("*.zip"):
        record = {"format": 1, "vecnormalize": None}
        rewrite_zip(path, {ZIP_RECORD: json.dumps(record).encode()})
    assert json.loads((run / "config.json").read_text())["normalize"] is True
    with pytest.raises(ModelLoadError, match="holds no normalisation statistics.*normalize: true"):
        load_policy(run / model)
    for argv in (["eval", str(run / model)], ["play", str(run / model), "--table", "sim"]):
        assert "normalize: true" in refused(argv, capsys)
    resume = ["train", "--resume", str(run), "--timesteps", "256", "--no-progress"]
    assert "holds no statistics" in refused(resume, capsys)


def test_resuming_from_a_checkpoint_without_its_statistics_is_refused(run, capsys):
    as_written_before(run)
    pointer = json.loads((run / "checkpoints" / "latest.json").read_text())
    (run / "model.zip").unlink()
    (run / f"{CHECKPOINT}_vecnormalize.json").unlink()
    assert pointer["timesteps"] == 128
    err = refused(["train", "--resume", str(run), "--timesteps", "256", "--no-progress"], capsys)
    assert "holds no statistics" in err


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"clip_obs": -1.0}, "clip_obs must be above 0"),
        ({"clip_obs": 0.0}, "clip_obs must be above 0"),
        ({"epsilon": 0.0}, "epsilon must be above 0"),
        ({"obs_mean": [1e300, 0, 0, 0, 0, 0]}, "mean of 1e"),
        ({"obs_var": [-1.0, 1, 1, 1, 1, 1]}, "variances must lie in"),
        ({"obs_var": [1e13, 1, 1, 1, 1, 1]}, "variances must lie in"),
        ({"obs_count": float("nan")}, "finite numbers"),
        ({"obs_mean": [0.0], "obs_var": [1.0]}, "of 1 observations, the policy takes 6"),
        ({"norm_obs": "yes"}, "true or false"),
    ],
)
def test_statistics_that_make_no_sense_are_refused(run, capsys, change, message):
    _, stats = zip_statistics(run / "model.zip")
    with zipfile.ZipFile(run / "model.zip") as archive:
        own = archive.read(ZIP_RECORD)
    record = {"format": 1, "vecnormalize": {**stats.to_dict(), **change}}
    rewrite_zip(run / "model.zip", {ZIP_RECORD: json.dumps(record).encode()})
    with pytest.raises(ModelLoadError, match=message):
        load_policy(run)
    refused(["eval", str(run), "--episodes", "1"], capsys)
    # The same numbers beside a zip from before are refused alike.
    rewrite_zip(run / "model.zip", {ZIP_RECORD: own})
    as_written_before(run)
    (run / "vecnormalize.json").write_text(json.dumps({**stats.to_dict(), **change}))
    with pytest.raises(ModelLoadError, match=message):
        load_policy(run)


def test_the_shipped_policies_statistics_pass_the_checks():
    # Written before the statistics went into the zip: beside it.
    from foosball_gym.training.loading.loader import builtin_names, builtin_path

    for name in builtin_names():
        for path in builtin_path(name).rglob("vecnormalize.json"):
            NormStats.load(path)


# -- damaged run files -------------------------------------------------------------------


@pytest.mark.parametrize(
    ("damage", "eval_says", "resume_says"),
    [
        ("[]", "JSON list, not a run's configuration", "JSON list, not the object"),
        ('"x"', "JSON str, not a run's configuration", "JSON str, not the object"),
        ('{"env_id": ', "not valid JSON", "not valid JSON"),
        ("[" * 100_000 + "]" * 100_000, "nested too deep", "nested too deep"),
        (
            '{"env_id": "Foosball-Block-v0", "seed": ' + "7" * 5000 + "}",
            "an integer of 5000 digits",
            "5000 digits",
        ),
        ({"env_kwargs": []}, "env_kwargs must be an object", "env_kwargs must be an object"),
        ({"env_kwargs": None}, "env_kwargs must be an object", "env_kwargs must be an object"),
        ({"env_kwargs": {"residual": "big"}}, "residual must be a number", "residual must be"),
        ({"net_arch": "big"}, None, "net_arch must be a list of whole numbers"),
        ({"timesteps": "many"}, None, "timesteps must be a whole number"),
        ({"env_id": 7}, "env_id must be an environment id", "env_id must be a string"),
        ({"backend": "tf"}, None, "backend must be sb3 or rllib"),
    ],
)
def test_a_damaged_configuration_is_refused_in_one_line(
    run, capsys, damage, eval_says, resume_says
):
    path = run / "config.json"
    if isinstance(damage, str):
        path.write_text(damage)
    else:
        path.write_text(json.dumps({**json.loads(path.read_text()), **damage}))
    if eval_says is not None:
        assert eval_says in refused(["eval", str(run), "--episodes", "1"], capsys)
    argv = ["train", "--resume", str(run), "--timesteps", "256", "--no-progress"]
    assert resume_says in refused(argv, capsys)
    assert not (run / "lost").exists() and not list(run.rglob("*.tmp"))


@pytest.mark.parametrize(
    "pointer",
    ["{", "[]", '{"timesteps": "x", "model": "m.zip"}', '{"timesteps": 1, "model": "../x"}'],
)
def test_a_damaged_checkpoint_pointer_is_refused_in_one_line(run, capsys, pointer):
    (run / "checkpoints" / "latest.json").write_text(pointer)
    argv = ["train", "--resume", str(run), "--timesteps", "256", "--no-progress"]
    assert "latest.json" in refused(argv, capsys)


def test_a_damaged_curve_or_best_record_is_refused_in_one_line(run, capsys):
    argv = ["train", "--resume", str(run), "--timesteps", "256", "--no-progress"]
    best = run / "best" / "best.json"
    best.write_text('{"success_rate": "high"}')
    assert "best.json" in refused(argv, capsys)
    best.unlink()
    (run / "eval.csv").write_text("timesteps,wall_seconds\n128,x\n")
    assert "eval.csv, line 2" in refused(argv, capsys)
    # A row no cut could keep or count lost: once dropped without a word.
    (run / "eval.csv").write_text("timesteps,wall_seconds\n128,1.0\nnan,2.0\n")
    assert "eval.csv, line 3: its timesteps is nan, not a finite number" in refused(argv, capsys)
    (run / "eval.csv").write_bytes(b"timesteps,wall_seconds\n128,\xff\xfe\n")
    assert f"{run / 'eval.csv'} is not an evaluation curve: not UTF-8" in refused(argv, capsys)


@pytest.fixture(scope="module")
def selfplay_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("selfplay") / "run"
    config = TrainConfig(
        "Foosball-KeeperVsKeeper-v0",
        env_kwargs={"stagnation_steps": 20},
        selfplay_window=2,
        **TINY,
    )
    train(config, run)
    return run


@pytest.mark.parametrize(
    ("history", "says"),
    [
        ("{}", "JSON dict, not the list"),
        ('{"generation": 0}', "JSON dict, not the list"),
        ("[1]", "record 0 is a int"),
        ('[{"generation": "0", "timesteps": 0, "games": 0}]', "generation must be a whole"),
        ("nonsense", "not valid JSON"),
    ],
)
def test_a_damaged_self_play_history_is_refused_in_one_line(
    selfplay_run, tmp_path, capsys, history, says
):
    run = Path(shutil.copytree(selfplay_run, tmp_path / "run"))
    (run / "selfplay" / "history.json").write_text(history)
    assert says in refused(["league", str(run), "--games", "2"], capsys)
    argv = ["train", "--resume", str(run), "--timesteps", "256", "--no-progress"]
    assert says in refused(argv, capsys)


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
def test_outputs_that_cannot_be_written_are_refused_before_the_work(capsys, monkeypatch):
    import foosball_gym.training.selfplay.league as league
    from foosball_gym.cli import evaluate as eval_command

    played = []

    def recorder(real):
        @functools.wraps(real)  # the parser reads its signature's defaults
        def record(*args, **kwargs):
            played.append(real.__name__)
            return real(*args, **kwargs)

        return record

    monkeypatch.setattr(eval_command, "evaluate", recorder(eval_command.evaluate))
    monkeypatch.setattr(league, "run_league", recorder(league.run_league))
    # /proc takes no new file, whatever the rights (root's included).
    argv = ["eval", "builtin:block", "--episodes", "100", "--json", "/proc/x.json"]
    assert "--json /proc/x.json cannot be written" in refused(argv, capsys)
    argv = ["league", "--env", "Foosball-KeeperVsKeeper-v0", "--add", "scripted:0"]
    argv += ["--add", "scripted:1", "--games", "2", "--out", "/proc/x"]
    assert "--out /proc/x cannot be written" in refused(argv, capsys)
    assert played == []


# -- model sizes -------------------------------------------------------------------------


def inner_torch_file(records: dict[str, bytes], compression: int) -> bytes:
    """A torch-format zip holding ``records`` (what ``torch.save`` writes, by hand)."""
    import io

    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression) as inner:
        for name, content in records.items():
            inner.writestr(name, content)
    return buffer.getvalue()


@pytest.fixture
def opened(monkeypatch):
    """The names of the zip entries opened to be inflated, in order."""
    names: list[str] = []
    real_open = zipfile.ZipFile.open

    def recording(self, name, *args, **kwargs):
        names.append(name if isinstance(name, str) else name.filename)
        return real_open(self, name, *args, **kwargs)

    monkeypatch.setattr(zipfile.ZipFile, "open", recording)
    return names


def test_a_model_zip_that_inflates_past_the_limit_is_refused_before_anything_is_inflated(
    run, monkeypatch, opened, capsys
):
    monkeypatch.setattr(storage, "MODEL_SIZE_LIMIT", 4 * 2**20)
    # A 6 MiB tensor of zeros, deflated to a few kB.
    huge = inner_torch_file({"archive/data/0": bytes(6 * 2**20)}, zipfile.ZIP_STORED)
    rewrite_zip(run / "model.zip", {"policy.pth": huge})
    assert (run / "model.zip").stat().st_size < 2**20
    opened.clear()
    with pytest.raises(ModelLoadError, match=r"it says it inflates to \d+ MiB, past the 4 MiB"):
        load_policy(run)
    assert opened == [], "nothing was inflated"
    assert "past the 4 MiB" in refused(["eval", str(run), "--episodes", "1"], capsys)


def test_a_weights_entry_whose_own_records_inflate_past_the_limit_is_refused_before_torch_reads_it(
    run, monkeypatch
):
    import torch

    monkeypatch.setattr(storage, "MODEL_SIZE_LIMIT", 4 * 2**20)
    loaded = []
    monkeypatch.setattr(torch, "load", lambda *a, **k: loaded.append(a))
    # Small in the model zip, but a record in it says it inflates to 6 MiB.
    sneaky = inner_torch_file({"archive/data/0": bytes(6 * 2**20)}, zipfile.ZIP_DEFLATED)
    rewrite_zip(run / "model.zip", {"policy.pth": sneaky})
    with pytest.raises(ValueError, match="its entry policy.pth says it inflates to 6 MiB"):
        read_model_zip(run / "model.zip")
    assert loaded == []


def lying_zip(path: Path, declared: int, inflated: int) -> None:
    """A zip whose one entry, ``data``, says it inflates to ``declared`` bytes and inflates to
    ``inflated`` (zeros; its check sum theirs)."""
    import struct
    import zlib

    deflate = zlib.compressobj(9, zlib.DEFLATED, -15)
    compressed, crc, block = bytearray(), 0, bytes(2**20)
    for _ in range(inflated // len(block)):
        compressed += deflate.compress(block)
        crc = zlib.crc32(block, crc)
    compressed += deflate.flush()
    name = b"data"
    sizes = (crc, len(compressed), declared, len(name))
    local = struct.pack("<IHHHHHIIIHH", 0x04034B50, 20, 0, 8, 0, 0, *sizes, 0)
    central = struct.pack(
        "<IHHHHHHIIIHHHHHII", 0x02014B50, 20, 20, 0, 8, 0, 0, *sizes, 0, 0, 0, 0, 0, 0
    )
    start = len(local) + len(name) + len(compressed)
    directory = central + name
    end = struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, 1, 1, len(directory), start, 0)
    path.write_bytes(local + name + bytes(compressed) + directory + end)


def test_a_zip_entry_that_inflates_past_the_size_it_declares_is_refused_at_that_size(
    tmp_path, capsys
):
    """An entry that says 100 bytes and inflates to 256 MiB: once inflated whole (ZipFile.read
    takes up to 2 GiB in one go) before its check sum refused it."""
    import tracemalloc

    path = tmp_path / "model.zip"
    lying_zip(path, declared=100, inflated=256 * 2**20)
    assert path.stat().st_size < 2**20
    tracemalloc.start()
    try:
        with pytest.raises(ValueError, match="a damaged one"):
            read_model_zip(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 32 * 2**20, f"{peak / 2**20:.0f} MiB inflated"
    err = refused(["eval", str(path), "--env", "Foosball-Block-v0", "--episodes", "1"], capsys)
    assert "is not a zip file, or a damaged one" in err


def test_the_size_limit_holds_the_policies_of_this_package_many_times_over(trained):
    for path in trained.rglob("*.zip"):
        with zipfile.ZipFile(path) as archive:
            assert sum(i.file_size for i in archive.infolist()) * 50 < storage.MODEL_SIZE_LIMIT
        read_model_zip(path)


@pytest.mark.slow
def test_a_model_zip_holding_a_deflated_gigabyte_tensor_is_refused_unread(run, opened, capsys):
    # Written in pieces: nothing here holds the gigabyte in memory either.
    with zipfile.ZipFile(run / "model.zip") as archive:
        entries = {n: archive.read(n) for n in archive.namelist() if n != "policy.pth"}
    with zipfile.ZipFile(run / "model.zip", "w", zipfile.ZIP_DEFLATED) as archive:
        for name, content in entries.items():
            archive.writestr(name, content)
        with archive.open("policy.pth", "w", force_zip64=True) as entry:
            with zipfile.ZipFile(entry, "w", zipfile.ZIP_STORED) as inner:
                with inner.open("archive/data/0", "w", force_zip64=True) as record:
                    for _ in range(1024):
                        record.write(bytes(2**20))
    assert (run / "model.zip").stat().st_size < 4 * 2**20
    opened.clear()
    assert "inflates to 1025 MiB, past the 256 MiB" in refused(
        ["eval", str(run), "--episodes", "1"], capsys
    )
    assert "policy.pth" not in opened


def test_an_error_writing_a_run_file_names_it(tmp_path, monkeypatch):
    def full(path, data):
        with open(path, "wb") as f:
            f.write(data[:1])
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(run_files, "_write_file", full)
    target = tmp_path / "config.json"
    with pytest.raises(OSError, match="No space left") as err:
        run_files.atomic_write_text(target, "{}")
    assert err.value.filename == str(target) and err.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "text",
    ["[" * 100_000 + "]" * 100_000, '{"env_id": "Foosball-Block-v0", "seed": ' + "9" * 5000 + "}"],
)
def test_load_policy_refuses_a_hostile_config_json_with_its_one_line_error(tmp_path, text):
    from foosball_gym.training.loading import ModelLoadError, builtin_path, load_policy

    shutil.copy(builtin_path("block") / "model.zip", tmp_path / "model.zip")
    (tmp_path / "config.json").write_text(text)
    with pytest.raises(ModelLoadError, match="config.json is not valid JSON"):
        load_policy(tmp_path)
