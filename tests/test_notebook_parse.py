"""notebooks/02_parse_and_compare.ipynb runs headless and shows the key numbers."""

from __future__ import annotations


import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

from notebook_utils import execute  # noqa: E402

# ~10-60 s each: outside the default suite; .ci/run runs them after it (pytest -m "e2e and not slow")
pytestmark = pytest.mark.e2e


def test_parse_notebook_executes(hands_dir, tmp_path):
    nb, texts = execute("02_parse_and_compare.ipynb", tmp_path, timeout=300)
    assert "shadow_hand/shadow_hand_right.urdf" in texts[0]
    assert "reproduces committed params: True" in texts[1]
    assert "mean fingertip error below 2 mm: True" in texts[2]
    assert "missing-mesh warnings" in texts[3] and "palm radius" in texts[3]
    assert "static HTML" in texts[4]
    assert (tmp_path / "shadow_overlay.html").is_file()
    # the coupled Inspire hand: mimic joints mapped, couplings read, targets met at the true fingertip
    assert "index_joint3 <- index_intermediate_joint" in texts[5] and "index_joint3 = 1.06399 * index_joint2" in texts[5]
    assert "inspire extended" in texts[6] and "inspire base" in texts[6] and "target met: False" not in texts[6]
    assert texts[6].count("target met: True") == 2
    assert "projected back: True" in texts[7]
    assert "static HTML" in texts[8] and (tmp_path / "inspire_overlay.html").is_file()
