"""The notebooks in ``notebooks/`` run top to bottom, small, on the project's interpreter.

Each notebook is executed with :mod:`nbclient` in a fresh temporary working directory (what
it writes, e.g. ``results/``, goes there), with ``MYOEXO_NB_SIZE=1`` (their size knob) and
``MUJOCO_GL=egl`` (headless rendering). A first cell is injected that checks the kernel runs
the interpreter of this test session (the project's ``.venv``), not some other Python that
happens to be registered as ``python3``. The committed files must have their outputs cleared.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

NOTEBOOK_DIR = Path(__file__).resolve().parent.parent / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
EXPECTED = (
    "01_digital_twin.ipynb",
    "02_spasticity.ipynb",
    "03_training.ipynb",
    "04_reproduce_paper.ipynb",
    "05_personal_twin.ipynb",
)
#: Size knob of the notebooks in CI (subjects per level, training steps / 1000, ...).
CI_SIZE = "1"
#: Per-notebook execution limit (s): each takes well under a minute at CI size on 2 cores;
#: the margin covers a loaded machine.
TIMEOUT_S = {"03_training.ipynb": 600}
DEFAULT_TIMEOUT_S = 300

_INTERPRETER_CHECK = f"""
import sys
assert sys.prefix == {sys.prefix!r}, (
    f"the notebook kernel runs {{sys.executable}} (prefix {{sys.prefix}}), "
    "not the interpreter of the test session ({sys.executable})"
)
"""


def test_all_notebooks_present() -> None:
    """The five notebooks exist (a rename would silently drop one from CI)."""
    names = {p.name for p in NOTEBOOKS}
    assert set(EXPECTED) <= names, f"missing notebooks: {sorted(set(EXPECTED) - names)}"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_outputs_cleared(path: Path) -> None:
    """Committed notebooks carry no outputs or execution counts (clean diffs)."""
    nb = nbformat.read(path, as_version=4)
    dirty = [
        i
        for i, cell in enumerate(nb.cells)
        if cell.cell_type == "code" and (cell.get("outputs") or cell.get("execution_count"))
    ]
    assert not dirty, (
        f"{path.name}: cells {dirty} have outputs; run "
        f"`jupyter nbconvert --clear-output --inplace {path}`"
    )


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs(path: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Execute every cell; any exception in a cell fails the test with the cell's traceback."""
    monkeypatch.setenv("MYOEXO_NB_SIZE", CI_SIZE)
    monkeypatch.setenv("MUJOCO_GL", "egl")
    nb = nbformat.read(path, as_version=4)
    nb.cells.insert(0, nbformat.v4.new_code_cell(_INTERPRETER_CHECK))
    client = nbclient.NotebookClient(
        nb,
        timeout=TIMEOUT_S.get(path.name, DEFAULT_TIMEOUT_S),
        kernel_name="python3",
        resources={"metadata": {"path": str(tmp_path)}},
    )
    client.execute()
    errors = [
        out
        for cell in nb.cells
        if cell.cell_type == "code"
        for out in cell.get("outputs", [])
        if out.get("output_type") == "error"
    ]
    assert not errors, f"{path.name}: {[(e['ename'], e['evalue']) for e in errors]}"
    # Every notebook shows at least one figure or image: a silently empty notebook fails.
    images = [
        out
        for cell in nb.cells
        if cell.cell_type == "code"
        for out in cell.get("outputs", [])
        if "image/png" in out.get("data", {})
    ]
    assert images, f"{path.name} displayed no image"
