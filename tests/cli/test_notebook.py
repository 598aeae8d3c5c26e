"""examples/first_steps.ipynb runs top to bottom in a fresh kernel, and every cell shows something.

The notebook is stored without outputs; this test executes it with nbclient (the
runner Jupyter itself uses) against this checkout, so it cannot rot as the API moves.
"""

from __future__ import annotations

import os

import nbclient
import nbformat
import pytest

from tests.conftest import ROOT

NOTEBOOK = ROOT / "examples" / "first_steps.ipynb"


@pytest.fixture(scope="module")
def executed():
    # The kernel is a child process: it must import this tree's animsim, draw with the
    # inline backend (an inherited MPLBACKEND=Agg would swallow the figures), and keep
    # numba quiet about caching in a read-only checkout.
    saved = dict(os.environ)
    os.environ["PYTHONPATH"] = str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")
    os.environ.pop("MPLBACKEND", None)
    try:
        nb = nbformat.read(NOTEBOOK, as_version=4)
        client = nbclient.NotebookClient(
            nb,
            timeout=600,
            kernel_name="python3",
            resources={"metadata": {"path": str(NOTEBOOK.parent)}},
        )
        client.execute()  # raises CellExecutionError, naming the cell, on the first error
    finally:
        os.environ.clear()
        os.environ.update(saved)
    return nb


def _code_cells(nb):
    return [c for c in nb.cells if c.cell_type == "code"]


def test_the_notebook_is_stored_without_outputs():
    nb = nbformat.read(NOTEBOOK, as_version=4)
    nbformat.validate(nb)
    assert all(not c.outputs and c.execution_count is None for c in _code_cells(nb))


@pytest.mark.slow
def test_every_cell_runs_and_shows_something(executed):
    for cell in _code_cells(executed):
        assert cell.outputs, f"cell {cell.id} showed nothing:\n{cell.source}"
        assert not [o for o in cell.outputs if o.output_type == "error"], cell.id
        assert not [o for o in cell.outputs if o.get("name") == "stderr" and "Traceback" in o.text], cell.id


@pytest.mark.slow
def test_it_draws_plots_tables_and_an_animation(executed):
    outputs = [o for c in _code_cells(executed) for o in c.outputs]
    pictures = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(pictures) >= 3, "the path, the energies and the convergence plot"
    tables = [o for o in outputs if "<table" in o.get("data", {}).get("text/html", "")]
    assert len(tables) >= 2, "to_pandas() and the compare table render as tables"
    last = _code_cells(executed)[-1].outputs
    html = [o["data"]["text/html"] for o in last if "text/html" in o.get("data", {})]
    assert html and len(html[0]) > 1000, "a trajectory shows itself as an inline animation"


@pytest.mark.slow
def test_the_runs_in_it_are_ok_and_the_errors_located(executed):
    text = "".join(o.get("text", "") for c in _code_cells(executed) for o in c.outputs)
    assert "ok (251,) (251, 2, 3)\nids: anchor, bob\n" in text
    assert "positon" in text and "did you mean 'position'" in text
