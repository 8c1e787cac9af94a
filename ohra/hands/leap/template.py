"""The LEAP-variant template: canonical extended parameters (LEAP flavour) of the full right LEAP hand.

The template is derived from the original URDF by :func:`derive_leap_template` and committed as
``ohra/hands/leap/template.json`` so that variants need no external data. Non-thumb fingers flex at the
palm (j1, axis +y) and abduct 38 mm up the proximal link (j2, axis +x); the ring finger is absent.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from ohra.errors import AssetsNotFoundError
from ohra.canonical.params import ExtendedParams
from ohra.paths import hands_root
from ohra.resources import leap_dir
from ohra.transforms import matrix_to_rpy, xyzrpy_to_matrix

TEMPLATE_JSON = "template.json"
INPUTS_YAML = "template.yaml"


def _round_axis(a: np.ndarray) -> np.ndarray:
    """Snap an axis that is a signed basis axis up to printing noise (1e-4) onto it."""
    b = np.round(a, 4)
    return b + 0.0


def derive_leap_template(urdf: str | Path | None = None) -> ExtendedParams:
    """Measure the LEAP template from the right LEAP hand URDF (Pinocchio forward kinematics at q=0)."""
    import pinocchio as pin

    cfg = yaml.safe_load((leap_dir() / INPUTS_YAML).read_text())
    path = Path(urdf) if urdf is not None else hands_root() / cfg["urdf"]
    if not path.is_file():
        raise AssetsNotFoundError(f"LEAP hand URDF not found: {path} (set OHRA_HANDS_ROOT)")
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    T_palm_root = np.linalg.inv(xyzrpy_to_matrix(cfg["palm_origin"]))

    def frame(name: str) -> tuple[np.ndarray, np.ndarray, float, float]:
        jid = model.getJointId(name)
        T = T_palm_root @ data.oMi[jid].homogeneous
        jm = model.joints[jid]
        short = jm.shortname()
        axis = np.eye(3)["XYZ".index(short[-1])] if short[-1] in "XYZ" else np.asarray(jm.extract().axis)
        iq = jm.idx_q
        return T[:3, 3], T[:3, :3] @ axis, float(model.lowerPositionLimit[iq]), float(model.upperPositionLimit[iq])

    geo = cfg["geometry"]
    r = geo["finger_radius"]
    radii = np.array([r, r, r, 0.0, r])
    lengths = np.zeros((5, 3))
    origins = np.zeros((12, 6))
    axes = np.zeros((12, 3))
    lo = np.zeros(22)
    up = np.zeros(22)

    # Thumb: j1 and j2 share an origin (on j1's axis, nearest j2); the thumb frame's +z points from
    # the MCP (j4) to the IP joint (j5) and its +y is the MCP flexion axis.
    t = cfg["thumb"]
    (p1, a1, l1, u1), (p2, a2, l2, u2) = frame(t["j1"]), frame(t["j2"])
    (p4, a4, l4, u4), (p5, a5, l5, u5) = frame(t["j4"]), frame(t["j5"])
    origin = p1 + a1 * np.dot(p2 - p1, a1)
    z = (p5 - p4) / np.linalg.norm(p5 - p4)
    y = a4 - z * np.dot(a4, z)
    y /= np.linalg.norm(y)
    R = np.column_stack([np.cross(y, z), y, z])
    origins[0, :3], origins[0, 3:] = origin, matrix_to_rpy(R)
    axes[0], axes[1] = _round_axis(R.T @ a1), _round_axis(R.T @ a2)
    prox = float(np.dot(p4 - origin, z))
    origins[2, 2] = prox
    lengths[0] = (prox, float(np.dot(p5 - p4, z)), geo["thumb_distal_length"])
    lo[[0, 1, 3, 4]] = (l1, l2, l4, l5)
    up[[0, 1, 3, 4]] = (u1, u2, u4, u5)

    # Fingers: the finger line is the abduction joint's y; j1 sits on that line at its own x, z.
    for fi, key, row, q0 in ((1, "index", 3, 5), (2, "middle", 5, 9), (4, "little", 10, 18)):
        f = cfg[key]
        (pf, af, lf, uf), (pa, aa, la, ua) = frame(f["flexion"]), frame(f["abduction"])
        (pp, _, lp, upp), (pd, _, ld, ud) = frame(f["pip"]), frame(f["dip"])
        origins[row, :3] = (pf[0], pa[1], pf[2])
        origins[row + 1, 2] = pa[2] - pf[2]
        axes[row], axes[row + 1] = _round_axis(af), _round_axis(aa)
        lengths[fi] = (pp[2] - pf[2], pd[2] - pp[2], geo["finger_distal_length"])
        lo[q0 : q0 + 4] = (lf, la, lp, ld)
        up[q0 : q0 + 4] = (uf, ua, upp, ud)

    return ExtendedParams(
        palm_radius=geo["palm_radius"],
        finger_radii=radii,
        finger_lengths=np.round(lengths, 6),
        joint_origins=np.round(origins, 6) + 0.0,
        joint_axes=axes,
        joint_lowers=lo,
        joint_uppers=up,
        template="leap",
    )


def load_leap_template() -> ExtendedParams:
    """The committed LEAP template (no external data needed)."""
    return ExtendedParams.from_json(leap_dir() / TEMPLATE_JSON)
