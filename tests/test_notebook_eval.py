"""notebooks/04_grasp_evaluation.ipynb runs headless and shows its key claims."""

from __future__ import annotations


import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

from notebook_utils import execute  # noqa: E402

# ~10-60 s each: outside the default suite; .ci/run runs them after it (pytest -m "e2e and not slow")
pytestmark = pytest.mark.e2e


def test_grasp_evaluation_notebook_executes(tmp_path):
    nb, texts = execute("04_grasp_evaluation.ipynb", tmp_path, timeout=180)
    assert "sphere: volume" in texts[0] and "l_block" in texts[0]
    assert "friction 3.0" in texts[1] and "strict: friction 1.0" in texts[1]
    assert "success rate" in texts[2] and "inf" not in texts[2]
    assert "early exit changes no outcome: True" in texts[3]
    assert "reversed order, same results: True" in texts[3]
    assert "sheet (" in texts[5]
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert any("image/png" in o.get("data", {}) for o in code[5].outputs)  # the contact sheet is shown
