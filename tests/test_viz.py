"""Static meshcat exports open framed on their content: the camera maths, and (marked ``browser``)
the Shadow compare overlay rendered in headless Chromium and measured."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from ohra import HandModel
from ohra import viz

from conftest import BROWSER_MISSING, DATA

REPO = Path(__file__).resolve().parents[1]
SCREENSHOTS = REPO / "out" / "screenshots"  # copies for humans (git-ignored)
WINDOW = (1280, 800)
# Share of the central 60 % x 60 % of the window that the hands cover. Calibrated on the Shadow
# compare overlay (base form) at 1280 x 800 in Chromium 150: framed 0.23; meshcat's default camera
# (the export before framing) 0.007.
MIN_CENTRAL_COVER = 0.10


class _Recorder:
    """Stands in for a meshcat Visualizer: accepts the drawing calls, keeps nothing but the window."""

    def __init__(self, window=None):
        self.window = window if window is not None else type("Window", (), {})()

    def __getitem__(self, path):
        return _Recorder(self.window)

    def set_object(self, *args, **kw):
        pass

    def set_transform(self, *args, **kw):
        pass

    def delete(self):
        pass

    def static_html(self) -> str:
        return "<html><body><script>var viewer;</script></body></html>"


def _camera_coords(view: viz.CameraView, points: np.ndarray) -> np.ndarray:
    """(N, 3) points in a pinhole camera at view.position looking at view.target, world z up:
    (right, up, distance in front)."""
    forward = view.target - view.position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = points - view.position
    return np.stack([d @ right, d @ up, d @ forward], axis=1)


@pytest.mark.parametrize("lo, hi", [((-0.05, -0.35, -0.1), (0.1, 0.1, 0.25)), ((0.0, 0.0, 0.0), (0.02, 0.2, 0.01)),
                                    ((1.0, 2.0, 3.0), (1.5, 2.1, 3.05))])
def test_frame_bounds_fits_the_box_tightly_in_the_field_of_view(lo, hi):
    view = viz.frame_bounds(np.array(lo), np.array(hi))
    assert view.target == pytest.approx((np.array(lo) + np.array(hi)) / 2)
    cam = _camera_coords(view, viz._box_corners(np.array(lo), np.array(hi)))
    assert np.all(cam[:, 2] > 0.01)  # in front of meshcat's near plane
    slope = np.abs(cam[:, :2]).max(axis=1) / cam[:, 2]
    t = np.tan(np.radians(viz.FOV_DEG) / 2)
    distance = np.linalg.norm(view.position - view.target)
    if distance > np.max(np.subtract(hi, lo)) * (1 + 1e-9):
        assert slope.max() == pytest.approx(t / 1.1, rel=1e-9)  # the widest corner sits on the 10 % margin
    else:  # flat content: no closer than its own size
        assert slope.max() < t / 1.1


def test_static_html_frames_what_was_drawn():
    from ohra.canonical.params import load_params

    hand = HandModel.from_params(load_params(DATA / "shadow_hand_right_base.json"))
    vis = _Recorder()
    assert viz.static_html(vis) == vis.static_html()  # nothing drawn: meshcat's page as it is
    T = np.eye(4)
    T[:3, 3] = (0.3, -0.2, 0.1)
    q = hand.neutral()
    viz.add_hand(vis, hand, q, T)
    lo, hi = viz.scene_bounds(vis)
    caps = hand.capsules(q)
    ends = np.vstack([caps.p0, caps.p1]) + T[:3, 3]
    assert np.all(lo <= ends.min(axis=0)) and np.all(hi >= ends.max(axis=0))
    assert np.all(hi - lo < 0.4) and np.all(lo > T[:3, 3] - 0.2)  # the hand, not the world origin
    html = viz.static_html(vis)
    view = viz.frame_bounds(lo, hi)
    c = view.target
    assert f"viewer.controls.target.set({c[0]:.6g}, {c[2]:.6g}, {-c[1]:.6g})" in html  # three.js is y-up
    assert html.index("ohra: open framed") < html.rindex("</body>")
    # a caption says what the page shows, as text (escaped), over the view
    captioned = viz.static_html(vis, caption="left: q = 0 <rest>, right: q & random")
    assert "left: q = 0 &lt;rest&gt;, right: q &amp; random</div>" in captioned and "<rest>" not in captioned
    assert captioned.index("ohra-caption") < captioned.rindex("</body>")
    viz.clear_bounds(vis)
    assert viz.scene_bounds(vis) is None


# -- in a browser ----------------------------------------------------------------------------------
# Hides the drawn content (everything but meshcat's own Background, Lights, Grid, Axes and Cameras)
# once the page's asynchronous drawing commands have landed: the same view without the hands.
_HIDE_CONTENT = """<script>
setInterval(function () {
  for (const k of Object.keys(viewer.scene_tree.children)) {
    if (!["Background", "Lights", "Grid", "Axes", "Cameras"].includes(k)) viewer.set_property([k], "visible", false);
  }
  viewer.set_dirty();
}, 20);
</script>"""


@pytest.fixture
def chromium() -> str:
    exe = os.environ.get("OHRA_CHROMIUM") or next(
        (p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)
    if not exe:
        pytest.skip(f"{BROWSER_MISSING}: chromium not on PATH and OHRA_CHROMIUM not set")
    return exe


def _screenshot(exe: str, html: Path, png: Path) -> np.ndarray:
    from PIL import Image

    cmd = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", f"--user-data-dir={png.parent / 'profile'}",
           f"--window-size={WINDOW[0]},{WINDOW[1]}", "--virtual-time-budget=3000", f"--screenshot={png}", html.as_uri()]
    subprocess.run(cmd, capture_output=True, timeout=180, check=True)
    return np.asarray(Image.open(png).convert("RGB")).astype(int)


def _children() -> set[int]:
    """Live child processes of this test process (a meshcat server would be one)."""
    me, out = os.getpid(), set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == me and fields[0] != "Z":
            out.add(int(stat.parent.name))
    return out


@pytest.mark.browser
@pytest.mark.e2e  # renders two hands and opens them in Chromium (~16 s)
def test_compare_overlay_opens_framed_on_the_hands(hands_dir, chromium, tmp_path):
    before = _children()
    html = viz.compare_html("shadow_hand_right", "base", tmp_path / "overlay.html")
    assert _children() <= before  # the export's meshcat server is gone
    page = html.read_text()
    assert "ohra: open framed" in page and "viewer.connect(" not in page  # static: no server to reach
    assert "grey = original collision meshes, blue = canonical capsules; right: q = 0, left: a random" in page
    cut = page.rindex("</body>")
    (tmp_path / "background.html").write_text(page[:cut] + _HIDE_CONTENT + page[cut:])

    shot = _screenshot(chromium, html, tmp_path / "overlay.png")
    empty = _screenshot(chromium, tmp_path / "background.html", tmp_path / "background.png")
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    for name in ("overlay.png", "background.png"):
        shutil.copy(tmp_path / name, SCREENSHOTS / f"compare_shadow_hand_right_{name}")

    assert shot.shape[:2] == (WINDOW[1], WINDOW[0])
    hand = np.abs(shot - empty).max(axis=2) > 8  # pixels the hands change
    h, w = hand.shape
    cover = float(hand[h // 5:4 * h // 5, w // 5:4 * w // 5].mean())
    assert cover >= MIN_CENTRAL_COVER, f"hands cover {cover:.3f} of the central region (screenshot {tmp_path / 'overlay.png'})"
    rows, cols = np.flatnonzero(hand.any(axis=1)), np.flatnonzero(hand.any(axis=0))
    assert rows[0] > 0 and cols[0] > 0 and rows[-1] < h - 1 and cols[-1] < w - 1  # nothing cut off at the edges
    assert (rows[-1] - rows[0]) > 0.4 * h  # and tall enough to see


def test_a_new_visualizer_starts_without_printing_meshcats_url(capsys):
    """Commands that only export static HTML must not tell the user to visit a server that stops with them."""
    vis = viz.new_visualizer()
    try:
        assert vis.url().startswith("http://127.0.0.1:")
    finally:
        del vis
    assert capsys.readouterr().out == ""
