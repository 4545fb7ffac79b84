"""MkDocs hooks (mkdocs.yml ``hooks:``): the shipped policies' pages are their REPRODUCE.md.

A page docs/results/shipped/NAME.md is shown as ``foosball_gym/builtin/NAME/REPRODUCE.md``, the
file that ships with the policy, so the site and the package say the same thing. Its commands
are one line each, as its run was started; on the page a line longer than ``WIDTH`` is split
before an option and continued with a backslash, the same command for a shell to run, and whole
beside the site's menu.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
WIDTH = 96
SHELL_BLOCK = re.compile(r"^```bash\n(.*?)^```", re.S | re.M)


def continued(line: str, width: int = WIDTH) -> str:
    """``line`` split before its options (`` --``) into lines of at most ``width`` characters
    where it can be, each but the last ending in `` \\``."""
    if len(line) <= width:
        return line
    first, *options = re.split(r" (?=--)", line)
    lines, current = [], first
    for option in options:
        if len(current) + len(option) + 3 > width:
            lines.append(current + " \\")
            current = "  " + option
        else:
            current += " " + option
    return "\n".join([*lines, current])


def reproduce_page(name: str) -> str:
    """The markdown of builtin:NAME's REPRODUCE.md, its long commands continued over lines."""
    text = (ROOT / "foosball_gym" / "builtin" / name / "REPRODUCE.md").read_text(encoding="utf-8")
    return SHELL_BLOCK.sub(
        lambda block: "```bash\n" + "\n".join(map(continued, block[1].splitlines())) + "\n```",
        text,
    )


def on_page_markdown(markdown: str, page: Any, **kwargs: Any) -> str:
    path = Path(page.file.src_uri)
    if path.parent.as_posix() == "results/shipped":
        return reproduce_page(path.stem)
    return markdown
