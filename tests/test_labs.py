"""The teaching labs (docs/labs/*.ipynb) run from the first cell to the last.

The default run executes each with the small budgets its ``FOOSBALL_LAB_QUICK`` switch sets,
so a change that breaks a lab fails here; the slow set runs them with their full budgets
(each under 10 minutes on a 2-core laptop).
"""

from __future__ import annotations

from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")
pytest.importorskip("stable_baselines3")

LABS = sorted((Path(__file__).resolve().parent.parent / "docs" / "labs").glob("*.ipynb"))


def execute(path: Path, workdir: Path) -> nbformat.NotebookNode:
    notebook = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(
        notebook,
        timeout=900,
        kernel_name="python3",
        resources={"metadata": {"path": str(workdir)}},
    )
    client.execute()
    return notebook


def outputs(notebook: nbformat.NotebookNode, kind: str) -> list[dict]:
    return [
        out
        for cell in notebook.cells
        if cell.cell_type == "code"
        for out in cell.outputs
        if out.output_type == kind
    ]


def test_there_are_three_labs_each_with_a_quick_switch():
    assert len(LABS) >= 3, [p.name for p in LABS]
    for path in LABS:
        assert "FOOSBALL_LAB_QUICK" in path.read_text(), path.name


@pytest.mark.parametrize("path", LABS, ids=lambda p: p.stem)
def test_lab_runs_with_small_budgets(path, tmp_path, monkeypatch):
    monkeypatch.setenv("FOOSBALL_LAB_QUICK", "1")
    notebook = execute(path, tmp_path)
    # Every lab shows at least one figure; nbclient raises on any cell's error.
    assert outputs(notebook, "display_data"), f"{path.name} displayed nothing"
    assert not outputs(notebook, "error")


@pytest.mark.slow
@pytest.mark.parametrize("path", LABS, ids=lambda p: p.stem)
def test_lab_runs_with_its_full_budget(path, tmp_path, monkeypatch):
    monkeypatch.delenv("FOOSBALL_LAB_QUICK", raising=False)
    execute(path, tmp_path)
