"""Canonical hand parameters: the base form (82 numbers) and the extended form (173 numbers).

Both forms describe the same 22-joint, five-finger template (see ``DESIGN.md``). All lengths are
in metres and all angles in radians; positions and orientations are expressed in the canonical
palm frame (+x palm normal, +y thumb side of a right hand, +z finger-forward, origin at the wrist
edge of the palm disc).

JSON files use the reference key names and shapes (joint limits as ragged lists ``[5,4,4,4,5]``,
extended joint origins/axes as ragged lists ``[3,2,2,2,3]``), are written in canonical key order
and are read in any key order. Every constructor validates; invalid input raises
:class:`ohra.ParamsError` naming the key and the flat index of the offending value.

Why one module of ~700 lines: the two forms are the reference file format, each a dataclass whose
validation, JSON round trip and conversion into the other form read the same field list; split
apart, a field added to one form would have to be changed in three files.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Mapping, Union

import numpy as np

from ohra.errors import ParamsError
from ohra.io import write_text
from ohra.transforms import inverse_rpy

FINGERS: tuple[str, ...] = ("thumb", "index", "middle", "ring", "little")
JOINTS_PER_FINGER: tuple[int, ...] = (5, 4, 4, 4, 5)
JOINT_NAMES: tuple[str, ...] = (
    *(f"thumb_joint{i}" for i in range(1, 6)),
    *(f"index_joint{i}" for i in range(1, 5)),
    *(f"middle_joint{i}" for i in range(1, 5)),
    *(f"ring_joint{i}" for i in range(1, 5)),
    *(f"little_joint{i}" for i in range(0, 5)),
)
FINGER_SLICES: dict[str, slice] = {
    "thumb": slice(0, 5),
    "index": slice(5, 9),
    "middle": slice(9, 13),
    "ring": slice(13, 17),
    "little": slice(17, 22),
}
JOINT_INDEX: dict[str, int] = {n: i for i, n in enumerate(JOINT_NAMES)}

# Rows of the extended joint_origins / joint_axes tables, and the canonical joint each row belongs to.
EXT_ROWS_PER_FINGER: tuple[int, ...] = (3, 2, 2, 2, 3)
EXT_ROW_JOINTS: tuple[str, ...] = (
    "thumb_joint1", "thumb_joint2", "thumb_joint3",
    "index_joint1", "index_joint2",
    "middle_joint1", "middle_joint2",
    "ring_joint1", "ring_joint2",
    "little_joint0", "little_joint1", "little_joint2",
)
EXT_ROW_START: tuple[int, ...] = (0, 3, 5, 7, 9)

# Physical plausibility bounds (a hand is a hand: nothing here is bigger than a dinner plate).
MAX_RADIUS = 0.2  # m, palm or finger radius
MAX_LENGTH = 0.5  # m, link length
MAX_POSITION = 0.5  # m, |coordinate| of any joint origin in the palm frame
MAX_ANGLE = 2.0 * math.pi + 1e-6  # rad, |joint limit| and |rpy component|
AXIS_UNIT_TOL = 1e-3
# m: the least gap between capsules of different fingers; synthesis keeps it in every grasp
# (ohra.synth.nlp.NLPSettings.finger_gap) and the parser keeps a fitted hand's fingers that far apart at rest
FINGER_GAP = 0.001


def _split(values: np.ndarray, counts: tuple[int, ...]) -> list[Any]:
    """Ragged split of a flat (or row) array into nested Python lists, as in reference JSON files."""
    out, k = [], 0
    for c in counts:
        out.append(np.asarray(values[k : k + c]).tolist())
        k += c
    return out


def _clean(x: Any) -> Any:
    """Nested lists of plain floats, with -0.0 written as 0.0 (deterministic JSON)."""
    if isinstance(x, list):
        return [_clean(v) for v in x]
    v = float(x)
    return 0.0 if v == 0.0 else v


def _as_array(d: Mapping[str, Any], key: str, shape: tuple[int, ...], ragged: tuple[int, ...] | None = None) -> np.ndarray:
    """Read ``d[key]`` as a float array of ``shape`` (flattening a ragged list if given)."""
    if key not in d:
        raise ParamsError(f"missing key {key!r}")
    raw = d[key]
    try:
        if ragged is not None and isinstance(raw, (list, tuple)) and len(raw) == len(ragged) and all(
            isinstance(r, (list, tuple, np.ndarray)) for r in raw
        ):
            lens = tuple(len(r) for r in raw)
            if lens != ragged:
                raise ParamsError(f"{key!r}: expected rows of lengths {list(ragged)}, got {list(lens)}")
            parts = [np.asarray(r, dtype=float).reshape(len(r), -1) for r in raw]
            arr = np.concatenate(parts, axis=0)
            if len(shape) == 1:
                arr = arr.reshape(-1)
        else:
            arr = np.asarray(raw, dtype=float)
    except ParamsError:
        raise
    except (TypeError, ValueError) as exc:
        raise ParamsError(f"{key!r}: not a numeric array of shape {shape} ({exc})") from None
    if arr.shape != shape:
        raise ParamsError(f"{key!r}: expected shape {shape}, got {arr.shape}")
    return arr.copy()


def _as_float(d: Mapping[str, Any], key: str) -> float:
    if key not in d:
        raise ParamsError(f"missing key {key!r}")
    raw = d[key]
    if isinstance(raw, (list, tuple)) and len(raw) == 1:
        raw = raw[0]
    try:
        return float(raw)
    except (TypeError, ValueError):
        raise ParamsError(f"{key!r}: expected a number, got {raw!r}") from None


class _Checker:
    """Collects the flat index of each key so that errors can name key and index."""

    def __init__(self, params: "Params"):
        self.params = params

    @staticmethod
    def _at(key: str, arr: np.ndarray, flat_index: int) -> str:
        """``'finger_xyz'[1][2]``: the index as the key is written in JSON and spec overrides (not ``[5]``)."""
        shape = np.shape(arr) or (1,)
        return f"{key!r}" + "".join(f"[{int(k)}]" for k in np.unravel_index(flat_index, shape))

    def finite(self, key: str, arr: np.ndarray) -> None:
        bad = np.flatnonzero(~np.isfinite(np.asarray(arr, dtype=float).reshape(-1)))
        if bad.size:
            raise ParamsError(f"{self._at(key, arr, int(bad[0]))} is not finite ({np.asarray(arr).reshape(-1)[bad[0]]})")

    def range(self, key: str, arr: np.ndarray, lo: float, hi: float, what: str) -> None:
        flat = np.asarray(arr, dtype=float).reshape(-1)
        bad = np.flatnonzero((flat < lo) | (flat > hi))
        if bad.size:
            i = int(bad[0])
            raise ParamsError(f"{self._at(key, arr, i)} = {flat[i]:g} is outside {what} [{lo:g}, {hi:g}]")


def _check_limits(chk: _Checker, lowers: np.ndarray, uppers: np.ndarray) -> None:
    chk.finite("joint_lowers", lowers)
    chk.finite("joint_uppers", uppers)
    chk.range("joint_lowers", lowers, -MAX_ANGLE, MAX_ANGLE, "joint angle bounds")
    chk.range("joint_uppers", uppers, -MAX_ANGLE, MAX_ANGLE, "joint angle bounds")
    bad = np.flatnonzero(lowers > uppers)
    if bad.size:
        i = int(bad[0])
        raise ParamsError(
            f"joint_lowers[{i}] = {lowers[i]:g} > joint_uppers[{i}] = {uppers[i]:g} ({JOINT_NAMES[i]})"
        )


def _check_axis(key: str, index: int, axis: np.ndarray, joint: str) -> None:
    n = float(np.linalg.norm(axis))
    if n < 1e-12:
        raise ParamsError(f"{key!r}[{index}] is a zero axis but {joint} is present")
    if abs(n - 1.0) > AXIS_UNIT_TOL:
        raise ParamsError(f"{key!r}[{index}] = {np.round(axis, 6).tolist()} is not a unit axis (norm {n:.6g}) for {joint}")


def _check_capsule(key: str, index: int, length: float, radius: float, link: str) -> None:
    if length < 2.0 * radius - 1e-9:
        raise ParamsError(
            f"{key!r}[{index}] = {length:g} m: capsule {link} is shorter than its diameter "
            f"2*'finger_radius' = 2*{radius:g} m (one of the two keys is wrong)"
        )


def present_mask(lowers: np.ndarray, uppers: np.ndarray) -> np.ndarray:
    """Present joints by the template rule: limits not both zero."""
    return (np.asarray(lowers) != 0.0) | (np.asarray(uppers) != 0.0)


def segment_mask(present: np.ndarray, template: str = "standard") -> np.ndarray:
    """Which (proximal, middle, distal) links carry geometry: joint presence (..., 22) -> (..., 5, 3) bool.

    Rules of the canonical templates (reference §2.2-2.4): thumb proximal iff j1 or j2, middle iff
    j3 or j4, distal iff j5. Other fingers: proximal iff j1 or j2, middle iff j3, distal iff j4
    (the little finger's joints 1-4: little_joint0 is the extra metacarpal joint and carries no
    segment). In the LEAP flavour (abduction after flexion): proximal iff j1, middle iff j2 or j3,
    distal iff j4. The one definition of these rules; batched for the learning code.
    """
    p = np.asarray(present, dtype=bool)
    if p.shape[-1] != 22:
        raise ParamsError(f"joint presence must have 22 entries in its last axis, got shape {p.shape}")
    out = np.zeros(p.shape[:-1] + (5, 3), dtype=bool)
    out[..., 0, :] = np.stack([p[..., 0] | p[..., 1], p[..., 2] | p[..., 3], p[..., 4]], axis=-1)
    for fi, f in enumerate(FINGERS[1:], start=1):
        j = p[..., FINGER_SLICES[f]]
        if f == "little":
            j = j[..., 1:]
        if template == "leap":
            out[..., fi, :] = np.stack([j[..., 0], j[..., 1] | j[..., 2], j[..., 3]], axis=-1)
        else:
            out[..., fi, :] = np.stack([j[..., 0] | j[..., 1], j[..., 2], j[..., 3]], axis=-1)
    return out


def link_presence(present: np.ndarray, template: str = "standard") -> dict[str, tuple[bool, bool, bool]]:
    """:func:`segment_mask` of one hand as ``{finger: (proximal, middle, distal)}``."""
    m = segment_mask(present, template)
    return {f: (bool(m[fi, 0]), bool(m[fi, 1]), bool(m[fi, 2])) for fi, f in enumerate(FINGERS)}


class _ParamsMixin:
    """Behaviour shared by both forms."""

    form: ClassVar[str]
    SIZE: ClassVar[int]
    KEYS: ClassVar[tuple[tuple[str, tuple[int, ...]], ...]]  # (key, shape) in canonical key order
    RAGGED: ClassVar[Mapping[str, tuple[int, ...]]]  # key -> rows per finger of its per-finger JSON lists
    joint_lowers: np.ndarray
    joint_uppers: np.ndarray

    # -- conversion --------------------------------------------------------------------------
    def _coerce(self) -> None:
        """Turn every key's value into a float (shape ``()``) or a float array of its shape, in key
        order (so the first bad key is the one named); per-finger lists are accepted for the keys
        of ``RAGGED``."""
        d = {k: getattr(self, k) for k, _ in self.KEYS}
        for key, shape in self.KEYS:
            setattr(self, key, _as_float(d, key) if shape == () else _as_array(d, key, shape, self.RAGGED.get(key)))

    @classmethod
    def _key_values(cls, d: Mapping[str, Any], also: frozenset[str] = frozenset()) -> dict[str, Any]:
        """The values of ``cls.KEYS`` in mapping ``d``; a key that is neither one of them nor in
        ``also`` (handled by the caller), or a missing one, raises :class:`ParamsError`."""
        if not isinstance(d, Mapping):
            raise ParamsError(f"expected a mapping of parameter keys, got {type(d).__name__}")
        extra = sorted(set(d) - {k for k, _ in cls.KEYS} - also)
        if extra:
            raise ParamsError(f"unknown key(s) for {cls.form} params: {extra}")
        missing = [k for k, _ in cls.KEYS if k not in d]
        if missing:
            raise ParamsError(f"missing key {missing[0]!r}")
        return {k: d[k] for k, _ in cls.KEYS}

    def _key_dict(self) -> dict[str, Any]:
        """Every key as plain JSON values in key order (per-finger lists for the ``RAGGED`` keys)."""
        out: dict[str, Any] = {}
        for key, shape in self.KEYS:
            v = getattr(self, key)
            out[key] = _clean(v if shape == () else _split(v, self.RAGGED[key]) if key in self.RAGGED else v.tolist())
        return out

    def to_vector(self) -> np.ndarray:
        """Flat (SIZE,) vector in canonical key order (an extended hand's template flavour is not part of it)."""
        return np.concatenate([np.atleast_1d(np.asarray(getattr(self, k), dtype=float)).reshape(-1) for k, _ in self.KEYS])

    # -- masks -------------------------------------------------------------------------------
    @property
    def present_joints(self) -> np.ndarray:
        """(22,) bool: joint is present (limits not both zero)."""
        return present_mask(self.joint_lowers, self.joint_uppers)

    @property
    def movable_joints(self) -> np.ndarray:
        """(22,) bool: joint can move (upper > lower)."""
        return np.asarray(self.joint_uppers) > np.asarray(self.joint_lowers)

    @property
    def present_fingers(self) -> np.ndarray:
        """(5,) bool: finger has at least one segment with geometry."""
        links = self.link_presence()
        return np.array([any(links[f]) for f in FINGERS])

    @property
    def num_fingers(self) -> int:
        return int(self.present_fingers.sum())

    @property
    def dof(self) -> int:
        """Number of movable canonical joints."""
        return int(self.movable_joints.sum())

    def link_presence(self) -> dict[str, tuple[bool, bool, bool]]:
        return link_presence(self.present_joints, getattr(self, "template", "standard"))

    # -- serialisation -----------------------------------------------------------------------
    def to_json(self, path: str | Path | None = None) -> str:
        """JSON text in canonical key order (lists of lists as in the reference files); optionally written."""
        d = self.to_dict()
        lines = ["{"]
        items = list(d.items())
        for k, (key, val) in enumerate(items):
            comma = "," if k < len(items) - 1 else ""
            lines.append(f"  {json.dumps(key)}: {json.dumps(val)}{comma}")
        lines.append("}")
        text = "\n".join(lines) + "\n"
        if path is not None:
            write_text(path, text)  # atomic, mode from the umask
        return text

    @classmethod
    def from_json(cls, source: str | Path):
        """Read from a JSON file path or JSON text."""
        d, where = _read_json_object(source)
        try:
            return cls.from_dict(_without_couplings(d, where))
        except ParamsError as exc:
            raise ParamsError(f"{where}: {exc}") from None

    def isclose(self, other: object, atol: float = 1e-9) -> bool:
        """Same form and every number within ``atol``."""
        if type(other) is not type(self):
            return False
        if getattr(self, "template", None) != getattr(other, "template", None):
            return False
        return bool(np.allclose(self.to_vector(), other.to_vector(), rtol=0.0, atol=atol))  # type: ignore[attr-defined]

    def __eq__(self, other: object) -> bool:
        return self.isclose(other, atol=1e-12)

    __hash__ = None  # type: ignore[assignment]

    def copy(self):
        return type(self).from_dict(self.to_dict())


def _read_json_object(source: str | Path) -> tuple[dict[str, Any], str]:
    """The JSON object in a file (a path, or a string not starting with ``{``) or in JSON text, and
    where it came from (the path or ``"<json text>"``, for messages)."""
    if isinstance(source, Path) or (isinstance(source, str) and not source.lstrip().startswith("{")):
        p = Path(source)
        if not p.is_file():
            raise ParamsError(f"params file not found: {p}")
        if p.suffix.lower() in (".urdf", ".xacro", ".xml"):
            raise ParamsError(f"{p}: a URDF is not a hand ohra can use directly: describe it in a spec YAML and parse "
                              "it (ohra hand parse SPEC.yaml -o params.json; README: Add your own hand), then give "
                              "the spec or the params JSON")
        try:
            text, where = p.read_text(), str(p)
        except UnicodeDecodeError:
            raise ParamsError(f"{p}: not a params JSON file (not text)") from None
    else:
        text, where = str(source), "<json text>"
    try:
        d = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ParamsError(f"{where}: malformed JSON ({exc})") from None
    if not isinstance(d, dict):
        raise ParamsError(f"{where}: expected a JSON object, got {type(d).__name__}")
    return d, where


@dataclass(eq=False)
class BaseParams(_ParamsMixin):
    """Base canonical parameters (82 numbers; one radius, shared non-thumb finger lengths).

    Attributes (metres / radians, canonical palm frame):
        palm_radius: palm disc radius.
        finger_radius: capsule radius of every finger segment.
        finger_lengths: (2, 3) thumb (proximal, middle, distal) and shared non-thumb lengths.
        finger_xyz: (5, 3) thumb base and finger knuckle positions (absent fingers: zeros).
        little_extra_origin: (6,) xyz + fixed-axis rpy of the little-finger metacarpal joint frame.
        thumb_rpy: (3,) fixed-axis rpy of the thumb base frame (the thumb points along its +z).
        thumb_axes: (2, 3) axes of thumb_joint1 and thumb_joint2 in the thumb base frame.
        joint_lowers, joint_uppers: (22,) limits in canonical joint order.
    """

    palm_radius: float
    finger_radius: float
    finger_lengths: np.ndarray
    finger_xyz: np.ndarray
    little_extra_origin: np.ndarray
    thumb_rpy: np.ndarray
    thumb_axes: np.ndarray
    joint_lowers: np.ndarray
    joint_uppers: np.ndarray

    form: ClassVar[str] = "base"
    SIZE: ClassVar[int] = 82
    KEYS: ClassVar[tuple[tuple[str, tuple[int, ...]], ...]] = (
        ("palm_radius", ()),
        ("finger_radius", ()),
        ("finger_lengths", (2, 3)),
        ("finger_xyz", (5, 3)),
        ("little_extra_origin", (6,)),
        ("thumb_rpy", (3,)),
        ("thumb_axes", (2, 3)),
        ("joint_lowers", (22,)),
        ("joint_uppers", (22,)),
    )
    RAGGED: ClassVar[Mapping[str, tuple[int, ...]]] = {"joint_lowers": JOINTS_PER_FINGER, "joint_uppers": JOINTS_PER_FINGER}

    def __post_init__(self) -> None:
        self._coerce()
        self.validate()

    # -- conversion --------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "BaseParams":
        return cls(**cls._key_values(d))

    def to_dict(self) -> dict[str, Any]:
        return self._key_dict()

    @classmethod
    def from_vector(cls, v: Any) -> "BaseParams":
        return cls.from_dict(_unflatten(cls.KEYS, v, cls.SIZE))

    # -- validation --------------------------------------------------------------------------
    def validate(self) -> None:
        """Raise :class:`ParamsError` on the first invalid value (key and flat index named)."""
        chk = _Checker(self)
        for key, _ in self.KEYS:
            chk.finite(key, np.asarray(getattr(self, key)))
        chk.range("palm_radius", np.array([self.palm_radius]), 1e-4, MAX_RADIUS, "radius bounds (m)")
        chk.range("finger_radius", np.array([self.finger_radius]), 1e-4, MAX_RADIUS, "radius bounds (m)")
        chk.range("finger_lengths", self.finger_lengths, 0.0, MAX_LENGTH, "length bounds (m)")
        chk.range("finger_xyz", self.finger_xyz, -MAX_POSITION, MAX_POSITION, "position bounds (m)")
        chk.range("little_extra_origin", self.little_extra_origin[:3], -MAX_POSITION, MAX_POSITION, "position bounds (m)")
        chk.range("little_extra_origin", self.little_extra_origin[3:], -MAX_ANGLE, MAX_ANGLE, "angle bounds (rad)")
        chk.range("thumb_rpy", self.thumb_rpy, -MAX_ANGLE, MAX_ANGLE, "angle bounds (rad)")
        chk.range("thumb_axes", self.thumb_axes, -1.0 - AXIS_UNIT_TOL, 1.0 + AXIS_UNIT_TOL, "axis component bounds")
        _check_limits(chk, self.joint_lowers, self.joint_uppers)
        present = self.present_joints
        for k in range(2):
            if present[k]:
                _check_axis("thumb_axes", 3 * k, self.thumb_axes[k], JOINT_NAMES[k])
        links = self.link_presence()
        names = ("proximal", "middle", "distal")
        for fi, f in enumerate(FINGERS):
            row = 0 if f == "thumb" else 1
            for s in range(3):
                if links[f][s]:
                    length = float(self.finger_lengths[row, s])
                    _check_capsule("finger_lengths", 3 * row + s, length, self.finger_radius, f"{f}_{names[s]}")
            if any(links[f]) and not np.any(self.finger_xyz[fi]):
                raise ParamsError(
                    f"'finger_xyz'[{3 * fi}] : finger {f!r} has links but no base joint position (finger_xyz[{fi}] is zero)"
                )

    # -- forms -------------------------------------------------------------------------------
    @property
    def handedness(self) -> str:
        """'right' when the thumb sits on +y of the palm frame (or, thumbless, the little finger on -y)."""
        return _handedness(self.finger_xyz[:, 1], self.present_fingers)

    def to_extended(self) -> "ExtendedParams":
        """The same hand in the extended form (renders to the same kinematics and geometry)."""
        r = self.finger_radius
        present_f = self.present_fingers
        radii = np.where(present_f, r, 0.0)
        lengths = np.vstack([self.finger_lengths[0], np.tile(self.finger_lengths[1], (4, 1))])
        origins = np.zeros((12, 6))
        axes = np.zeros((12, 3))
        p = self.present_joints
        # thumb: j1 at the thumb base; base collapses the proximal offset when j1, j2 are absent,
        # the extended template always adds finger_lengths[0][0] to the j3 origin: cancel it.
        origins[0, :3], origins[0, 3:] = self.finger_xyz[0], self.thumb_rpy
        axes[0] = self.thumb_axes[0] if p[0] else (1.0, 0.0, 0.0)
        axes[1] = self.thumb_axes[1] if p[1] else (0.0, 1.0, 0.0)
        if not (p[0] or p[1]):
            origins[2, 2] = -self.finger_lengths[0, 0]
        axes[2] = (1.0, 0.0, 0.0)
        for fi in (1, 2, 3):
            row = EXT_ROW_START[fi]
            origins[row, :3] = self.finger_xyz[fi]
            axes[row] = (1.0, 0.0, 0.0)
            axes[row + 1] = (0.0, 1.0, 0.0)
        e = self.little_extra_origin
        origins[9] = e
        axes[9] = (0.0, 1.0, 0.0)
        origins[10, :3] = self.finger_xyz[4]
        origins[10, 3:] = inverse_rpy(e[3:])
        axes[10] = (1.0, 0.0, 0.0)
        axes[11] = (0.0, 1.0, 0.0)
        return ExtendedParams(
            palm_radius=self.palm_radius,
            finger_radii=radii,
            finger_lengths=lengths,
            joint_origins=origins,
            joint_axes=axes,
            joint_lowers=self.joint_lowers.copy(),
            joint_uppers=self.joint_uppers.copy(),
        )

    def to_base(self) -> "BaseParams":
        return self.copy()


@dataclass(eq=False)
class ExtendedParams(_ParamsMixin):
    """Extended canonical parameters (173 numbers; per-finger radii, lengths, joint origins and axes).

    Attributes (metres / radians):
        palm_radius: palm disc radius.
        finger_radii: (5,) capsule radius per finger (0 for an absent finger).
        finger_lengths: (5, 3) proximal, middle, distal length per finger.
        joint_origins: (12, 6) xyz + fixed-axis rpy, rows thumb j1, j2, j3 | index j1, j2 | middle j1, j2 |
            ring j1, j2 | little j0, j1, j2 (see ``EXT_ROW_JOINTS``). Thumb j1, finger j1 and little j0
            are in the palm frame; little j1 xyz is a palm-frame position with rpy relative to the
            metacarpal frame; the others are relative to their parent frame.
        joint_axes: (12, 3) joint axes of the same rows.
        joint_lowers, joint_uppers: (22,) limits in canonical joint order.
        template: ``"extended"`` or ``"leap"`` (LEAP flavour: flexion at the palm, abduction after it).
    """

    palm_radius: float
    finger_radii: np.ndarray
    finger_lengths: np.ndarray
    joint_origins: np.ndarray
    joint_axes: np.ndarray
    joint_lowers: np.ndarray
    joint_uppers: np.ndarray
    template: str = field(default="extended")

    form: ClassVar[str] = "extended"
    SIZE: ClassVar[int] = 173
    TEMPLATES: ClassVar[tuple[str, ...]] = ("extended", "leap")
    KEYS: ClassVar[tuple[tuple[str, tuple[int, ...]], ...]] = (
        ("palm_radius", ()),
        ("finger_radii", (5,)),
        ("finger_lengths", (5, 3)),
        ("joint_origins", (12, 6)),
        ("joint_axes", (12, 3)),
        ("joint_lowers", (22,)),
        ("joint_uppers", (22,)),
    )
    RAGGED: ClassVar[Mapping[str, tuple[int, ...]]] = {
        "joint_origins": EXT_ROWS_PER_FINGER, "joint_axes": EXT_ROWS_PER_FINGER,
        "joint_lowers": JOINTS_PER_FINGER, "joint_uppers": JOINTS_PER_FINGER,
    }

    def __post_init__(self) -> None:
        self._coerce()
        if self.template not in self.TEMPLATES:
            raise ParamsError(f"'template': expected one of {list(self.TEMPLATES)}, got {self.template!r}")
        self.validate()

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "ExtendedParams":
        return cls(**cls._key_values(d, also=frozenset({"template"})), template=str(d.get("template", "extended")))

    def to_dict(self) -> dict[str, Any]:
        d = self._key_dict()
        if self.template != "extended":
            d["template"] = self.template
        return d

    @classmethod
    def from_vector(cls, v: Any, template: str = "extended") -> "ExtendedParams":
        d = _unflatten(cls.KEYS, v, cls.SIZE)
        d["template"] = template
        return cls.from_dict(d)

    def validate(self) -> None:
        """Raise :class:`ParamsError` on the first invalid value (key and flat index named)."""
        chk = _Checker(self)
        for key, _ in self.KEYS:
            chk.finite(key, np.asarray(getattr(self, key)))
        chk.range("palm_radius", np.array([self.palm_radius]), 1e-4, MAX_RADIUS, "radius bounds (m)")
        chk.range("finger_radii", self.finger_radii, 0.0, MAX_RADIUS, "radius bounds (m)")
        chk.range("finger_lengths", self.finger_lengths, 0.0, MAX_LENGTH, "length bounds (m)")
        for r in range(12):
            for c in range(6):
                v = self.joint_origins[r, c]
                lim = MAX_POSITION if c < 3 else MAX_ANGLE
                if abs(v) > lim:
                    raise ParamsError(f"'joint_origins'[{6 * r + c}] = {v:g} is outside bounds [{-lim:g}, {lim:g}] ({EXT_ROW_JOINTS[r]})")
        chk.range("joint_axes", self.joint_axes, -1.0 - AXIS_UNIT_TOL, 1.0 + AXIS_UNIT_TOL, "axis component bounds")
        _check_limits(chk, self.joint_lowers, self.joint_uppers)
        present = self.present_joints
        for r, jn in enumerate(EXT_ROW_JOINTS):
            if present[JOINT_INDEX[jn]]:
                _check_axis("joint_axes", 3 * r, self.joint_axes[r], jn)
        links = self.link_presence()
        names = ("proximal", "middle", "distal")
        for fi, f in enumerate(FINGERS):
            if not any(links[f]):
                continue
            radius = float(self.finger_radii[fi])
            if radius < 1e-4:
                raise ParamsError(f"'finger_radii'[{fi}] = {radius:g}: finger {f!r} has links but no radius")
            for s in range(3):
                if links[f][s]:
                    _check_capsule("finger_lengths", 3 * fi + s, float(self.finger_lengths[fi, s]), radius, f"{f}_{names[s]}")
            base_row = EXT_ROW_START[fi] + (1 if f == "little" else 0)
            if not np.any(self.joint_origins[base_row, :3]):
                raise ParamsError(
                    f"'joint_origins'[{6 * base_row}] : finger {f!r} has links but no base joint position "
                    f"({EXT_ROW_JOINTS[base_row]} origin is zero)"
                )

    @property
    def handedness(self) -> str:
        ys = np.array([self.joint_origins[EXT_ROW_START[fi] + (1 if f == "little" else 0), 1] for fi, f in enumerate(FINGERS)])
        return _handedness(ys, self.present_fingers)

    def to_extended(self) -> "ExtendedParams":
        return self.copy()

    def to_base(self) -> BaseParams:
        """The same hand in the base form; :class:`ParamsError` says why when it is not representable."""
        if self.template != "extended":
            raise ParamsError(f"extended params with template {self.template!r} have no base-form equivalent")
        present_f = self.present_fingers
        radii = self.finger_radii[present_f]
        if radii.size == 0:
            radii = self.finger_radii[self.finger_radii > 0]
        r = float(radii[0]) if radii.size else 0.01
        if radii.size and np.ptp(radii) > 1e-9:
            raise ParamsError(f"not representable in base form: 'finger_radii' differ between fingers ({radii.tolist()})")
        nonthumb = [fi for fi in range(1, 5) if present_f[fi]] or [1]
        fl_f = self.finger_lengths[nonthumb[0]]
        for fi in nonthumb:
            if not np.allclose(self.finger_lengths[fi], fl_f, atol=1e-9):
                raise ParamsError(
                    f"not representable in base form: 'finger_lengths' of {FINGERS[fi]} differ from {FINGERS[nonthumb[0]]}"
                )
        o, a, p = self.joint_origins, self.joint_axes, self.present_joints

        def need(cond: bool, what: str) -> None:
            if not cond:
                raise ParamsError(f"not representable in base form: {what}")

        need(not np.any(o[1]), "thumb_joint2 origin is not zero")
        j3_expected = -self.finger_lengths[0, 0] if not (p[0] or p[1]) else 0.0
        need(np.allclose(o[2], [0, 0, j3_expected, 0, 0, 0], atol=1e-9), "thumb_joint3 origin is not the default")
        need(not p[2] or np.allclose(a[2], [1, 0, 0]), "thumb_joint3 axis is not +x")
        for fi in (1, 2, 3):
            row = EXT_ROW_START[fi]
            need(not np.any(o[row, 3:]) and not np.any(o[row + 1]), f"{FINGERS[fi]} joint origins are not palm-aligned")
            need(not p[JOINT_INDEX[f"{FINGERS[fi]}_joint1"]] or np.allclose(a[row], [1, 0, 0]), f"{FINGERS[fi]}_joint1 axis is not +x")
            need(not p[JOINT_INDEX[f"{FINGERS[fi]}_joint2"]] or np.allclose(a[row + 1], [0, 1, 0]), f"{FINGERS[fi]}_joint2 axis is not +y")
        need(not p[17] or np.allclose(a[9], [0, 1, 0]), "little_joint0 axis is not +y")
        need(np.allclose(o[10, 3:], inverse_rpy(o[9, 3:]), atol=1e-9), "little_joint1 rpy is not the inverse of little_joint0 rpy")
        need(not p[18] or np.allclose(a[10], [1, 0, 0]), "little_joint1 axis is not +x")
        need(not p[19] or np.allclose(a[11], [0, 1, 0]), "little_joint2 axis is not +y")
        need(not np.any(o[11]), "little_joint2 origin is not zero")
        finger_xyz = np.vstack([o[0, :3], o[3, :3], o[5, :3], o[7, :3], o[10, :3]])
        thumb_axes = np.vstack([a[0] if p[0] else np.zeros(3), a[1] if p[1] else np.zeros(3)])
        return BaseParams(
            palm_radius=self.palm_radius,
            finger_radius=r,
            finger_lengths=np.vstack([self.finger_lengths[0], fl_f]),
            finger_xyz=finger_xyz,
            little_extra_origin=o[9].copy(),
            thumb_rpy=o[0, 3:].copy(),
            thumb_axes=thumb_axes,
            joint_lowers=self.joint_lowers.copy(),
            joint_uppers=self.joint_uppers.copy(),
        )


# either form of the canonical parameters: the one alias every module annotates with
Params = Union[BaseParams, ExtendedParams]


# A base position this close to the palm's x-z plane is on it: parse round-off (Barrett's extended
# thumb sits at y = -1e-6 m) must not decide a hand's side.
SIDE_TOLERANCE = 1e-5  # m


def _handedness(ys: np.ndarray, present: np.ndarray) -> str:
    if present[0] and abs(ys[0]) > SIDE_TOLERANCE:
        return "right" if ys[0] > 0 else "left"
    # Without a thumb off the centre line, the little finger sits on -y of a right hand.
    if present[4] and abs(ys[4]) > SIDE_TOLERANCE:
        return "right" if ys[4] < 0 else "left"
    if present[1] and abs(ys[1]) > SIDE_TOLERANCE:
        return "right" if ys[1] > 0 else "left"
    return "right"


def _unflatten(keys: tuple[tuple[str, tuple[int, ...]], ...], v: Any, size: int) -> dict[str, Any]:
    try:
        arr = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ParamsError(f"expected a numeric vector of length {size}") from None
    if arr.size != size:
        raise ParamsError(f"expected a vector of length {size}, got {arr.size}")
    out: dict[str, Any] = {}
    k = 0
    for key, shape in keys:
        n = int(np.prod(shape)) if shape else 1
        out[key] = arr[k : k + n].reshape(shape) if shape else float(arr[k])
        k += n
    return out


def _without_couplings(d: dict[str, Any], where: str) -> dict[str, Any]:
    """``d`` without the optional ``"couplings"`` key (validated here; read with
    :func:`ohra.canonical.couplings.read_couplings`). Reference files have no such key."""
    if "couplings" not in d:
        return d
    from ohra.canonical.couplings import couplings_from_json_value

    couplings_from_json_value(d["couplings"], where)
    return {k: v for k, v in d.items() if k != "couplings"}


def load_params(source: str | Path | Mapping[str, Any]) -> BaseParams | ExtendedParams:
    """Load params of either form from a JSON path, JSON text or dict; the form is detected by its keys."""
    if isinstance(source, Mapping):
        d, where = dict(source), "<dict>"
    else:
        d, where = _read_json_object(source)
    d = _without_couplings(d, where)
    cls: type[BaseParams] | type[ExtendedParams]
    if "finger_radii" in d or "joint_origins" in d:
        cls = ExtendedParams
    elif "finger_radius" in d or "finger_xyz" in d:
        cls = BaseParams
    else:
        raise ParamsError(f"{where}: cannot tell the form (neither 'finger_radius' nor 'finger_radii' present)")
    try:
        return cls.from_dict(d)
    except ParamsError as exc:
        raise ParamsError(f"{where}: {exc}") from None


def require_params(params: Any) -> None:
    """Raise :class:`ParamsError` unless ``params`` is :class:`BaseParams` or :class:`ExtendedParams`; a hand name
    or path gets a hint to resolve it first."""
    if isinstance(params, (BaseParams, ExtendedParams)):
        return
    hint = f" (a hand name or file: pass ohra.get_hand({str(params)!r}))" if isinstance(params, (str, Path)) else ""
    raise ParamsError(f"expected BaseParams or ExtendedParams, got {type(params).__name__}{hint}")
