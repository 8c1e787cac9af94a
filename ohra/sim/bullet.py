"""Small PyBullet helpers: load URDF text, capture what the C++ side prints (warnings), and load a
simulator hand with its joint table."""

from __future__ import annotations

import math
import os
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import pybullet as pb

from ohra.sim.pybullet_import import captured_c_output  # noqa: F401  (re-exported: ohra.sim.bullet.captured_c_output)

if TYPE_CHECKING:
    from ohra.sim.hands import SimHand


def load_urdf_text(text: str, client: int, **kwargs) -> int:
    """``pybullet.loadURDF`` from URDF text (PyBullet only reads files); returns the body id."""
    fd, path = tempfile.mkstemp(suffix=".urdf")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        return pb.loadURDF(path, physicsClientId=client, **kwargs)
    finally:
        Path(path).unlink(missing_ok=True)


# Mesh files PyBullet's URDF importer reads itself; any other (.glb, .ply, .off, ...) is handed to it as OBJ.
BULLET_MESH_SUFFIXES = (".obj", ".stl", ".dae")


def bullet_mesh(path: str | Path) -> Path:
    """``path``, or for a format PyBullet cannot read (its importer rejects e.g. ``.glb`` and the
    whole URDF with it) the same mesh as OBJ in the cache, read as the parser reads it (trimesh,
    scene transforms applied, no processing) so that the simulator and the measurement see one
    shape. The copy is keyed by the file's content; units and the URDF's ``scale`` are untouched.

    Raises :class:`~ohra.errors.ParseError` naming the file when trimesh cannot read it.
    """
    import hashlib

    import trimesh

    from ohra.io import write_bytes
    from ohra.original.hand import read_mesh
    from ohra.paths import cache_dir

    path = Path(path)
    if path.suffix.lower() in BULLET_MESH_SUFFIXES or not path.is_file():
        return path  # a missing file is the URDF loader's to report
    digest = hashlib.sha256(path.read_bytes()).hexdigest()[:20]
    out = cache_dir() / "bullet_meshes" / f"{path.stem}-{digest}.obj"
    if out.is_file():
        return out
    mesh = read_mesh(path)
    write_bytes(out, trimesh.exchange.obj.export_obj(mesh, include_normals=False, include_texture=False).encode())
    return out


@dataclass(frozen=True)
class LoadedHand:
    """A :class:`~ohra.sim.hands.SimHand` loaded into PyBullet, with its URDF names resolved.

    Attributes:
        body: PyBullet body id.
        links: (PyBullet link index, URDF link name) of every link, the root link first as -1.
        jidx: PyBullet joint index of each driven joint, in ``hand.joints`` order.
        mimic: (PyBullet joint index, index of its driver in ``hand.joints``, multiplier, offset) of
            each loaded mimic joint.
        link_finger: PyBullet link index -> finger index (0 thumb .. 4 little; -1 palm and others).
    """

    body: int
    links: list[tuple[int, str]]
    jidx: list[int]
    mimic: list[tuple[int, int, float, float]]
    link_finger: dict[int, int]


def urdf_joint_damping(urdf: str) -> bool:
    """Whether the URDF text gives any joint a nonzero ``<dynamics damping>`` (which PyBullet applies
    explicitly; see :attr:`ohra.sim.protocol.Protocol.urdf_joint_damping`)."""
    root = ET.fromstring(urdf)
    return any(float(d.get("damping", 0.0) or 0.0) != 0.0 for d in root.iterfind("joint/dynamics"))


def load_hand(hand: "SimHand", urdf: str, flags: int, friction: float, client: int,
              joint_damping: bool = True) -> LoadedHand:
    """Load ``urdf`` (``hand.urdf`` or a variant of it with the same joints) fixed-base with
    ``flags``, resolve the hand's joint and link names, and give every link lateral friction
    ``sqrt(friction)`` (PyBullet multiplies the two bodies' coefficients, so a contact with an
    object of the same coefficient gets ``friction``), no spinning/rolling friction, no restitution.
    ``joint_damping=False`` drops the URDF's ``<dynamics damping>``, which PyBullet applies explicitly
    and which diverges on light links (see ``ohra.sim.rotation.config.RotationConfig.joint_damping``).

    Raises ``RuntimeError`` when PyBullet did not load a driven joint (e.g. merged away).
    """
    with captured_c_output():  # the fixed-link merge prints its progress on stdout
        b = load_urdf_text(urdf, client, useFixedBase=True, flags=flags)
    by_name: dict[str, int] = {}
    links: list[tuple[int, str]] = [(-1, ET.fromstring(hand.urdf).find("link").get("name"))]
    for j in range(pb.getNumJoints(b, physicsClientId=client)):
        info = pb.getJointInfo(b, j, physicsClientId=client)
        by_name[info[1].decode()] = j
        links.append((j, info[12].decode()))
    missing = [n for n in hand.joints if n not in by_name]
    if missing:
        raise RuntimeError(f"PyBullet did not load driven joints {missing}")
    mimic = [(by_name[n], hand.joints.index(m), mul, off) for n, (m, mul, off) in hand.mimic.items() if n in by_name]
    mu = math.sqrt(friction)
    for j, _ in links:
        pb.changeDynamics(b, j, lateralFriction=mu, spinningFriction=0.0, rollingFriction=0.0, restitution=0.0,
                          physicsClientId=client)
        if not joint_damping and j >= 0:
            pb.changeDynamics(b, j, jointDamping=0.0, physicsClientId=client)
    return LoadedHand(b, links, [by_name[n] for n in hand.joints], mimic,
                      {j: hand.link_finger.get(name, -1) for j, name in links})


def convex_pieces_shape(pieces: list, client: int) -> int:
    """One PyBullet collision shape of convex trimesh pieces (their vertices in the body's link frame [m])."""
    if len(pieces) == 1:
        return pb.createCollisionShape(pb.GEOM_MESH, vertices=[list(map(float, v)) for v in pieces[0].vertices],
                                       physicsClientId=client)
    # createCollisionShapeArray takes meshes only as files: one temporary OBJ per convex piece
    n = len(pieces)
    with tempfile.TemporaryDirectory() as tmp:
        files = []
        for k, piece in enumerate(pieces):
            files.append(str(Path(tmp) / f"piece{k}.obj"))
            piece.export(files[-1])
        return pb.createCollisionShapeArray([pb.GEOM_MESH] * n, fileNames=files, meshScales=[[1, 1, 1]] * n,
                                            collisionFramePositions=[[0, 0, 0]] * n,
                                            collisionFrameOrientations=[[0, 0, 0, 1]] * n, physicsClientId=client)
