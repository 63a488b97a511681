"""Notebooks run top to bottom in a real Jupyter kernel (nbclient) with their small settings, and
every cell tagged ``figure`` must display an image (a figure that is drawn but never reaches the
notebook, e.g. a bare ``Figure`` followed by ``plt.show()``, fails here)."""

import os
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
# The first-hour notebook runs in the default suite; the two longer ones (about 40 s and 90 s
# on 2 cores) run with ``pytest -m slow`` to keep the default suite under 10 minutes.
DEFAULT = "getting_started.ipynb"
RUNS = [pytest.param(p, id=p.name, marks=() if p.name == DEFAULT else pytest.mark.slow) for p in NOTEBOOKS]


def figure_cells(nb):
    return [c for c in nb.cells if c.cell_type == "code" and "figure" in c.get("metadata", {}).get("tags", [])]


def images(cell) -> int:
    return sum("image/png" in o.get("data", {}) for o in cell.get("outputs", []))


def execute(path: Path, workdir: Path, monkeypatch):
    # The kernel is a fresh process: make this checkout importable even when not installed (it
    # inherits the suite's XLA flags and compilation-cache folder through the environment).
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    nb = nbformat.read(path, as_version=4)
    # The suite's compiled programs are shared with the kernel through the persistent cache (the
    # folder comes from SOCBJAX_CACHE_DIR, set by conftest); the cell is not part of the notebook.
    nb.cells.insert(0, nbformat.v4.new_code_cell("import socbjax\nsocbjax.enable_compilation_cache()"))
    client = NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(workdir)}})
    client.execute()  # raises CellExecutionError with the failing cell's traceback
    return nb


def test_every_notebook_has_tagged_figures():
    for path in NOTEBOOKS:
        assert figure_cells(nbformat.read(path, as_version=4)), f"{path.name}: no cell tagged 'figure'"


def test_the_default_notebook_exists():
    assert DEFAULT in [p.name for p in NOTEBOOKS]


@pytest.mark.parametrize("path", RUNS)
def test_notebook_runs_and_shows_its_figures(path, tmp_path, monkeypatch):
    nb = execute(path, tmp_path, monkeypatch)
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.get("output_type") == "error"]
    assert not errors
    missing = [c.source.splitlines()[0] for c in figure_cells(nb) if images(c) == 0]
    assert figure_cells(nb)
    assert not missing, f"{path.name}: figure cells without an image: {missing}"
