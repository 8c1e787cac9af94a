"""Pictures of hand sequences: a matplotlib PNG strip and a meshcat HTML scene.

The PNG draws each hand's capsules and palm (from :class:`ohra.HandModel`) in orthographic views
(default: from the palm side, +x, turned by ``azimuth`` about the finger axis and tilted by
``elevation``; and from the thumb side), painter's order (far parts first), with the palm outline
and the finger bases marked on top. No OpenGL is needed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from ohra.canonical.kinematics import HandModel
from ohra.canonical.params import BaseParams, ExtendedParams

PALM_COLOR = "#9fb7c9"
FINGER_COLORS = ("#d9534f", "#5b9bd5", "#70ad47", "#ffc000", "#8064a2")  # thumb, index, middle, ring, little


def _view(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """3x3 rows: screen-right, screen-up, towards-viewer, for a camera on +x looking at the palm."""
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    # base camera: viewer on +x, right = +y, up = +z; rotate about z by azimuth, then tilt by elevation
    Rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    Ry = np.array([[np.cos(e), 0, -np.sin(e)], [0, 1, 0], [np.sin(e), 0, np.cos(e)]])
    toward = Rz @ Ry @ np.array([1.0, 0.0, 0.0])
    up0 = np.array([0.0, 0.0, 1.0])
    right = np.cross(up0, toward)
    right /= np.linalg.norm(right)
    up = np.cross(toward, right)
    return np.stack([right, up, toward])


def _circle(c: np.ndarray, r: float, k: int = 24) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)
    return c + r * np.stack([np.cos(t), np.sin(t)], axis=1)


def _hull(points: np.ndarray) -> np.ndarray:
    from scipy.spatial import ConvexHull

    return points[ConvexHull(points).vertices]


def draw_hand(ax, params: BaseParams | ExtendedParams, q: np.ndarray | None = None, azimuth: float = 25.0,
              elevation: float = 15.0, title: str | None = None, faded: bool = False, half: float | None = None) -> float:
    """Draw one canonical hand into a matplotlib axes (metres, equal aspect); returns the half-width
    of the view it chose (pass ``half`` to use a common scale across panels).

    On top of the shapes: the palm's outline (dashed, so it shows through the fingers) and each
    finger's base (a dot in the finger's colour), so a base inside the palm is easy to see.
    ``faded`` draws the hand pale (the original hands beside a decoded sequence).
    """
    from matplotlib.patches import Polygon

    hm = HandModel.from_params(params)
    q = np.zeros(22) if q is None else np.asarray(q, dtype=float)
    V = _view(azimuth, elevation)
    shapes = []  # (depth, polygon (K,2), colour)
    palm = hm.palm
    R, depth = palm["radius"], palm["depth"]
    t = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    rim = np.stack([np.zeros_like(t), R * np.cos(t), R + R * np.sin(t)], axis=1)
    pts = np.concatenate([rim + [depth / 2, 0, 0], rim - [depth / 2, 0, 0]]) @ V.T
    shapes.append((float(pts[:, 2].mean()), _hull(pts[:, :2]), PALM_COLOR))
    caps = hm.capsules(q)
    for k in range(len(caps.link)):
        a, b = caps.p0[k] @ V.T, caps.p1[k] @ V.T
        r = float(caps.radius[k])
        poly = _hull(np.concatenate([_circle(a[:2], r), _circle(b[:2], r)]))
        shapes.append((float(max(a[2], b[2])), poly, FINGER_COLORS[int(caps.finger[k])]))
    alpha = 0.35 if faded else 0.95
    allpts = [np.zeros((1, 2))]
    for _, poly, color in sorted(shapes, key=lambda s: s[0]):
        ax.add_patch(Polygon(poly, closed=True, facecolor=color, edgecolor="#333333", linewidth=0.6, alpha=alpha))
        allpts.append(poly)
    front = (rim + [depth / 2, 0, 0]) @ V.T
    ax.add_patch(Polygon(front[:, :2], closed=True, fill=False, edgecolor="#1f3b57", linewidth=1.2, linestyle="--", zorder=5))
    bases = _finger_bases(params)
    for fi, b in bases:
        p = b @ V.T
        ax.plot(p[0], p[1], "o", markersize=4.5, markerfacecolor=FINGER_COLORS[fi], markeredgecolor="black",
                markeredgewidth=0.8, zorder=6, alpha=1.0 if not faded else 0.6)
    P = np.concatenate(allpts)
    lo, hi = P.min(axis=0), P.max(axis=0)
    c = (lo + hi) / 2
    half = max(hi - lo) / 2 + 0.01 if half is None else half
    ax.set_xlim(c[0] - half, c[0] + half)
    ax.set_ylim(c[1] - half, c[1] + half)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=8)
    return half


def _finger_bases(params: BaseParams | ExtendedParams) -> list[tuple[int, np.ndarray]]:
    """(finger index, base position in the palm frame) of every present finger."""
    out = []
    if isinstance(params, BaseParams):
        xyz = params.finger_xyz
    else:
        o = params.joint_origins  # rows as in ExtendedParams.to_base: thumb j1, index/middle j1, ring j1, little j1
        xyz = o[[0, 3, 5, 7, 10], :3]
    for fi in np.flatnonzero(params.present_fingers):
        out.append((int(fi), np.asarray(xyz[fi], dtype=float)))
    return out


VIEWS = ((25.0, 15.0), (95.0, 10.0))  # (azimuth, elevation): palm side, then thumb side
VIEW_NAMES = {VIEWS[0]: "palm side", VIEWS[1]: "thumb side"}


def strip_png(params: Sequence[BaseParams | ExtendedParams], path: str | Path, labels: Sequence[str] | None = None,
              q: np.ndarray | None = None, panel_size: float = 2.0, dpi: int = 100,
              originals: Sequence[tuple[str, BaseParams | ExtendedParams]] | None = None,
              views: Sequence[tuple[float, float]] = VIEWS) -> Path:
    """Draw hands side by side into one PNG, one row per view (default: palm side and thumb side),
    all panels of a row at one scale; returns the path.

    ``originals``: two (label, params) drawn pale before the first and after the last hand (the
    hands a latent interpolation starts and ends at, beside their decoded versions).
    """
    from matplotlib.figure import Figure  # no pyplot: a notebook's inline backend is left alone

    hands = list(params)
    titles = [labels[i] if labels is not None else f"{i}: {p.num_fingers} fingers, {p.dof} dof" for i, p in enumerate(hands)]
    faded = [False] * len(hands)
    if originals is not None:
        (la, pa), (lb, pb) = originals
        hands, titles, faded = [pa, *hands, pb], [la, *titles, lb], [True, *faded, True]
    n, m = len(hands), len(views)
    fig = Figure(figsize=(panel_size * n, panel_size * 1.1 * m))
    axes = fig.subplots(m, n, squeeze=False)
    for row, (az, el) in enumerate(views):
        half = 0.0
        for i, p in enumerate(hands):  # first pass: the largest extent, so a row shares one scale
            half = max(half, draw_hand(axes[row, i], p, q, az, el))
        for i, p in enumerate(hands):
            axes[row, i].clear()
            draw_hand(axes[row, i], p, q, az, el, title=titles[i] if row == 0 else None, faded=faded[i], half=half)
        axes[row, 0].set_ylabel(VIEW_NAMES.get((az, el), f"azimuth {az:g}, elevation {el:g}"), fontsize=8)
    fig.tight_layout()
    from ohra.io import atomic_path

    path = Path(path)
    with atomic_path(path, suffix=path.suffix or ".png") as tmp:  # savefig picks the format from the name
        fig.savefig(tmp, dpi=dpi)
    return path


def sequence_html(params: Sequence[BaseParams | ExtendedParams], path: str | Path, spacing: float = 0.2,
                  originals: Sequence[BaseParams | ExtendedParams] | None = None, caption: str | None = None) -> Path:
    """A static meshcat HTML scene: the hands in a row (first on the left, seen from the palm side),
    ``spacing`` metres apart; ``originals`` (two hands) stand in grey one row higher, above the first
    and the last. The camera is set to frame the row (meshcat's orbit target is the scene origin,
    so the scene is centred there)."""
    import contextlib
    import io

    from ohra import viz

    with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints its server URL
        vis = viz.new_visualizer()
    vis.delete()
    n = len(params)
    rows = 1 if originals is None else 2
    z0 = -0.75 * spacing * (rows - 1) - 0.08  # palm frames sit at the wrist; hands rise ~0.16 m along +z

    def place(i: int, row: int) -> np.ndarray:
        T = np.eye(4)
        T[1, 3], T[2, 3] = spacing * (i - (n - 1) / 2.0), z0 + 1.5 * spacing * row  # +y is right, seen from +x
        return T

    for i, p in enumerate(params):
        viz.add_hand(vis, HandModel.from_params(p), np.zeros(22), T_world_palm=place(i, 0), path=f"hands/step_{i:02d}")
    if originals is not None:
        for name, p, i in zip(("original_a", "original_b"), originals, (0, n - 1)):
            viz.add_hand(vis, HandModel.from_params(p), np.zeros(22), T_world_palm=place(i, 1), path=f"hands/{name}",
                         color=viz.ORIGINAL_COLOR)
    _frame_camera(vis, width=spacing * n, height=1.5 * spacing * rows)
    return viz.save_html(vis, path, caption)


def _frame_camera(vis, width: float, height: float) -> None:
    """Put meshcat's camera on +x (palm side, a little above), looking at the origin from far enough
    that a ``width`` x ``height`` metre area around it fills most of the view; hide the 1 m grid."""
    span = max(width / 1.6, height)  # the default view is about 1.6 times wider than high
    dist = 0.75 * span / np.tan(np.radians(75.0) / 2.0)  # meshcat's default vertical field of view is 75 deg
    # the camera object lives in three.js axes under /rotated (y up): x = scene x, y = scene z
    vis["/Cameras/default/rotated/<object>"].set_property("position", [dist, 0.2 * dist, 0.0])
    vis["/Grid"].set_property("visible", False)
