"""The rigid body an object is grasped *and* simulated as.

An object's surface mesh (what a file holds) is not what PyBullet can simulate: a dynamic body
must be convex pieces (or primitives). The solver used to grasp the mesh while the simulator held
a decomposition up to 7 mm away from it (a YCB can's provided V-HACD piece, a 2x-inflated wrench),
so grasps started inside the simulated object. Here one :class:`Body` is both: the solver's signed
distance, the simulator's collision shape, and the mass, centre of mass and inertia all come from
it. How far it lies from the mesh is measured (:class:`Fidelity`, stored in dataset manifests).

Kinds: ``primitives`` (spheres, boxes, cylinders, capsules: exact in PyBullet, closed-form signed
distance and mass properties), ``exact`` (a convex mesh of a shape with a closed-form signed
distance, e.g. a procedural superquadric), and convex ``pieces`` (the hull, a provided
decomposition or V-HACD). For pieces, the sign of the distance comes from the exact point-in-piece
test (face planes) and the magnitude from dense samples of the union's surface (overestimating by
at most half the sample spacing, ``sample_spacing``).

Frames: everything is in the object's mesh frame, metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Callable

import numpy as np
import trimesh
from scipy.spatial import ConvexHull, cKDTree

SDF = Callable[[np.ndarray], np.ndarray]
# a body whose surface lies within this of the mesh (95th percentile, both ways) matches it [m];
# YCB scans sit 1-6 mm from their best convex body (dents, recessed lids), so 5 mm flags real misfits
BODY_TOLERANCE_M = 0.005
# a body whose volume leaves this range of the mesh's (body / mesh) fills a cavity or thin walls, or
# misses parts: its mass and inertia, taken from the body, are then that far off and said so
BODY_VOLUME_RANGE = (0.8, 1.25)
# PyBullet inflates convex meshes by this collision margin; the world sets it to 0 on the object
BULLET_MESH_MARGIN_M = 0.001


@dataclass(frozen=True)
class MassProperties:
    """Volume [m^3], centre of mass [m] and inertia about it per unit density [m^5] of one body."""

    volume: float
    center_mass: np.ndarray
    inertia_per_density: np.ndarray
    method: str  # how they were obtained ("exact ..." or "estimated ...")

    @property
    def estimated(self) -> bool:
        return self.method.startswith("estimated")


@dataclass(frozen=True)
class Fidelity:
    """How well the body matches the mesh: volume ratio and surface distances [m] both ways."""

    volume_ratio: float  # body / mesh
    mesh_to_body_mean: float
    body_to_mesh_mean: float
    mesh_to_body_p95: float
    mesh_to_body_max: float
    body_to_mesh_p95: float
    body_to_mesh_max: float

    @property
    def mean(self) -> float:
        """Mean surface distance, averaged over both directions [m] (how bodies are ranked)."""
        return 0.5 * (self.mesh_to_body_mean + self.body_to_mesh_mean)

    @property
    def p95(self) -> float:
        """The larger of the two 95th-percentile surface distances [m] (what the tolerance bounds)."""
        return max(self.mesh_to_body_p95, self.body_to_mesh_p95)

    @property
    def within_tolerance(self) -> bool:
        return self.p95 <= BODY_TOLERANCE_M

    def to_dict(self) -> dict:
        return {"volume_ratio": self.volume_ratio, "mesh_to_body_mean_m": self.mesh_to_body_mean,
                "body_to_mesh_mean_m": self.body_to_mesh_mean, "mesh_to_body_p95_m": self.mesh_to_body_p95,
                "mesh_to_body_max_m": self.mesh_to_body_max, "body_to_mesh_p95_m": self.body_to_mesh_p95,
                "body_to_mesh_max_m": self.body_to_mesh_max, "tolerance_m": BODY_TOLERANCE_M,
                "within_tolerance": self.within_tolerance}


# -- primitives --------------------------------------------------------------------------------------
class PrimitiveSDF:
    """Signed distance [m] to the union of primitive dicts (see :mod:`ohra.objects.builtin`): exact
    outside and on the surface; inside, the distance to the nearest primitive's surface. A class,
    not a closure, so objects pickle into worker processes."""

    def __init__(self, prims: list[dict]):
        self.prims = prims

    @staticmethod
    def _one(p: np.ndarray, pr: dict) -> np.ndarray:
        x = p - np.asarray(pr["pos"], dtype=float)
        s = pr["size"]
        if pr["type"] == "sphere":
            return np.linalg.norm(x, axis=1) - s[0]
        if pr["type"] == "box":
            q = np.abs(x) - np.asarray(s, dtype=float)
            return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
        if pr["type"] == "cylinder":
            q = np.stack([np.linalg.norm(x[:, :2], axis=1) - s[0], np.abs(x[:, 2]) - s[1] / 2], axis=1)
            return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
        if pr["type"] == "capsule":
            z = np.clip(x[:, 2], -s[1] / 2, s[1] / 2)
            return np.linalg.norm(x - np.stack([0 * z, 0 * z, z], axis=1), axis=1) - s[0]
        raise ValueError(f"unknown primitive type {pr['type']!r}")

    def __call__(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        return np.min([self._one(p, pr) for pr in self.prims], axis=0)


def primitive_sdf(prims: list[dict]) -> SDF:
    """The :class:`PrimitiveSDF` of ``prims``."""
    return PrimitiveSDF(prims)


def _primitive_mass(pr: dict) -> tuple[float, np.ndarray]:
    """Volume and (3,3) inertia about the primitive's centre per unit density (axis z for round ones)."""
    s = pr["size"]
    if pr["type"] == "sphere":
        v = 4 / 3 * math.pi * s[0] ** 3
        return v, np.eye(3) * 0.4 * v * s[0] ** 2
    if pr["type"] == "box":
        a, b, c = (2 * x for x in s)
        v = a * b * c
        return v, np.diag([b * b + c * c, a * a + c * c, a * a + b * b]) * v / 12
    r, h = s[0], s[1]
    vc = math.pi * r * r * h
    if pr["type"] == "cylinder":
        return vc, np.diag([vc * (3 * r * r + h * h) / 12] * 2 + [vc * r * r / 2])
    vs = 4 / 3 * math.pi * r**3  # two hemispheres, centred h/2 from the middle
    ixx = vc * (h * h / 12 + r * r / 4) + vs * (0.4 * r * r + h * h / 4 + 3 * h * r / 8)
    return vc + vs, np.diag([ixx, ixx, vc * r * r / 2 + vs * 0.4 * r * r])


def primitive_mass_properties(prims: list[dict]) -> MassProperties:
    """Closed-form mass properties of non-overlapping primitives (parallel-axis sum)."""
    parts = [(_primitive_mass(pr), np.asarray(pr["pos"], dtype=float)) for pr in prims]
    vol = sum(v for (v, _), _ in parts)
    com = sum(v * p for (v, _), p in parts) / vol
    inertia = np.zeros((3, 3))
    for (v, I), p in parts:
        d = p - com
        inertia += I + v * (d @ d * np.eye(3) - np.outer(d, d))
    return MassProperties(vol, com, inertia, f"exact: closed form over {len(prims)} primitive(s)")


# -- bodies ---------------------------------------------------------------------------------------------
class Body:
    """Convex pieces (and optionally the primitives or exact SDF they stand for) of one rigid body."""

    def __init__(self, pieces: list[trimesh.Trimesh], kind: str, primitives: list[dict] | None = None,
                 exact_sdf: SDF | None = None):
        if not pieces:
            raise ValueError("a body needs at least one convex piece")
        self.pieces = pieces
        self.kind = kind
        self.primitives = primitives
        self._exact = primitive_sdf(primitives) if primitives else exact_sdf
        # outward face planes of each piece: n . x + d <= 0 inside (Qhull's, robust to sliver faces)
        # (coplanar triangles share a plane: a box has 6, a 96-segment cylinder 98, not 2x as many)
        self._planes = [np.unique(np.round(ConvexHull(np.asarray(p.vertices)).equations, 12), axis=0) for p in pieces]
        self._boxes = np.array([p.bounds for p in pieces])

    @property
    def bounds(self) -> np.ndarray:
        """(2,3) axis-aligned bounds of all pieces [m]."""
        return np.array([self._boxes[:, 0].min(axis=0), self._boxes[:, 1].max(axis=0)])

    @cached_property
    def vertices(self) -> np.ndarray:
        return np.vstack([p.vertices for p in self.pieces])

    def piece_value(self, points: np.ndarray) -> np.ndarray:
        """(N,) min over pieces of the largest face-plane distance: < 0 exactly inside the union."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        out = np.full(len(p), np.inf)
        for eq, (lo, hi) in zip(self._planes, self._boxes):
            # outside a piece's bounds the value only matters if no other piece is nearer: the
            # distance to the box is a lower bound on it, so far points skip the plane products
            gap = np.linalg.norm(np.maximum(np.maximum(lo - p, p - hi), 0.0), axis=1)
            near = gap < out
            if near.any():
                out[near] = np.minimum(out[near], (p[near] @ eq[:, :3].T + eq[:, 3]).max(axis=1))
        return out

    @cached_property
    def _surface(self) -> tuple[cKDTree, np.ndarray, np.ndarray, float]:
        """KD-tree, (M,3) points and outward normals of dense samples of the union's surface, spacing."""
        areas = np.array([p.area for p in self.pieces])
        n_total = int(np.clip(areas.sum() / 0.0015**2, 20_000, 150_000))
        pts, nrm = [], []
        for k, (p, a) in enumerate(zip(self.pieces, areas)):
            s, fid = trimesh.sample.sample_surface(p, max(int(n_total * a / areas.sum()), 64), seed=k)
            pts.append(np.vstack([s, p.vertices]))
            nrm.append(np.vstack([p.face_normals[fid], p.vertex_normals]))
        P, N = np.vstack(pts), np.vstack(nrm)
        if len(self.pieces) > 1:
            keep = self.piece_value(P) > -1e-6  # samples buried inside another piece are not on the union's surface
            P, N = P[keep], N[keep]
        return cKDTree(P), P, N, math.sqrt(areas.sum() / max(len(P), 1))

    @property
    def sample_spacing(self) -> float:
        """Mean spacing of the surface samples behind :meth:`signed_distance` (0 when exact) [m]."""
        return 0.0 if self._exact else self._surface[3]

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """(N,) signed distance [m] to the body's surface at (N,3) points (negative inside).

        The sign is the exact point-in-piece test, except for a single convex piece farther than three
        sample spacings from its surface: there a vote of the four nearest samples' outward normals
        cannot be wrong and spares the plane products of a many-faced hull (an SDF grid took 9 s,
        now 0.6 s). In a union of pieces the vote can err near concave creases, so it is not used.
        """
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        if self._exact is not None:
            return self._exact(p)
        tree, P, N, spacing = self._surface
        if len(self.pieces) > 1:  # the sign is the point-in-piece test everywhere: only the nearest sample is needed
            d1 = tree.query(p, k=1)[0]
            return np.where(self.piece_value(p) < 0.0, -d1, d1)
        d, i = tree.query(p, k=4)
        side = np.einsum("nkj,nkj->nk", p[:, None, :] - P[i], N[i]) / (d + 1e-9)
        inside = side.sum(axis=1) < 0.0
        near = d[:, 0] < 3.0 * spacing
        inside[near] = self.piece_value(p[near]) < 0.0
        return np.where(inside, -d[:, 0], d[:, 0])

    def sample_surface(self, n: int, seed: int = 0) -> np.ndarray:
        """(n,3) points on the body's surface (area-uniform over the union's exposed faces)."""
        P = self._surface[1]
        return P[np.random.default_rng(seed).choice(len(P), size=min(n, len(P)), replace=False)]

    @cached_property
    def mass_properties(self) -> MassProperties:
        if self.primitives:
            return primitive_mass_properties(self.primitives)
        if len(self.pieces) == 1:
            m = self.pieces[0]
            return MassProperties(float(m.volume), np.asarray(m.center_mass, dtype=float), np.asarray(m.moment_inertia, dtype=float),
                                  f"exact: closed convex mesh of {len(m.faces)} faces")
        return grid_mass_properties(self)

    def hash_bytes(self) -> bytes:
        """Bytes that identify the body's geometry (for cache keys and manifests)."""
        if self.primitives:
            return repr(self.primitives).encode()
        return b"".join(np.ascontiguousarray(p.vertices, dtype=np.float64).tobytes() for p in self.pieces) + self.kind.encode()


def grid_mass_properties(body: Body, cells: int = 1_000_000) -> MassProperties:
    """Mass properties of a union of overlapping convex pieces, estimated on a regular grid of about
    ``cells`` cell centres over the bounds (relative volume error ~ surface x spacing / volume / 10)."""
    lo, hi = body.bounds
    h = float(np.prod(hi - lo) / cells) ** (1 / 3)
    axes = [np.arange(lo[d] + h / 2, hi[d], h) for d in range(3)]
    inside = np.zeros(tuple(len(a) for a in axes), dtype=bool)
    for eq, (blo, bhi) in zip(body._planes, body._boxes):
        sl = [slice(np.searchsorted(a, blo[d]), np.searchsorted(a, bhi[d], side="right")) for d, a in enumerate(axes)]
        X, Y, Z = np.meshgrid(*(a[s] for a, s in zip(axes, sl)), indexing="ij")
        P = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
        if len(P):
            inside[tuple(sl)] |= ((P @ eq[:, :3].T + eq[:, 3]).max(axis=1) < 0).reshape(X.shape)
    idx = np.argwhere(inside)
    P = lo + h / 2 + h * idx  # cell centres
    vol = len(P) * h**3
    com = P.mean(axis=0)
    r = P - com
    inertia = ((r * r).sum() * np.eye(3) - r.T @ r) * h**3 + np.eye(3) * vol * h * h / 6  # cells' own inertia too
    return MassProperties(vol, com, inertia, f"estimated: {len(P)} cells of {1e3 * h:.2f} mm over the union of {len(body.pieces)} convex pieces")


def fidelity(body: Body, mesh: trimesh.Trimesh, mesh_points: np.ndarray, mesh_volume: float, n: int = 2000) -> Fidelity:
    """Compare ``body`` with ``mesh`` (given with (M,3) surface samples and its volume [m^3]):
    distances from mesh samples to the body and from body samples to the closest mesh triangle."""
    a = np.abs(body.signed_distance(mesh_points))
    _, b, _ = trimesh.proximity.closest_point(mesh, body.sample_surface(n, seed=1))
    return Fidelity(body.mass_properties.volume / mesh_volume, float(a.mean()), float(b.mean()), float(np.percentile(a, 95)), float(a.max()),
                    float(np.percentile(b, 95)), float(b.max()))
