"""The install commands of the README, the docs, CI and tox take PyTorch's CPU build.

PyPI's torch for Linux is the CUDA build, 2.7 GB with its nvidia-* and triton packages; every
command that installs torch takes it from PyTorch's CPU-only index, in a form that still
works, within seconds, where that index cannot be reached (docs/getting-started.md).
"""

from __future__ import annotations

import configparser
import re
from pathlib import Path

import pytest
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parent.parent
CPU_INDEX = "--extra-index-url https://download.pytorch.org/whl/cpu"
QUICK_FAILURE = "--retries 0 --timeout 5"
# A command, not a mention in the text: at a line's start, after "&&", or after "with: ".
TORCH_PIN = re.compile(r"(?:^\s*|&& |: )(?:python -m )?pip install [^\n]*?torch==", re.M)
# The pages and scripts a user or CI installs from.
SOURCES = [
    "README.md",
    ".ci/run",
    "foosball_gym/training/__init__.py",
    *sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").rglob("*.md")),
]


def commands(text: str) -> str:
    """``text`` with shell continuations (and the string joins of a Python message) undone."""
    text = re.sub(r"\s*\\\n\s*", " ", text)
    return re.sub(r'["\']\n\s*["\']', "", text)


def torch_installs() -> dict[str, list[str]]:
    found: dict[str, list[str]] = {}
    for name in SOURCES:
        for line in commands((ROOT / name).read_text()).splitlines():
            if TORCH_PIN.search(line):
                found.setdefault(name, []).append(line.strip())
    return found


def test_every_command_that_installs_torch_takes_the_cpu_index():
    found = torch_installs()
    assert {"README.md", "docs/getting-started.md", ".ci/run", "docs/labs/index.md"} <= set(
        found
    ), found
    for name, lines in found.items():
        for line in lines:
            assert CPU_INDEX in line, f"{name}: {line}"
            assert QUICK_FAILURE in line or name.endswith(".py"), f"{name}: {line}"


def test_both_readme_blocks_install_torch_from_the_cpu_index():
    readme = commands((ROOT / "README.md").read_text())
    for heading in ("## Set up and train a keeper", "## Run the tests"):
        block = readme.split(heading, 1)[1].split("```bash\n", 1)[1].split("```", 1)[0]
        assert f"pip install torch==2.13.0 {CPU_INDEX} {QUICK_FAILURE}" in block, block


def test_tox_installs_torch_from_the_cpu_index_and_gives_up_quickly():
    tox = configparser.ConfigParser()
    tox.read(ROOT / "tox.ini")
    deps = tox["testenv"]["deps"].split("\n")
    assert CPU_INDEX in deps and "torch==2.13.0" in deps, deps
    env = dict(
        (part.strip() for part in line.split("=", 1))
        for line in tox["testenv"]["set_env"].strip().split("\n")
    )
    assert env == {"PIP_RETRIES": "0", "PIP_DEFAULT_TIMEOUT": "5"}, env


@pytest.mark.parametrize("source", ["README.md", "tox.ini"])
def test_the_pinned_torch_meets_the_train_extra(source):
    setup = configparser.ConfigParser()
    setup.read(ROOT / "setup.cfg")
    train = setup["options.extras_require"]["train"].split("\n")
    wanted = next(Requirement(r) for r in train if r.startswith("torch"))
    pin = re.search(r"torch==(\d[\w.]*)", (ROOT / source).read_text())
    assert pin and wanted.specifier.contains(pin[1]), (wanted, pin)


def test_the_pages_and_the_messages_install_foosball_gym_from_its_clone():
    # foosball_gym is not on PyPI: "pip install foosball_gym[...]" finds nothing there.
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    pages += [*sorted((ROOT / "foosball_gym").rglob("*.py")), *sorted((ROOT / "cli").rglob("*.py"))]
    from_index = re.compile(r"pip install [\"']?foosball_gym")
    offending = [p.relative_to(ROOT).as_posix() for p in pages if from_index.search(p.read_text())]
    assert not offending, offending


def test_the_docs_extra_brings_what_formats_the_signatures():
    # mkdocstrings sets each signature apart and formats it with Ruff or Black where one is
    # installed; with neither, an environment's signature is one line cut at the page's edge.
    setup = configparser.ConfigParser()
    setup.read(ROOT / "setup.cfg")
    docs = [Requirement(r).name for r in setup["options.extras_require"]["docs"].split("\n") if r]
    assert {"ruff", "black"} & set(docs), docs
    options = (ROOT / "mkdocs.yml").read_text()
    assert "separate_signature: true" in options
    assert re.search(r"^\s+line_length: \d+$", options, re.M)
