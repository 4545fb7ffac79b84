"""Reading and writing a run's model files without unpickling anything.

Python's pickle runs whatever code a file asks it to, so a model file from elsewhere could do
anything on load. Runs are therefore written as plain data only:

- the normalisation statistics as JSON numbers (:class:`NormStats`), not VecNormalize's
  pickle;
- the model as Stable-Baselines3's zip with the pickled (``":serialized:"``) fields of its
  ``data`` entry removed (:func:`strip_pickles`); the weights stay in its ``.pth`` entries,
  which are read with ``torch.load(weights_only=True)`` (:func:`read_model_zip`).

The statistics go into the model's zip, as its entry ``foosball_gym.json`` (:data:`ZIP_RECORD`),
which also says where a model trained without them: a model and its statistics are written in
one step, the zip's replacement, so a run killed at any moment holds either the old pair or
the new one, never a model beside another save's statistics (or none). Runs from before kept
them beside the zip in ``vecnormalize.json``, which is still read for such a zip.

A zip is read only where what its entries say they inflate to stays under
:data:`MODEL_SIZE_LIMIT`, so a small file that inflates to gigabytes is refused before
anything is inflated.

Files from before, ``vecnormalize.pkl`` and self-play snapshots holding a pickled policy, are
read only when the caller says it trusts them (``trust=True``, ``--trust-model``);
``foosball migrate RUN --trust-model`` converts a run once (:mod:`.migrate`).
"""

from __future__ import annotations

import io
import json
import math
import os
import pickle
import zipfile
import zlib
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from foosball_gym import user_json
from foosball_gym.training.run_dir.files import (
    LEGACY_NORM_FILE,
    MODEL_FILE,
    NORM_FILE,
    atomic_write_text,
    write_bytes,
)

NORM_FORMAT = 1
# The entry of a model zip that holds its normalisation statistics (or says it has none).
ZIP_RECORD = "foosball_gym.json"
ZIP_RECORD_FORMAT = 1
# The most a model file's entries may say they inflate to, in all. This package's policies
# take under 2 MB (weights and optimiser state of [256, 128, 64]); 256 MiB holds PPO's
# [2048, 2048, 2048] with its optimiser's state.
MODEL_SIZE_LIMIT = 256 * 2**20
# Bounds past which statistics cannot come from an observation of this package (positions in
# metres, speeds in m/s and rad/s): a mean of 1e300 or a spread of 1e13 is a damaged file.
MOST_OBS_MEAN = 1e6
MOST_OBS_VAR = 1e12
# SB3 marks each field it cloudpickled with this key, next to a readable description.
SERIALIZED = ":serialized:"


class UntrustedFileError(ValueError):
    """A file would have to be unpickled, and the caller did not say it trusts it."""


def refusal(path: Path, run: Path | str) -> UntrustedFileError:
    """The error for a pickled ``path`` of the run ``run``: why it is not read, and what to do."""
    return UntrustedFileError(
        f"{path} is stored with pickle, which can run any code when it is read, so it was not "
        f"read. If you trust where {run} comes from, convert it once with "
        f"`foosball migrate {run} --trust-model` (or give --trust-model to read it as it is)"
    )


@dataclass
class NormStats:
    """VecNormalize's statistics and settings, as plain numbers.

    ``obs_mean``, ``obs_var`` and ``obs_count`` are the running statistics of the
    observations, ``ret_*`` those of the returns (used where rewards are normalised).
    """

    obs_mean: list[float]
    obs_var: list[float]
    obs_count: float
    ret_mean: float
    ret_var: float
    ret_count: float
    clip_obs: float
    clip_reward: float
    epsilon: float
    gamma: float
    norm_obs: bool
    norm_reward: bool

    @classmethod
    def of(cls, venv: Any) -> NormStats:
        """The statistics of a ``VecNormalize`` (or an object with its attributes)."""
        if isinstance(venv.obs_rms, dict):
            raise ValueError("dictionary observations are not supported")
        return cls(
            obs_mean=[float(v) for v in np.ravel(venv.obs_rms.mean)],
            obs_var=[float(v) for v in np.ravel(venv.obs_rms.var)],
            obs_count=float(venv.obs_rms.count),
            ret_mean=float(np.ravel(venv.ret_rms.mean)[0]),
            ret_var=float(np.ravel(venv.ret_rms.var)[0]),
            ret_count=float(venv.ret_rms.count),
            clip_obs=float(venv.clip_obs),
            clip_reward=float(venv.clip_reward),
            epsilon=float(venv.epsilon),
            gamma=float(venv.gamma),
            norm_obs=bool(venv.norm_obs),
            norm_reward=bool(venv.norm_reward),
        )

    def apply(self, venv: Any) -> None:
        """Set a ``VecNormalize``'s running statistics to these (its settings stay its own)."""
        if len(self.obs_mean) != int(np.prod(venv.obs_rms.mean.shape)):
            raise ValueError(
                f"the statistics are of {len(self.obs_mean)} observations, the environment "
                f"gives {int(np.prod(venv.obs_rms.mean.shape))}"
            )
        shape = venv.obs_rms.mean.shape
        venv.obs_rms.mean = np.array(self.obs_mean, np.float64).reshape(shape)
        venv.obs_rms.var = np.array(self.obs_var, np.float64).reshape(shape)
        venv.obs_rms.count = self.obs_count
        venv.ret_rms.mean = np.array(self.ret_mean, np.float64)
        venv.ret_rms.var = np.array(self.ret_var, np.float64)
        venv.ret_rms.count = self.ret_count

    def to_dict(self) -> dict[str, Any]:
        return {"format": NORM_FORMAT, **asdict(self)}

    def save(self, path: Path) -> None:
        atomic_write_text(Path(path), json.dumps(self.to_dict()))

    @classmethod
    def load(cls, path: Path) -> NormStats:
        """Read statistics :meth:`save` wrote; ValueError naming what is wrong otherwise."""
        try:
            data = user_json.loads(Path(path).read_text(encoding="utf-8"))
        except ValueError as err:
            raise ValueError(f"{path} is not valid JSON: {err}") from None
        return cls.from_dict(data, str(path))

    @classmethod
    def from_dict(cls, data: Any, where: str) -> NormStats:
        """The statistics ``data`` (:meth:`to_dict`'s) hold, checked (:meth:`check`);
        ValueError naming ``where`` they come from and what is wrong otherwise."""
        if not isinstance(data, dict) or data.get("format") != NORM_FORMAT:
            raise ValueError(f"{where} is not a normalisation record of format {NORM_FORMAT}")
        names = {f.name for f in fields(cls)}
        if set(data) - {"format"} != names:
            missing = sorted(names - set(data))
            extra = sorted(set(data) - names - {"format"})
            raise ValueError(
                f"{where}: the normalisation record "
                + (f"lacks {', '.join(missing)}" if missing else f"has unknown {', '.join(extra)}")
            )
        stats = cls(**{k: v for k, v in data.items() if k != "format"})
        stats.check(where)
        return stats

    def check(self, where: str) -> None:
        """Raise ValueError, naming ``where``, for statistics no run of this package makes:
        not numbers, not finite, a variance below 0, a mean or variance past
        :data:`MOST_OBS_MEAN` and :data:`MOST_OBS_VAR`, or a clip or epsilon not above 0."""

        def number(v: Any) -> bool:
            return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)

        if not isinstance(self.obs_mean, list) or not isinstance(self.obs_var, list):
            raise ValueError(f"{where}: obs_mean and obs_var must be lists of numbers")
        if not self.obs_mean or len(self.obs_mean) != len(self.obs_var):
            raise ValueError(f"{where}: obs_mean and obs_var must be lists of the same length")
        scalars = [self.obs_count, self.ret_mean, self.ret_var, self.ret_count, self.clip_obs]
        scalars += [self.clip_reward, self.epsilon, self.gamma]
        if not all(number(v) for v in (*self.obs_mean, *self.obs_var, *scalars)):
            raise ValueError(f"{where}: the statistics must be finite numbers")
        if not all(isinstance(v, bool) for v in (self.norm_obs, self.norm_reward)):
            raise ValueError(f"{where}: norm_obs and norm_reward must be true or false")
        worst_mean = max(abs(v) for v in self.obs_mean)
        if worst_mean > MOST_OBS_MEAN:
            raise ValueError(
                f"{where}: an observation's mean of {worst_mean:g} is past what any observation "
                f"takes (at most {MOST_OBS_MEAN:g} in size): the statistics are damaged"
            )
        if not all(0 <= v <= MOST_OBS_VAR for v in self.obs_var) or self.ret_var < 0:
            raise ValueError(
                f"{where}: variances must lie in [0, {MOST_OBS_VAR:g}], got obs_var "
                f"{min(self.obs_var):g} to {max(self.obs_var):g} and ret_var {self.ret_var:g}"
            )
        for name in ("clip_obs", "clip_reward", "epsilon"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{where}: {name} must be above 0, got {getattr(self, name)}")
        if min(self.obs_count, self.ret_count) < 0 or not 0 < self.gamma <= 1:
            raise ValueError(f"{where}: counts must be 0 or more and gamma in (0, 1]")


def load_pickled_norm(path: Path) -> NormStats:
    """The statistics of a ``vecnormalize.pkl``. Unpickles it: only for trusted files."""
    with open(path, "rb") as f:
        saved = pickle.load(f)  # noqa: S301 - the caller trusts the file
    return NormStats.of(saved)


def read_norm(path: Path, run: Path | str, trust: bool) -> NormStats:
    """Normalisation statistics from a JSON file, or from a legacy pickle where trusted."""
    if path.name.endswith(LEGACY_NORM_FILE):
        if not trust:
            raise refusal(path, run)
        return load_pickled_norm(path)
    return NormStats.load(path)


def check_declared_size(archive: zipfile.ZipFile, where: str, limit: int) -> None:
    """Refuse a zip whose entries say they inflate to more than ``limit`` bytes in all,
    before any is inflated (the reader stops at the size an entry declares)."""
    declared = sum(info.file_size for info in archive.infolist())
    if declared > limit:
        raise ValueError(
            f"{where} says it inflates to {declared / 2**20:.0f} MiB, past the "
            f"{limit / 2**20:.0f} MiB a model may take (foosball_gym's take under 2 MiB), "
            "so it was not read"
        )


#: How much of an entry is inflated at a time (:func:`read_entry`).
READ_CHUNK = 2**20


def read_entry(archive: zipfile.ZipFile, name: str | zipfile.ZipInfo) -> bytes:
    """A zip entry's bytes, inflated :data:`READ_CHUNK` at a time.

    ``ZipFile.read`` inflates all of an entry's compressed bytes in one go (up to 2 GiB) and
    only then cuts them to the size the entry declares: an entry that declares a few bytes and
    inflates to gigabytes took gigabytes of memory before its check sum refused it. Read a
    megabyte at a time, it is refused at the size it declared.
    """
    out = bytearray()
    with archive.open(name) as entry:
        while chunk := entry.read(READ_CHUNK):
            out += chunk
    return bytes(out)


def check_torch_file(path: Path, limit: int | None = None) -> None:
    """:func:`check_declared_size` for a file ``torch.save`` wrote (a zip of its own), against
    :data:`MODEL_SIZE_LIMIT` unless ``limit`` is given."""
    try:
        with zipfile.ZipFile(path) as archive:
            check_declared_size(archive, str(path), MODEL_SIZE_LIMIT if limit is None else limit)
    except zipfile.BadZipFile:
        pass  # not a zip: torch.load says what it is not


def _check_pth(content: bytes, where: str, limit: int) -> None:
    try:
        with zipfile.ZipFile(io.BytesIO(content)) as inner:
            check_declared_size(inner, where, limit)
    except zipfile.BadZipFile:
        raise ValueError(f"{where} is not a PyTorch file of the format SB3 writes") from None


def _load_pth(content: bytes, where: str) -> Any:
    import torch as th

    try:
        return th.load(io.BytesIO(content), map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as err:
        first = str(err).strip().splitlines()[0]
        raise ValueError(
            f"an entry holds more than weights, so it was not read ({first})"
        ) from None
    except (RuntimeError, EOFError) as err:
        raise ValueError(f"{where} cannot be read as tensors ({err})") from None


def read_model_zip(
    path: Path, limit: int | None = None
) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any] | None]:
    """A Stable-Baselines3 model zip's plain fields, its state dicts and its PyTorch variables.

    ``data``'s pickled fields are not evaluated (they are left as their description), and the
    ``.pth`` entries are read with ``weights_only=True``, which refuses anything but tensors
    and plain containers, as Stable-Baselines3's ``load_from_zip_file`` reads them. Nothing is
    inflated where the zip, or a ``.pth`` in it, says it inflates to more than ``limit`` bytes
    (:data:`MODEL_SIZE_LIMIT` unless given).

    Raises:
        ValueError: not a zip, too large, or an entry is not what SB3 writes.
    """
    limit = MODEL_SIZE_LIMIT if limit is None else limit
    try:
        with zipfile.ZipFile(path) as archive:
            check_declared_size(archive, "it", limit)
            names = archive.namelist()
            try:
                data = json.loads(read_entry(archive, "data")) if "data" in names else {}
            except (json.JSONDecodeError, UnicodeDecodeError) as err:
                raise ValueError(f"its data entry is not JSON ({err})") from None
            # Every entry checked before any is read as tensors.
            pth = {name: read_entry(archive, name) for name in names if name.endswith(".pth")}
            for name, content in pth.items():
                _check_pth(content, f"its entry {name}", limit)
            params: dict[str, Any] = {}
            variables = None
            for name, content in pth.items():
                value = _load_pth(content, f"its entry {name}")
                # "tensors.pth" is the name SB3 before 0.9 gave "pytorch_variables.pth".
                if name in ("pytorch_variables.pth", "tensors.pth"):
                    variables = value
                else:
                    params[os.path.splitext(name)[0]] = value
    except (zipfile.BadZipFile, zlib.error, EOFError) as err:
        raise ValueError(f"{path} is not a zip file, or a damaged one ({err})") from None
    if not isinstance(data, dict):
        raise ValueError("its data entry is not a JSON object")
    return data, params, variables


def zip_statistics(path: Path) -> tuple[bool, NormStats | None]:
    """What a model zip records of its normalisation: whether it records it at all (a zip
    written before the statistics went into it, or by another tool, does not), and the
    statistics (None: the model was trained without them).

    Raises:
        ValueError: the record is damaged or the statistics make no sense
            (:meth:`NormStats.check`); the message says what of "its entry", for the caller to
            name the zip.
    """
    where = f"its entry {ZIP_RECORD}"  # the caller names the zip
    try:
        with zipfile.ZipFile(path) as archive:
            if ZIP_RECORD not in archive.namelist():
                return False, None
            if archive.getinfo(ZIP_RECORD).file_size > 2**20:
                raise ValueError(f"{where} is too large to be a normalisation record")
            record = json.loads(read_entry(archive, ZIP_RECORD))
    except (zipfile.BadZipFile, zlib.error, EOFError) as err:
        raise ValueError(f"it is not a zip file, or a damaged one ({err})") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{where} is not valid JSON ({err})") from None
    if (
        not isinstance(record, dict)
        or record.get("format") != ZIP_RECORD_FORMAT
        or "vecnormalize" not in record
    ):
        raise ValueError(f"{where} is not a record of format {ZIP_RECORD_FORMAT}")
    stats = record["vecnormalize"]
    return True, None if stats is None else NormStats.from_dict(stats, where)


def _rewritten(content: bytes, extra: dict[str, bytes] | None = None) -> bytes:
    """A model zip ``content`` without the pickled fields of its ``data`` entry, and with the
    entries ``extra`` (in place of any of their names)."""
    extra = extra or {}
    out_buffer = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(content)) as archive:
        with zipfile.ZipFile(out_buffer, "w", compression=zipfile.ZIP_DEFLATED) as out:
            for info in archive.infolist():
                if info.filename in extra:
                    continue
                entry = read_entry(archive, info)
                if info.filename == "data":
                    data = json.loads(entry)
                    for value in data.values():
                        if isinstance(value, dict):
                            value.pop(SERIALIZED, None)
                    entry = json.dumps(data, indent=4).encode()
                out.writestr(info, entry)
            for name, entry in extra.items():
                out.writestr(name, entry)
    return out_buffer.getvalue()


def strip_pickles(path: Path) -> None:
    """Rewrite a model zip without the pickled fields of its ``data`` entry, atomically."""
    path = Path(path)
    write_bytes(path, _rewritten(path.read_bytes()))


def save_model(model: Any, path: Path) -> None:
    """Save the model with its VecNormalize statistics in one file, in one step.

    The zip holds no pickle: it loses the pickled fields SB3 writes into it (nothing here
    reads them back), and the statistics are its entry :data:`ZIP_RECORD`, as numbers. A
    ``vecnormalize.json`` beside it from before is removed: the zip's own record is read.
    """
    path = Path(path)
    buffer = io.BytesIO()
    model.save(buffer)
    norm = model.get_vec_normalize_env()
    stats = None if norm is None else NormStats.of(norm).to_dict()
    record = json.dumps({"format": ZIP_RECORD_FORMAT, "vecnormalize": stats}).encode()
    write_bytes(path, _rewritten(buffer.getvalue(), {ZIP_RECORD: record}))
    for stale in statistics_beside(path):
        stale.unlink(missing_ok=True)


def statistics_beside(path: Path) -> list[Path]:
    """Where a model zip from before kept its statistics: ``<name>_vecnormalize.json`` (a
    checkpoint's), and for a ``model.zip`` also ``vecnormalize.json``."""
    path = Path(path)
    beside = [path.with_name(f"{path.stem}_{NORM_FILE}")]
    return beside + ([path.with_name(NORM_FILE)] if path.name == MODEL_FILE else [])
