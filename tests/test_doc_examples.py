"""The Python examples of the README and the documentation run as written.

Each page's ```python blocks run in order as one script, in a fresh interpreter: a block that
leaves out an import it needs fails here as it would for a reader.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def examples(page: Path) -> str:
    return "\n".join(BLOCK.findall(page.read_text()))


WITH_EXAMPLES = [p for p in PAGES if examples(p)]


def test_the_pages_with_examples_are_found():
    names = {p.relative_to(ROOT).as_posix() for p in WITH_EXAMPLES}
    assert {"README.md", "docs/add-a-task.md", "docs/envs/index.md"} <= names, names


@pytest.mark.parametrize("page", WITH_EXAMPLES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_the_page_examples_run(page, tmp_path):
    script = examples(page)
    result = subprocess.run(
        [sys.executable, "-c", script],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr[-3000:]


def test_the_new_task_of_add_a_task_plays():
    # The page's own claims: the new environment's observation, and its scripted team blocks.
    script = examples(ROOT / "docs" / "add-a-task.md")
    result = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0, result.stderr[-3000:]
    assert "'home_keeper_slide_pos', 'home_defense_slide_pos'" in result.stdout
    blocked = int(re.search(r"blocked (\d+) of 20", result.stdout)[1])
    assert blocked >= 15, result.stdout


def test_the_any_shot_speeds_quoted_are_those_builtin_block_trains_on():
    config = json.loads((ROOT / "foosball_gym" / "builtin" / "block" / "config.json").read_text())
    low, high = config["env_kwargs"]["speed_range"]
    for page in ("README.md", "docs/envs/index.md"):
        row = next(
            line
            for line in (ROOT / page).read_text().splitlines()
            if line.startswith("| [`Foosball-Block-v0`]")
        )
        quoted = re.search(r"any shot\]\([^)]*\):[^|]*?(\d+)-(\d+) m/s", row)
        assert quoted, f"{page}: {row}"
        assert (float(quoted[1]), float(quoted[2])) == (low, high), f"{page}: {row}"
