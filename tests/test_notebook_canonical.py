"""notebooks/01_canonical_hand.ipynb runs headless and shows the key numbers."""

from __future__ import annotations


import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

from notebook_utils import execute  # noqa: E402

# ~10-60 s each: outside the default suite; .ci/run runs them after it (pytest -m "e2e and not slow")
pytestmark = pytest.mark.e2e


def test_canonical_hand_notebook_executes(hands_dir, tmp_path):
    nb, texts = execute("01_canonical_hand.ipynb", tmp_path, timeout=180, html_chars=200)
    assert "3 fingers, 12 DoF, right hand, 82 numbers" in texts[0]
    assert "index   tip at q=0: [0.    0.025 0.185]" in texts[1]
    assert "batch tips (1024, 5, 3) | index tip Jacobian (6, 22)" in texts[2]
    assert "<iframe" in texts[3] or "iframe" in texts[3].lower()
    assert "round trip exact: True" in texts[4]
