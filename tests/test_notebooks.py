"""Execute every notebook in notebooks/ (so they never rot): jupytext percent-format sources.

The first runs in a Jupyter kernel, so that path stays checked; the others run in the test
process, cell by cell, each notebook in a namespace of its own and with JAX's settings as a
new kernel has them. A kernel per notebook cost about 6 s of start-up and imports each, and
the operations the notebooks share were compiled again in every one.
"""

import os
from pathlib import Path

import jax
import pytest

jupytext = pytest.importorskip("jupytext", reason="notebook tests need the [test] extra (jupytext)")
nbclient = pytest.importorskip("nbclient", reason="notebook tests need the [test] extra (nbclient)")

NOTEBOOKS = sorted((Path(__file__).resolve().parent.parent / "notebooks").glob("[0-9][0-9]_*.py"))
IN_A_KERNEL, AS_SCRIPTS = NOTEBOOKS[:1], NOTEBOOKS[1:]


def test_notebooks_found():
    assert NOTEBOOKS, "no notebooks/NN_*.py found"


@pytest.mark.parametrize("path", IN_A_KERNEL, ids=[p.stem for p in IN_A_KERNEL])
def test_notebook_runs_in_a_kernel(path, monkeypatch):
    nb = jupytext.read(path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    monkeypatch.setenv("JAX_PLATFORMS", os.environ.get("JAX_PLATFORMS", "cpu"))
    client = nbclient.NotebookClient(
        nb, timeout=900, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}
    )
    client.execute()


@pytest.mark.filterwarnings("ignore:FigureCanvasAgg is non-interactive")  # plt.show()
@pytest.mark.parametrize("path", AS_SCRIPTS, ids=[p.stem for p in AS_SCRIPTS])
def test_notebook_runs(path, monkeypatch):
    """Its code cells in order, in the notebooks' folder, with the figures drawn by Agg
    (closed after) and JAX's default dtype promotion (the suite's is strict); the notebook
    switches float64 on itself, as the suite has."""
    import matplotlib
    import matplotlib.pyplot as plt

    monkeypatch.chdir(path.parent)
    namespace = {"__name__": "__main__"}
    backend = matplotlib.get_backend()
    plt.switch_backend("Agg")
    try:
        with matplotlib.rc_context(), jax.numpy_dtype_promotion("standard"):
            for number, cell in enumerate(jupytext.read(path).cells):
                if cell.cell_type == "code":
                    code = compile(cell.source, f"{path.name} (cell {number})", "exec")
                    exec(code, namespace)  # noqa: S102
    finally:
        plt.close("all")
        plt.switch_backend(backend)
