"""Pictures of hand sequences: the PNG strip (originals beside the ends, palm outline, finger bases)
and the meshcat scene, checked in a real (headless) browser when one is installed."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from ohra.learn.sampler import sample_params
from ohra.learn.strip import _finger_bases, sequence_html, strip_png


def _png_size(path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def test_strip_has_a_column_per_hand_plus_the_originals_and_a_row_per_view(tmp_path):
    hands = sample_params(3, 4)
    a = strip_png(hands, tmp_path / "a.png", panel_size=1.0, dpi=50)
    b = strip_png(hands, tmp_path / "b.png", panel_size=1.0, dpi=50, originals=[("a", hands[0]), ("b", hands[2])])
    c = strip_png(hands, tmp_path / "c.png", panel_size=1.0, dpi=50, views=[(25.0, 15.0)])
    (wa, ha), (wb, hb), (wc, hc) = _png_size(a), _png_size(b), _png_size(c)
    assert wb / wa == pytest.approx(5 / 3, rel=0.02) and hb == ha
    assert hc / ha == pytest.approx(0.5, rel=0.05) and wc == wa


def test_finger_bases_are_the_present_fingers_bases():
    p = sample_params(1, 9)[0]
    bases = _finger_bases(p)
    assert [f for f, _ in bases] == list(np.flatnonzero(p.present_fingers))
    for f, b in bases:
        assert np.array_equal(b, p.finger_xyz[f])


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


def _screenshot(html, png) -> np.ndarray:
    import matplotlib.image

    cmd = [_chromium(), "--headless", "--no-sandbox", "--use-gl=swiftshader", "--enable-unsafe-swiftshader",
           "--window-size=900,500", "--virtual-time-budget=10000", f"--screenshot={png}", f"file://{html}"]
    subprocess.run(cmd, capture_output=True, timeout=120, check=True)
    return matplotlib.image.imread(str(png))[..., :3]


@pytest.mark.slow
@pytest.mark.skipif(_chromium() is None, reason="no chromium / chrome on this machine for the browser check")
def test_the_sequence_scene_renders_in_a_browser_framed_on_the_hands(tmp_path):
    hands = sample_params(4, 2)
    sequence_html(hands, tmp_path / "scene.html", originals=(hands[0], hands[-1]))
    shot = _screenshot(tmp_path / "scene.html", tmp_path / "scene.png")
    # meshcat's background is a vertical gradient: constant along each row, so a pixel far from its
    # row's median colour belongs to an object
    changed = np.abs(shot - np.median(shot, axis=1, keepdims=True)).max(axis=-1) > 0.08
    changed[:40] = False  # the "Open Controls" bar
    # the hands cover a sizeable share of the view (the default, metre-scale camera leaves ~1 %)
    assert changed.mean() > 0.05
    cols = np.flatnonzero(changed.any(0))
    assert cols.max() - cols.min() > 0.5 * changed.shape[1]  # the row of hands spans the view
