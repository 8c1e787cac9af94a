"""notebooks/03_morphology_vae.ipynb runs headless (small settings) and shows the key numbers."""

from __future__ import annotations


import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("torch")

from notebook_utils import execute  # noqa: E402

# ~10-60 s each: outside the default suite; .ci/run runs them after it (pytest -m "e2e and not slow")
pytestmark = pytest.mark.e2e


def test_morphology_notebook_executes(tmp_path):
    nb, texts = execute("03_morphology_vae.ipynb", tmp_path, timeout=300)
    assert "4096 hands, 82 numbers each" in texts[0] and "<png>" in texts[0]
    assert "epoch 3: total" in texts[1]
    assert "shipped model: latent" in texts[2] and "encoding rot6d70" in texts[2]
    assert "fingers: [3," in texts[3] and "<png>" in texts[3]
    assert "reference model, steps with a thumb pointing into the palm" in texts[4] and "<png>" in texts[4]
    assert "valid: True | plausible: True" in texts[5]
    assert (tmp_path / "interpolation.png").is_file() and (tmp_path / "small_run" / "model.pt").is_file()
