"""notebooks/08_in_hand_rotation.ipynb runs headless and shows its key claims."""

from __future__ import annotations

from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("stable_baselines3", reason="notebook 08 needs the rl extra")

NB = Path(__file__).resolve().parents[1] / "notebooks" / "08_in_hand_rotation.ipynb"


def _text(cell) -> str:
    return "\n".join(o.get("text", "") + str(o.get("data", {}).get("text/plain", "")) for o in cell.get("outputs", []))


def test_rotation_notebook_executes(tmp_path, hands_dir):
    nb = nbformat.read(NB, as_version=4)
    nbclient.NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    texts = [_text(c) for c in nb.cells if c.cell_type == "code"]
    assert "LEAP canonical: actions 22 (6 ignored)" in texts[0] and "LEAP original : actions 16 (0 ignored)" in texts[0]
    assert "'steps_to_fall_mean': 400.0" in texts[2]  # zero actions hold the object
    assert "Steps-to-Fall" in texts[3] and "budget" in texts[3]
    assert "rad about +z" in texts[5]
