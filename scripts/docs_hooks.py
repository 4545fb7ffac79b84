"""MkDocs hooks (mkdocs.yml ``hooks:``): the shipped policies' pages are their REPRODUCE.md, and
the reference's source tree is drawn from the code.

A page docs/results/shipped/NAME.md is shown as ``foosball_gym/builtin/NAME/REPRODUCE.md``, the
file that ships with the policy, so the site and the package say the same thing. Its commands
are one line each, as its run was started; on the page a line longer than ``WIDTH`` is split
before an option and continued with a backslash, the same command for a shell to run, and whole
beside the site's menu.
"""

from __future__ import annotations

import ast
import re
import textwrap
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


SOURCE_TREE = "<!-- the source tree -->"
# The folders at the top that are not packages: what they hold is listed, not described.
PLAIN_FOLDERS = {
    "benchmarks": "scripts that print figures",
    "scripts": "scripts that make what the project ships",
    "docs": "this site (mkdocs.yml at the top); docs/labs/ the teaching labs, run by the tests",
    "tests": "one file per concern",
}
TREE_WIDTH = 100


def summary(package: Path) -> str:
    """The first sentence of ``package``'s docstring, roles and markup taken out."""
    doc = ast.get_docstring(ast.parse((package / "__init__.py").read_text(encoding="utf-8")))
    if not doc:
        raise ValueError(f"{package}/__init__.py has no docstring to describe it by")
    first = " ".join(doc.split("\n\n")[0].split())
    first = re.sub(r":\w+:`~?\.?([^`]+)`", r"\1", first).replace("``", "")
    return re.split(r"(?<=[a-z)])\. ", first)[0].rstrip(".")


def _entry(name: str, depth: int, text: str) -> list[str]:
    label = "  " * depth + name
    column = 22
    lines = textwrap.wrap(text, TREE_WIDTH - column, break_on_hyphens=False) or [""]
    head = label.ljust(column - 1) + " " + lines[0] if len(label) < column else label
    rest = [" " * column + line for line in (lines[1:] if len(label) < column else lines)]
    return [head, *rest]


def source_tree(root: Path = ROOT) -> str:
    """The repository's folders, each package told by its docstring's first sentence."""
    lines: list[str] = []
    for top in ("cli", "urdf"):
        lines += _entry(f"{top}/", 0, f"{summary(root / top)} (installed as foosball_gym.{top})")
    package = root / "foosball_gym"
    modules = sorted(p.name for p in package.glob("*.py") if p.name != "__init__.py")
    lines += _entry("foosball_gym/", 0, f"{summary(package)}; its modules {', '.join(modules)}")

    def walk(folder: Path, depth: int) -> None:
        for child in sorted(p for p in folder.iterdir() if p.is_dir()):
            if (child / "__init__.py").exists():
                lines.extend(_entry(f"{child.name}/", depth, summary(child)))
                walk(child, depth + 1)
            elif child.name == "builtin":
                names = sorted(p.parent.name for p in child.glob("*/REPRODUCE.md"))
                text = f"the shipped policies, loaded as builtin:NAME: {', '.join(names)}"
                lines.extend(_entry("builtin/", depth, text))
            elif child.name == "configs":
                names = sorted(p.stem for p in child.glob("*.yaml"))
                text = f"the shipped settings files, --config builtin:NAME: {', '.join(names)}"
                lines.extend(_entry("configs/", depth, text))

    walk(package, 1)
    for name, text in PLAIN_FOLDERS.items():
        scripts = sorted(p.name for p in (root / name).glob("*.py")) if name != "tests" else []
        lines += _entry(f"{name}/", 0, f"{text}: {', '.join(scripts)}" if scripts else text)
    return "\n".join(lines)


def on_page_markdown(markdown: str, page: Any, **kwargs: Any) -> str:
    path = Path(page.file.src_uri)
    if path.parent.as_posix() == "results/shipped":
        return reproduce_page(path.stem)
    if SOURCE_TREE in markdown:
        return markdown.replace(SOURCE_TREE, f"```text\n{source_tree()}\n```")
    return markdown
