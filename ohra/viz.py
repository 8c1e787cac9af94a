"""meshcat scenes: canonical hands (capsules), meshes, grasps; static HTML export.

Every function draws into a ``meshcat.Visualizer`` under a path of your choice, in metres. Poses
are 4x4 transforms of the palm frame in the scene (world) frame. ``static_html`` snapshots a scene
into a self-contained HTML page (meshcat's own export) that opens without a running server.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ohra.canonical.kinematics import HandModel

__all__ = [
    # a scene and what goes in it
    "new_visualizer", "add_hand", "add_capsules", "add_original", "add_overlay", "add_mesh", "add_points", "add_frame",
    "add_grasp", "show_hand",
    # pages, pictures and framing
    "static_html", "save_html", "embed", "compare_html", "grasp_png", "caption_div",
    "CameraView", "scene_bounds", "clear_bounds", "frame_bounds", "framing_script",
    "HAND_COLOR", "OBJECT_COLOR", "ORIGINAL_COLOR", "SERVERS",
]

HAND_COLOR = 0x66BFFF
OBJECT_COLOR = 0xD9A066
ORIGINAL_COLOR = 0xB0B0B0

# three.js cylinders run along their local y axis; ours run along z.
_Y_TO_Z = np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])


SERVERS: list = []  # meshcat server processes this process started (the CLI stops them on SIGTERM / SIGHUP)


def new_visualizer(open_browser: bool = False):
    """Start a meshcat server (local, loopback) and return its Visualizer (``vis.url()`` is its address).

    meshcat prints "You can open the visualizer by visiting ..." on stdout; that line is kept out of
    the output here, since most callers only export static HTML and the server stops with them.
    """
    import contextlib
    import io

    import meshcat

    with contextlib.redirect_stdout(io.StringIO()):
        vis = meshcat.Visualizer()
    proc = getattr(getattr(vis, "window", None), "server_proc", None)
    if proc is not None:
        SERVERS.append(proc)
    if open_browser:  # pragma: no cover - interactive
        vis.open()
    return vis


def _material(color: int, opacity: float):
    import meshcat.geometry as g

    return g.MeshLambertMaterial(color=color, opacity=opacity, transparent=opacity < 1.0)


def add_hand(vis: Any, hand: HandModel, q: np.ndarray, T_world_palm: np.ndarray | None = None,
             path: str = "hand", color: int = HAND_COLOR, opacity: float = 0.8) -> None:
    """Draw the canonical hand (palm cylinder + finger capsules) at configuration ``q``."""
    import meshcat.geometry as g

    if not isinstance(hand, HandModel):
        from ohra.errors import OhraError

        raise OhraError(f"add_hand: expected a HandModel (HandModel.from_params(params)), got {type(hand).__name__}")
    T0 = np.eye(4) if T_world_palm is None else np.asarray(T_world_palm, dtype=float)
    if T0.shape != (4, 4):
        from ohra.errors import OhraError

        raise OhraError(f"add_hand: T_world_palm must be a (4, 4) transform, got shape {T0.shape}")
    mat = _material(color, opacity)
    vis[path].delete()
    palm = hand.palm
    Tp = np.eye(4)
    Tp[:3, :3] = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # cylinder y -> palm x
    Tp[:3, 3] = (0.0, 0.0, palm["radius"])
    vis[path]["palm"].set_object(g.Cylinder(palm["depth"], palm["radius"]), mat)
    vis[path]["palm"].set_transform(T0 @ Tp)
    caps = hand.capsules(q)
    half = np.array([palm["depth"] / 2, palm["radius"], palm["radius"]])
    _grow_bounds(vis, _box_corners(Tp[:3, 3] - half, Tp[:3, 3] + half) @ T0[:3, :3].T + T0[:3, 3])
    _grow_bounds(vis, _capsule_corners(caps) @ T0[:3, :3].T + T0[:3, 3])
    _draw_capsules(vis[path], caps, T0, mat)


def _draw_capsules(node: Any, capsules: Any, T0: np.ndarray, mat: Any) -> None:
    """Draw each capsule of :class:`ohra.Capsules` under ``node[link]``: a cylinder ``body`` (omitted
    for a zero-length capsule) and spheres ``end0``/``end1``, in world pose ``T0 @ (palm-frame pose)``."""
    import meshcat.geometry as g

    for k, link in enumerate(capsules.link):
        a, b, r = capsules.p0[k], capsules.p1[k], float(capsules.radius[k])
        d = b - a
        length = float(np.linalg.norm(d))
        z = d / length if length > 1e-12 else np.array([0.0, 0.0, 1.0])
        x = np.cross([0.0, 1.0, 0.0], z) if abs(z[1]) < 0.9 else np.cross([1.0, 0.0, 0.0], z)
        x /= np.linalg.norm(x)
        Tc = np.eye(4)
        Tc[:3, :3] = np.column_stack([x, np.cross(z, x), z])
        Tc[:3, 3] = (a + b) / 2
        if length > 1e-9:
            node[link]["body"].set_object(g.Cylinder(length, r), mat)
            node[link]["body"].set_transform(T0 @ Tc @ _Y_TO_Z)
        for end, p in (("end0", a), ("end1", b)):
            Ts = np.eye(4)
            Ts[:3, 3] = p
            node[link][end].set_object(g.Sphere(r), mat)
            node[link][end].set_transform(T0 @ Ts)


def add_mesh(vis: Any, vertices: np.ndarray, faces: np.ndarray, T: np.ndarray | None = None,
             path: str = "object", color: int = OBJECT_COLOR, opacity: float = 1.0) -> None:
    """Draw a triangle mesh (vertices in metres) at pose ``T``."""
    import meshcat.geometry as g

    vis[path].set_object(g.TriangularMeshGeometry(np.asarray(vertices, dtype=float), np.asarray(faces, dtype=np.int64)),
                         _material(color, opacity))
    T = np.eye(4) if T is None else np.asarray(T, dtype=float)
    vis[path].set_transform(T)
    _grow_bounds(vis, np.asarray(vertices, dtype=float) @ T[:3, :3].T + T[:3, 3])


def _array(x: Any, what: str, shape: tuple[int | None, ...]) -> np.ndarray:
    """``x`` as a finite float array of ``shape`` (None: any length); else an :class:`~ohra.errors.OhraError`
    naming ``what``."""
    from ohra.errors import OhraError

    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise OhraError(f"{what} must be numbers, got {type(x).__name__}") from None
    if isinstance(x, (str, bytes)) or a.ndim != len(shape) or any(n is not None and n != m for n, m in zip(shape, a.shape)):
        want = "x".join("N" if n is None else str(n) for n in shape)
        raise OhraError(f"{what} must be an array of shape ({want}), got {getattr(a, 'shape', type(x).__name__)}")
    if not np.all(np.isfinite(a)):
        raise OhraError(f"{what} holds non-finite values")
    return a


def add_points(vis: Any, points: np.ndarray, path: str = "points", color: int = 0xFF3030, size: float = 0.004) -> None:
    """Draw a point cloud (N,3) [m, world frame]; ``color`` 0xRRGGBB, ``size`` [m]."""
    import meshcat.geometry as g

    pts = _array(points, "add_points: points", (None, 3)).astype(np.float32).T
    colors = np.tile(np.array([[(color >> 16) & 255], [(color >> 8) & 255], [color & 255]], dtype=np.float32) / 255.0, (1, pts.shape[1]))
    vis[path].set_object(g.PointCloud(pts, colors, size=size))
    _grow_bounds(vis, pts.T)


def add_frame(vis: Any, T: np.ndarray, path: str = "frame", length: float = 0.05) -> None:
    """Draw a coordinate triad (x red, y green, z blue) at the 4x4 pose ``T`` [m, world frame]; ``length`` [m]."""
    import meshcat.geometry as g

    T = _array(T, "add_frame: T", (4, 4))
    vis[path].set_object(g.triad(length))
    vis[path].set_transform(T)
    _grow_bounds(vis, np.vstack([T[:3, 3], T[:3, 3] + length * T[:3, :3].T]))


def static_html(vis: Any, caption: str | None = None) -> str:
    """A self-contained HTML snapshot of the scene (opens without a server), framed on its content; ``caption``
    (plain text) is shown in its top-left corner (what the colours and places mean)."""
    html = vis.static_html()
    bounds = scene_bounds(vis)
    extra = (framing_script(frame_bounds(*bounds)) if bounds is not None else "") + (caption_div(caption) if caption else "")
    if not extra:
        return html
    cut = html.rfind("</body>")
    return html[:cut] + extra + html[cut:]


def caption_div(text: str) -> str:
    """A fixed caption over a static page (HTML-escaped)."""
    from html import escape

    return ('<div class="ohra-caption" style="position:fixed;top:8px;left:8px;max-width:60%;z-index:10;'
            'font:13px/1.35 sans-serif;color:#111;background:rgba(255,255,255,0.82);padding:5px 9px;border-radius:4px">'
            f"{escape(text)}</div>\n")


# -- framing: a static export opens on its content ------------------------------------------------------
FOV_DEG = 75.0  # meshcat's perspective camera: vertical field of view [deg]
MESHCAT_GRID_CELL = 0.5  # m: meshcat's grid is 20 m wide in 40 cells
MESHCAT_AXES_LENGTH = 0.5  # m
VIEW_DIRECTION = (1.0, 0.35, 0.45)  # world direction from the content toward the camera (palm side, a bit above)


@dataclass(frozen=True)
class CameraView:
    """Where a static export's camera sits and looks (world frame, z up, metres), and its grid cell."""

    target: np.ndarray
    position: np.ndarray
    grid_cell: float


def _box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    return np.array([[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])


def _capsule_corners(capsules: Any) -> np.ndarray:
    """Corners of the boxes around every capsule's two end spheres (palm frame)."""
    r = np.asarray(capsules.radius, dtype=float)[:, None]
    ends = np.vstack([capsules.p0, capsules.p1])
    rr = np.vstack([r, r])
    return np.vstack([ends - rr, ends + rr]).reshape(-1, 3)


def _grow_bounds(vis: Any, points: np.ndarray) -> None:
    """Widen the box of drawn content that the visualizer's window keeps for :func:`static_html`."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) == 0:
        return
    window = vis.window
    lo, hi = p.min(axis=0), p.max(axis=0)
    old = getattr(window, "_ohra_bounds", None)
    if old is not None:
        lo, hi = np.minimum(lo, old[0]), np.maximum(hi, old[1])
    window._ohra_bounds = (lo, hi)


def scene_bounds(vis: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """(lo, hi) corners [m, world] of everything the ``add_*`` functions drew into ``vis``, or None."""
    return getattr(vis.window, "_ohra_bounds", None)


def clear_bounds(vis: Any) -> None:
    """Forget the drawn content's box (after ``vis.delete()``)."""
    vis.window._ohra_bounds = None


def _nice(x: float) -> float:
    """The 1-2-5 number nearest below ``x`` (> 0)."""
    e = 10.0 ** np.floor(np.log10(x))
    return float(max(m for m in (1.0, 2.0, 5.0) if m * e <= x * (1 + 1e-9)) * e)


def frame_bounds(lo: np.ndarray, hi: np.ndarray, direction=VIEW_DIRECTION, fov_deg: float = FOV_DEG,
                 margin: float = 1.1) -> CameraView:
    """The camera that sees the whole box [lo, hi] (world, m) from ``direction``, looking at its centre.

    The distance fits every corner into the vertical field of view and, assuming a window at least
    as wide as it is tall, the horizontal one; ``margin`` leaves a border. The grid cell is the 1-2-5
    length nearest below a tenth of the box's largest side.
    """
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    centre = (lo + hi) / 2
    size = max(float(np.max(hi - lo)), 1e-3)
    back = np.asarray(direction, dtype=float)
    back = back / np.linalg.norm(back)
    up = np.array([0.0, 0.0, 1.0]) - back[2] * back
    up /= np.linalg.norm(up)
    right = np.cross(up, back)
    c = _box_corners(lo, hi) - centre
    t = np.tan(np.radians(fov_deg) / 2)
    # a corner at depth c.back toward the camera needs distance >= c.back + (offset across) / tan
    across = np.maximum(np.abs(c @ up), np.abs(c @ right))
    distance = float(np.max(c @ back + margin * across / t))
    distance = max(distance, size)  # flat or tiny content: not closer than its own size
    return CameraView(centre, centre + distance * back, _nice(size / 10))


def framing_script(view: CameraView) -> str:
    """JavaScript for meshcat's static page: orbit target and camera position, grid and axes scaled.

    meshcat's three.js world is y-up: a world point (x, y, z) is (x, z, -y) there. The orbit target
    has no meshcat command, hence a script rather than scene commands.
    """

    def three(p: np.ndarray) -> str:
        return ", ".join(f"{v:.6g}" for v in (p[0], p[2], -p[1]))

    grid = view.grid_cell / MESHCAT_GRID_CELL
    axes = 2 * view.grid_cell / MESHCAT_AXES_LENGTH
    return (
        "<script>\n(function () {  // ohra: open framed on the content\n"
        f"  viewer.controls.target.set({three(view.target)});\n"
        f"  viewer.camera.position.set({three(view.position)});\n"
        f'  viewer.set_property(["Grid"], "scale", [{grid:.6g}, {grid:.6g}, {grid:.6g}]);\n'
        f'  viewer.set_property(["Axes"], "scale", [{axes:.6g}, {axes:.6g}, {axes:.6g}]);\n'
        "  viewer.controls.update();\n  viewer.set_dirty();\n})();\n</script>\n"
    )


def embed(vis: Any, height: int = 420):
    """The view as a Jupyter cell output: :func:`static_html` in an iframe (self-contained, framed on the content;
    meshcat's own ``vis.render_static()`` opens on its default camera, where a hand is a speck on the grid)."""
    from html import escape

    from IPython.display import HTML

    return HTML(f'<div><iframe srcdoc="{escape(static_html(vis), quote=True)}" width="100%" height="{int(height)}"></iframe></div>')


def save_html(vis: Any, path: str | Path, caption: str | None = None) -> Path:
    """Write :func:`static_html` (with ``caption``) to ``path`` (atomically, mode from the umask; see :mod:`ohra.io`)."""
    from ohra.io import write_text

    return write_text(path, static_html(vis, caption))


# -- original vs canonical overlays (parser / fidelity) ----------------------------------------------
def add_capsules(vis: Any, capsules: Any, T_world_palm: np.ndarray | None = None, path: str = "capsules",
                 color: int = HAND_COLOR, opacity: float = 0.8) -> None:
    """Draw :class:`ohra.Capsules` (one configuration) as cylinders + end spheres."""
    T0 = np.eye(4) if T_world_palm is None else np.asarray(T_world_palm, dtype=float)
    mat = _material(color, opacity)
    _grow_bounds(vis, _capsule_corners(capsules) @ T0[:3, :3].T + T0[:3, 3])
    _draw_capsules(vis[path], capsules, T0, mat)


def add_original(vis: Any, hand: Any, q_orig: np.ndarray, T_world_root: np.ndarray | None = None,
                 path: str = "original", color: int = ORIGINAL_COLOR, opacity: float = 0.6,
                 links: list[str] | None = None, prefer: str = "collision") -> None:
    """Draw an :class:`ohra.original.urdf.OriginalHand` at its joint vector ``q_orig`` (root pose ``T_world_root``)."""
    import warnings

    T0 = np.eye(4) if T_world_root is None else np.asarray(T_world_root, dtype=float)
    names = list(hand.links if links is None else links)
    poses = hand.link_poses(np.asarray(q_orig, dtype=float), names)
    vis[path].delete()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, T in zip(names, poses):
            m = hand.link_geometry(name, prefer=prefer)
            if m is None:
                continue
            add_mesh(vis, m.vertices, m.faces, T0 @ T, path=f"{path}/{name}", color=color, opacity=opacity)


def add_overlay(vis: Any, name: Any, form: str = "base", q: np.ndarray | None = None,
                T_world_palm: np.ndarray | None = None, path: str = "overlay", original: bool = True) -> None:
    """The paper's Fig. 2 view: a hand's original meshes and canonical capsules at the same canonical
    configuration ``q`` (default 0 clamped into the limits, couplings applied), both in the palm frame.
    ``name``: anything :func:`ohra.hands.resolve_hand` accepts (registered name, spec YAML, params JSON)."""
    from ohra.canonical.couplings import project
    from ohra.canonical.kinematics import HandModel
    from ohra.hands.resolve import resolve_hand
    from ohra.transforms import invert, xyzrpy_to_matrix

    ref = resolve_hand(name, form)
    params = ref.params
    hm = HandModel.from_params(params)
    qc = hm.neutral() if q is None else hm.clamp(q)
    qc = hm.clamp(project(ref.couplings, qc)) if ref.couplings else qc
    T0 = np.eye(4) if T_world_palm is None else np.asarray(T_world_palm, dtype=float)
    add_hand(vis, hm, qc, T0, path=f"{path}/canonical")
    if original:
        import warnings

        sp = ref.require_spec("the original overlay")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            orig = ref.original()
            am = ref.action_map()
        T_root = T0 @ invert(xyzrpy_to_matrix(sp.palm_origin))
        add_original(vis, orig, am.to_original(qc), T_root, path=f"{path}/original")


def compare_html(name: Any, form: str, out: str | Path, seed: int = 0, vis: Any = None) -> Path:
    """Static HTML with the overlay at q = 0 and at a random configuration (side by side, 0.3 m apart)."""
    from ohra.canonical.kinematics import HandModel
    from ohra.hands.resolve import resolve_hand

    name = resolve_hand(name, form)  # resolved once (a spec file is parsed once)
    hm = HandModel.from_params(name.params)
    own = vis is None
    vis = new_visualizer() if own else vis
    try:
        vis.delete()
        clear_bounds(vis)
        add_overlay(vis, name, form, None, np.eye(4), path="q0")
        T = np.eye(4)
        T[1, 3] = -0.3
        add_overlay(vis, name, form, hm.random_configurations(1, seed)[0], T, path="random")
        return save_html(vis, out, caption=f"{name.name} ({form} form): grey = original collision meshes, blue = canonical "
                                           f"capsules; right: q = 0, left: a random configuration (seed {seed})")
    finally:
        proc = getattr(getattr(vis, "window", None), "server_proc", None)
        if own and proc is not None:  # the meshcat server we started for the export
            proc.kill()
            proc.wait()


def show_hand(vis: Any, name: Any, form: str = "base", q: np.ndarray | None = None, original: bool = False) -> None:
    """Draw a hand (any :func:`ohra.hands.resolve_hand` reference; optionally over its original) for ``ohra hand show``."""
    add_overlay(vis, name, form, q, path="hand", original=original)


def add_grasp(vis: Any, hand: HandModel, grasp: np.ndarray, vertices: np.ndarray | None = None, faces: np.ndarray | None = None,
              path: str = "grasp") -> None:
    """Draw a grasp (31-vector, palm pose in the object frame) with its object mesh at the origin."""
    from ohra.rotations import grasp_to_pose

    T, q = grasp_to_pose(np.asarray(grasp, dtype=float))
    if vertices is not None and faces is not None:
        add_mesh(vis, vertices, faces, path=f"{path}/object")
    add_hand(vis, hand, q, T, path=f"{path}/hand")


def grasp_png(hand: HandModel, grasp: np.ndarray, vertices: np.ndarray, faces: np.ndarray, path: str | Path,
              views: tuple[tuple[float, float], ...] = ((20, -60), (20, 30)), size: float = 4.0) -> Path:
    """Render a grasp to a PNG with matplotlib (no display needed): object mesh + capsule hand,
    one panel per (elevation, azimuth) view, metres on the axes."""
    # The object-oriented Figure (no pyplot, no backend switch): a notebook's inline figures keep working.
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from ohra.rotations import grasp_to_pose

    T, q = grasp_to_pose(np.asarray(grasp, dtype=float))
    caps = hand.capsules(q)
    p0 = caps.p0 @ T[:3, :3].T + T[:3, 3]
    p1 = caps.p1 @ T[:3, :3].T + T[:3, 3]
    V, F = np.asarray(vertices), np.asarray(faces)
    fig = Figure(figsize=(size * len(views), size))
    for k, (elev, azim) in enumerate(views):
        ax = fig.add_subplot(1, len(views), k + 1, projection="3d")
        ax.add_collection3d(Poly3DCollection(V[F], facecolor="#d9a066", edgecolor="none", alpha=0.6))
        pts = np.vstack([V, p0, p1])
        c, h = pts.mean(axis=0), (pts.max(axis=0) - pts.min(axis=0)).max() / 2 + 0.02
        pt_per_m = size * 72 * 0.4 / (2 * h)  # marker points per metre at this zoom
        for a, b, r in zip(p0, p1, caps.radius):
            n = max(2, int(np.linalg.norm(b - a) / (0.5 * r)) + 2)
            seg = a + np.linspace(0, 1, n)[:, None] * (b - a)
            ax.scatter(*seg.T, color="#2a7fd4", s=(2 * r * pt_per_m) ** 2, alpha=0.9, depthshade=False, edgecolors="none")
        palm = T[:3, 3] + T[:3, :3] @ np.array([0.0, 0.0, hand.palm["radius"]])
        ax.scatter(*palm, color="#2a7fd4", s=(2 * hand.palm["radius"] * pt_per_m) ** 2, alpha=0.35, edgecolors="none")
        ax.set_xlim(c[0] - h, c[0] + h); ax.set_ylim(c[1] - h, c[1] + h); ax.set_zlim(c[2] - h, c[2] + h)
        ax.view_init(elev, azim)
        ax.set_xlabel("x [m]"); ax.set_ylabel("y [m]"); ax.set_zlabel("z [m]")
    fig.tight_layout()
    from ohra.io import atomic_path

    path = Path(path)
    with atomic_path(path, suffix=path.suffix or ".png") as tmp:  # savefig picks the format from the name
        fig.savefig(tmp, dpi=80)
    return path
