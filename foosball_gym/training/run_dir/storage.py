"""Reading and writing a run's model files without unpickling anything.

Python's pickle runs whatever code a file asks it to, so a model file from elsewhere could do
anything on load. Runs are therefore written as plain data only:

- the normalisation statistics as JSON numbers (:class:`NormStats`), not VecNormalize's
  pickle;
- the model as Stable-Baselines3's zip with the pickled (``":serialized:"``) fields of its
  ``data`` entry removed (:func:`strip_pickles`); the weights stay in its ``.pth`` entries,
  which are read with ``torch.load(weights_only=True)`` (:func:`read_model_zip`).

Files from before, ``vecnormalize.pkl`` and self-play snapshots holding a pickled policy, are
read only when the caller says it trusts them (``trust=True``, ``--trust-model``);
``foosball migrate RUN --trust-model`` converts a run once (:mod:`.migrate`).
"""

from __future__ import annotations

import json
import math
import pickle
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from foosball_gym.training.run_dir.files import LEGACY_NORM_FILE, atomic_write_text

NORM_FORMAT = 1
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

    def save(self, path: Path) -> None:
        atomic_write_text(Path(path), json.dumps({"format": NORM_FORMAT, **asdict(self)}))

    @classmethod
    def load(cls, path: Path) -> NormStats:
        """Read statistics :meth:`save` wrote; ValueError naming what is wrong otherwise."""
        try:
            data = json.loads(Path(path).read_text())
        except json.JSONDecodeError as err:
            raise ValueError(f"{path} is not valid JSON: {err}") from None
        if not isinstance(data, dict) or data.get("format") != NORM_FORMAT:
            raise ValueError(f"{path} is not a normalisation file of format {NORM_FORMAT}")
        try:
            stats = cls(**{k: v for k, v in data.items() if k != "format"})
        except TypeError as err:
            raise ValueError(f"{path}: {err}") from None
        numbers = [*stats.obs_mean, *stats.obs_var, stats.obs_count, stats.clip_obs]
        if not stats.obs_mean or len(stats.obs_mean) != len(stats.obs_var):
            raise ValueError(f"{path}: obs_mean and obs_var must be lists of the same length")
        if not all(isinstance(v, int | float) and math.isfinite(v) for v in numbers):
            raise ValueError(f"{path}: the statistics must be finite numbers")
        return stats


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


def read_model_zip(path: Path) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any] | None]:
    """A Stable-Baselines3 model zip's plain fields, its state dicts and its PyTorch variables.

    ``data``'s pickled fields are not evaluated (they are left as their description), and the
    ``.pth`` entries are read with ``weights_only=True``, which refuses anything but tensors
    and plain containers.

    Raises:
        ValueError: not a zip, or an entry is not what SB3 writes.
    """
    from stable_baselines3.common.save_util import load_from_zip_file

    try:
        with zipfile.ZipFile(path) as archive:
            data = json.loads(archive.read("data")) if "data" in archive.namelist() else {}
    except zipfile.BadZipFile:
        raise ValueError(f"{path} is not a zip file") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"its data entry is not JSON ({err})") from None
    try:
        _, params, variables = load_from_zip_file(path, load_data=False, device="cpu")
    except pickle.UnpicklingError as err:
        first = str(err).strip().splitlines()[0]
        raise ValueError(
            f"an entry holds more than weights, so it was not read ({first})"
        ) from None
    if not isinstance(data, dict):
        raise ValueError("its data entry is not a JSON object")
    return data, params, variables


def strip_pickles(path: Path) -> None:
    """Rewrite a model zip without the pickled fields of its ``data`` entry, atomically."""
    path = Path(path)
    with zipfile.ZipFile(path) as archive:
        entries = [(info, archive.read(info)) for info in archive.infolist()]
    tmp = path.with_name(path.name + ".strip.tmp")
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as out:
        for info, content in entries:
            if info.filename == "data":
                data = json.loads(content)
                for value in data.values():
                    if isinstance(value, dict):
                        value.pop(SERIALIZED, None)
                content = json.dumps(data, indent=4).encode()
            out.writestr(info, content)
    tmp.replace(path)


def save_model(model: Any, path: Path, norm_path: Path) -> None:
    """Save the model (and its VecNormalize statistics) through a temporary file each.

    Neither holds a pickle: the zip loses the pickled fields SB3 writes into it (nothing here
    reads them back) and the statistics are written as numbers.
    """
    tmp = path.with_name(path.stem + ".tmp.zip")
    model.save(tmp)
    strip_pickles(tmp)
    tmp.replace(path)
    norm = model.get_vec_normalize_env()
    if norm is not None:
        NormStats.of(norm).save(norm_path)
