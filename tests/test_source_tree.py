"""The reference's source tree is drawn from the code, so it names every package there is."""

from __future__ import annotations

from pathlib import Path

import pytest
from scripts_loader import load_script

ROOT = Path(__file__).resolve().parent.parent


def hooks():
    return load_script("docs_hooks")


def test_the_source_tree_names_every_package_with_its_docstring():
    docs_hooks = hooks()
    tree = docs_hooks.source_tree()
    packages = [p.parent for p in (ROOT / "foosball_gym").rglob("__init__.py")]
    assert len(packages) > 15
    for package in packages:
        assert f"{package.name}/" in tree, package
        assert docs_hooks.summary(package)[:30] in " ".join(tree.split()), package
    for folder in ("cli/", "urdf/", "builtin/", "configs/", "benchmarks/", "tests/"):
        assert folder in tree
    assert "paper-ppo" in tree and "train_throughput.py" in tree
    assert all(len(line) <= docs_hooks.TREE_WIDTH for line in tree.splitlines())


def test_a_package_without_a_docstring_is_refused(tmp_path):
    (tmp_path / "bare").mkdir()
    (tmp_path / "bare" / "__init__.py").write_text("x = 1\n")
    with pytest.raises(ValueError, match="has no docstring"):
        hooks().summary(tmp_path / "bare")


def test_the_reference_page_is_given_the_tree():
    page = type("Page", (), {"file": type("File", (), {"src_uri": "reference/training.md"})})
    markdown = (ROOT / "docs" / "reference" / "training.md").read_text()
    built = hooks().on_page_markdown(markdown, page)
    assert "<!-- the source tree -->" not in built and "  selfplay/" in built
