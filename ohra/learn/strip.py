"""Pictures of hand sequences: a matplotlib PNG strip and a meshcat HTML scene.

The PNG draws each hand's capsules and palm (from :class:`ohra.HandModel`) in an orthographic
view from the palm side (+x), turned by ``azimuth`` about the finger axis and tilted by
``elevation``, painter's order (far parts first). No OpenGL is needed.
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
              elevation: float = 15.0, title: str | None = None) -> None:
    """Draw one canonical hand into a matplotlib axes (metres, equal aspect)."""
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
    allpts = [np.zeros((1, 2))]
    for _, poly, color in sorted(shapes, key=lambda s: s[0]):
        ax.add_patch(Polygon(poly, closed=True, facecolor=color, edgecolor="#333333", linewidth=0.6, alpha=0.95))
        allpts.append(poly)
    P = np.concatenate(allpts)
    lo, hi = P.min(axis=0), P.max(axis=0)
    c, half = (lo + hi) / 2, max(hi - lo) / 2 + 0.01
    ax.set_xlim(c[0] - half, c[0] + half)
    ax.set_ylim(c[1] - half, c[1] + half)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=8)


def strip_png(params: Sequence[BaseParams | ExtendedParams], path: str | Path, labels: Sequence[str] | None = None,
              q: np.ndarray | None = None, panel_size: float = 2.0, dpi: int = 100) -> Path:
    """Draw hands side by side into one PNG; returns the path."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    n = len(params)
    fig, axes = plt.subplots(1, n, figsize=(panel_size * n, panel_size * 1.15), squeeze=False)
    for i, p in enumerate(params):
        label = labels[i] if labels is not None else None
        if label is None:
            label = f"{i}: {p.num_fingers} fingers, {p.dof} dof"
        draw_hand(axes[0, i], p, q, title=label)
    fig.tight_layout()
    from ohra.io import atomic_path

    path = Path(path)
    with atomic_path(path, suffix=path.suffix or ".png") as tmp:  # savefig picks the format from the name
        fig.savefig(tmp, dpi=dpi)
    plt.close(fig)
    return path


def sequence_html(params: Sequence[BaseParams | ExtendedParams], path: str | Path, spacing: float = 0.2) -> Path:
    """A static meshcat HTML scene with the hands in a row along -y, ``spacing`` metres apart."""
    import contextlib
    import io

    from ohra import viz

    with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints its server URL
        vis = viz.new_visualizer()
    vis.delete()
    for i, p in enumerate(params):
        T = np.eye(4)
        T[1, 3] = -spacing * i
        viz.add_hand(vis, HandModel.from_params(p), np.zeros(22), T_world_palm=T, path=f"hands/step_{i:02d}")
    return viz.save_html(vis, path)
