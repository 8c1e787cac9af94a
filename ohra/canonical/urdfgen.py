"""Canonical URDF generation: parameters -> URDF text through the Jinja2 templates in ``urdf/templates``.

Departures from the reference templates (DESIGN decision 1): exact pi; correct capsule and palm
inertias (solid capsule and solid cylinder of density 1000 kg/m^3); an explicit small inertial on every
link, because PyBullet gives a link without one a mass of 1 kg; the little finger's metacarpal frame is
undone with the exact inverse rotation; tip frames are emitted only for present fingers, at the end of
the finger's last present segment. Numbers are written with 12 significant digits, so the same
parameters always give byte-identical text.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape

import jinja2
import numpy as np

from ohra.canonical.params import BaseParams, ExtendedParams, Params, require_params
from ohra.io import write_text
from ohra.resources import templates_dir
from ohra.transforms import inverse_rpy, rpy_to_matrix

DENSITY = 1000.0  # kg/m^3, finger and palm material
DUMMY_MASS = 1e-3  # kg, geometry-free links (bases, knuckles, tips)
DUMMY_INERTIA = 1e-8  # kg m^2, about a 5 mm sphere of DUMMY_MASS
EFFORT = 1.0  # N m, the drive force limit of the reference evaluation protocol
VELOCITY = 2.0 * math.pi  # rad/s
MIN_PALM_DEPTH = 0.01  # m, palm thickness of a hand without fingers


def fmt(x: float) -> str:
    """Compact deterministic number: 12 significant digits, no negative zero."""
    x = float(x)
    if x == 0.0 or abs(x) < 1e-15:
        return "0"
    s = f"{x:.12g}"
    return s


def fmt_vec(v: Any) -> str:
    return " ".join(fmt(x) for x in np.asarray(v, dtype=float).reshape(-1))


@dataclass(frozen=True)
class Inertia:
    mass: str
    ixx: str
    iyy: str
    izz: str


@dataclass(frozen=True)
class CapsuleSpec:
    """Formatted capsule geometry of radius ``r`` spanning z in [0, L]."""

    r: str
    cyl: str
    half: str
    top: str
    inertia: Inertia


def capsule_inertia(r: float, L: float) -> tuple[float, float, float]:
    """Mass and principal inertias (about the COM at L/2) of a solid capsule of total length L.

    Returns ``(mass, i_transverse, i_axial)`` in kg and kg m^2.
    """
    h = max(L - 2.0 * r, 0.0)
    m_cyl = DENSITY * math.pi * r * r * h
    m_hemi = DENSITY * 2.0 / 3.0 * math.pi * r**3
    mass = m_cyl + 2.0 * m_hemi
    i_axial = m_cyl * r * r / 2.0 + 2.0 * m_hemi * 2.0 * r * r / 5.0
    # Each hemisphere: 83/320 m r^2 about its own COM, which sits 3r/8 from the flat face.
    i_trans = m_cyl * (h * h / 12.0 + r * r / 4.0) + 2.0 * m_hemi * (
        83.0 / 320.0 * r * r + (h / 2.0 + 3.0 * r / 8.0) ** 2
    )
    return mass, i_trans, i_axial


def palm_inertia(R: float, depth: float) -> tuple[float, float, float]:
    """Mass, axial (x) and transverse inertia of the solid palm cylinder (axis along +x)."""
    mass = DENSITY * math.pi * R * R * depth
    return mass, mass * R * R / 2.0, mass * (3.0 * R * R + depth * depth) / 12.0


def _capsule(r: float, L: float) -> CapsuleSpec:
    m, it, ia = capsule_inertia(r, L)
    return CapsuleSpec(
        r=fmt(r),
        cyl=fmt(max(L - 2.0 * r, 0.0)),
        half=fmt(L / 2.0),
        top=fmt(L - r),
        inertia=Inertia(fmt(m), fmt(it), fmt(it), fmt(ia)),
    )


@lru_cache(maxsize=1)
def _environment() -> jinja2.Environment:
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(templates_dir())),
        trim_blocks=True,
        lstrip_blocks=True,
        undefined=jinja2.StrictUndefined,
        keep_trailing_newline=True,
    )
    return env


def template_name(params: Params) -> str:
    """Template file used for these params (``base``, ``extended`` or ``leap`` flavour)."""
    if isinstance(params, BaseParams):
        return "base.urdf.j2"
    return "leap.urdf.j2" if params.template == "leap" else "extended.urdf.j2"


def palm_geometry(params: Params) -> tuple[float, float]:
    """Palm cylinder ``(radius, depth)`` in metres: depth is the thickest finger's diameter."""
    if isinstance(params, BaseParams):
        rmax = params.finger_radius if params.num_fingers else 0.0
    else:
        radii = params.finger_radii[params.present_fingers]
        rmax = float(radii.max()) if radii.size else 0.0
    return params.palm_radius, max(2.0 * rmax, MIN_PALM_DEPTH)


def _context(params: Params, robot_name: str) -> dict[str, Any]:
    a = params.present_joints.tolist()
    R, depth = palm_geometry(params)
    pm, pix, pit = palm_inertia(R, depth)
    ctx: dict[str, Any] = {
        "robot_name": robot_name,
        "form": params.form if not isinstance(params, ExtendedParams) or params.template == "extended" else "leap-variant",
        "a": a,
        "lo": [fmt(x) for x in params.joint_lowers],
        "up": [fmt(x) for x in params.joint_uppers],
        "links": params.link_presence(),
        "fingers": params.present_fingers.tolist(),
        "finger_lengths": params.finger_lengths.tolist(),
        "PALM": {"r": fmt(R), "depth": fmt(depth), "inertia": Inertia(fmt(pm), fmt(pix), fmt(pit), fmt(pit))},
        "DUMMY": Inertia(fmt(DUMMY_MASS), fmt(DUMMY_INERTIA), fmt(DUMMY_INERTIA), fmt(DUMMY_INERTIA)),
        "EFFORT": fmt(EFFORT),
        "VELOCITY": fmt(VELOCITY),
        "HALF_PI": fmt(math.pi / 2.0),
        "v": fmt_vec,
        "z": lambda d: fmt_vec((0.0, 0.0, d)),
        "capsule": lambda r, L: _capsule(float(r), float(L)),
    }
    if isinstance(params, BaseParams):
        e = params.little_extra_origin
        ctx.update(
            finger_radius=params.finger_radius,
            finger_xyz=params.finger_xyz.tolist(),
            thumb_rpy=params.thumb_rpy.tolist(),
            thumb_axes=params.thumb_axes.tolist(),
            little_extra_origin=e.tolist(),
            little_knuckle_xyz=rpy_to_matrix(e[3:]).T @ (params.finger_xyz[4] - e[:3]),
            little_knuckle_rpy=inverse_rpy(e[3:]),
        )
    else:
        o = params.joint_origins
        ctx.update(
            finger_radii=params.finger_radii.tolist(),
            o=o.tolist(),
            ax=params.joint_axes.tolist(),
            little_knuckle_xyz=rpy_to_matrix(o[9, 3:]).T @ (o[10, :3] - o[9, :3]),
            little_base_inverse_rpy=inverse_rpy(o[9, 3:]),
        )
    return ctx


def render(params: Params, robot_name: str = "canonical_hand") -> str:
    """Canonical URDF text of ``params`` (deterministic: same params, same bytes).

    Args:
        params: base or extended params (lengths [m], angles [rad], palm frame).
        robot_name: the ``<robot name>``.

    Returns:
        URDF text: root link ``world``, fixed to ``palm`` (the palm frame); lengths [m], masses [kg],
        limits [rad]; ends with one newline.

    Raises:
        ParamsError: ``params`` is not :class:`BaseParams` or :class:`ExtendedParams` (a hand name: resolve it
            with :func:`ohra.get_hand` first).
    """
    require_params(params)
    tpl = _environment().get_template(template_name(params))
    text = tpl.render(**_context(params, escape(str(robot_name), {'"': "&quot;"})))  # a file stem may hold & < "
    # Blank lines left by conditional blocks carry no meaning; drop them for compact files.
    return "\n".join(line for line in text.splitlines() if line.strip()) + "\n"


def write(params: Params, path: str | Path, robot_name: str = "canonical_hand") -> Path:
    """Render (:func:`render`) and write atomically to ``path``, creating parent folders.

    Args:
        params: base or extended params.
        path: the ``.urdf`` file to write (replaced if present).
        robot_name: the ``<robot name>``.

    Returns:
        ``path`` as a :class:`~pathlib.Path`.
    """
    return write_text(path, render(params, robot_name))
