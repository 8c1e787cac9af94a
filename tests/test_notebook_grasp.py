"""notebooks/06_grasp_model.ipynb runs headless on the shipped model and shows the key outputs."""

from __future__ import annotations


import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("torch")

from notebook_utils import execute  # noqa: E402

from ohra.learn.grasp.model import default_model_dir  # noqa: E402

# ~10-60 s each: outside the default suite; .ci/run runs them after it (pytest -m "e2e and not slow")
pytestmark = pytest.mark.e2e


def test_grasp_model_notebook_executes(tmp_path):
    if not (default_model_dir() / "model.pt").is_file():
        pytest.skip("shipped grasp model not present")
    nb, texts = execute("06_grasp_model.ipynb", tmp_path, timeout=600)
    assert "hands: allegro_hand_left, barrett_hand, shadow_hand_right" in texts[0]
    assert "unified model of the grasp-model study" in texts[0]
    assert texts[1].count("(100, 31)") == 5 and texts[1].count("same seed same grasps: True") == 5
    assert texts[2].count("succeeded") == 3
    assert "<png>" in texts[3]
    assert (tmp_path / "grasp_sheet.png").is_file() and (tmp_path / "grasp_scene.html").is_file()
    # from a checkout the study's committed tables are shown: one line per hand, then the sheet
    assert texts[5].count("hand-specific") == 3 and "<png>" in texts[5]
    # ... and where the model loses success (stop 44): the three measurements' tables
    code = [c for c in nb.cells if c.cell_type == "code"]
    shown = "\n".join(o.get("data", {}).get("text/markdown", "") for o in code[6].outputs)
    assert "unified-24000" in shown and "seen (training objects)" in shown and "stored rotations" in shown and "best of 8" in shown
    assert "palm position error" in shown
    # ... and fingers on the surface (stop 45): touch brings the fingers to the surface; both tables shown
    lines = "".join(o.get("text", "") for o in code[7].outputs).splitlines()
    pct = {ln.split()[0]: [int(w.rstrip("%,")) for w in ln.split() if w.rstrip(",").endswith("%")] for ln in lines if "%" in ln}
    assert pct["touch"][1] >= 80 and pct["touch"][1] > pct["opened"][1] > pct["sampled"][1] - 1  # touching share
    assert pct["touch"][0] == 0 == pct["opened"][0] and pct["sampled"][0] > 0  # nothing sunk after either
    shown = "\n".join(o.get("data", {}).get("text/markdown", "") for o in code[7].outputs)
    assert "penetration weight" in shown and "hovering ones closed" in shown
    # ... and left twins through their mirror images (stop 48): the left Shadow holds more often as its mirror image
    text = "".join(o.get("text", "") for o in code[8].outputs if o.get("name") == "stdout")
    # sampled as it is, the left hand lies outside the training hands: the model says so (stderr)
    warned = "".join(o.get("text", "") for o in code[8].outputs if o.get("name") == "stderr")
    assert "'shadow_hand_left' lies outside the hands this grasp model trained on" in warned
    assert "shadow_hand_left   sampled as its mirror image: True" in text
    assert "shadow_hand_right  sampled as its mirror image: False" in text
    held = {ln.split("mirror=")[1][:5].strip(): int(ln.split(": ")[1].split("/")[0]) for ln in text.splitlines() if "mirror=" in ln}
    assert held["True"] > held["False"]
