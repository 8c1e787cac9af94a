"""The 66-D morphology encoding of base-form hands, and decoding back to valid hands.

Layout (reference §7.2, canonical key order of :class:`ohra.canonical.params.BaseParams`):

=========  ====  ================================================================================
slice      size  content
=========  ====  ================================================================================
[0:32]     32    continuous: palm_radius, finger_radius, finger_lengths (6), finger_xyz (15),
                 little_extra_origin (6), thumb_rpy (3) -- metres / radians
[32:38]    6     one-hot of thumb_axes[0] over (+x, -x, +y, -y, +z, -z); a zero axis encodes as +x
[38:44]    6     one-hot of thumb_axes[1]
[44:66]    22    flags, 1 where joint_lowers != joint_uppers (the VAE's "present" = movable)
=========  ====  ================================================================================

Axes that are not a signed basis axis (fitted real hands, MANO/Sharpa-style thumbs) are snapped to
the nearest one and an :class:`AxisSnapWarning` names them.

Decoding always yields valid params: joint limits come from a given source (another hand, or a
(lowers, uppers) pair) or default to ``[0, pi/2]`` for flagged joints and ``[0, 0]`` otherwise;
then :func:`project_vectors` makes the hand canonical and physically sensible (see there).

The encoding itself keeps raw units. The VAE standardises the 32 continuous values with a
:class:`Standardizer` fitted on its training set and stored in its checkpoint: the reference's
raw-unit MSE is dominated by the angles (radians are ~30x larger numbers than the metre-valued
sizes), so its latent space barely resolves millimetres; per-dimension z-scores weigh every
continuous parameter equally.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ohra.errors import OhraError, ParamsError, user_stacklevel
from ohra.canonical.params import MAX_ANGLE, BaseParams, ExtendedParams, segment_mask
from ohra.learn.sampler import BASIS_AXES, EXTRA, FINGER_RADIUS, LENGTHS, LOWERS, PALM, THUMB_AXES, THUMB_RPY, UPPERS, XYZ

ENCODING_DIM = 66
CONT_DIM = 32
CONT = slice(0, 32)
AXIS1 = slice(32, 38)
AXIS2 = slice(38, 44)
FLAGS = slice(44, 66)
AXIS_CATEGORIES: tuple[str, ...] = ("+x", "-x", "+y", "-y", "+z", "-z")
DEFAULT_UPPER = math.pi / 2  # default limits of a decoded present joint: [0, pi/2]
SNAP_TOL = 1e-6

# Names of the 32 continuous values, for reports.
CONT_NAMES: tuple[str, ...] = (
    "palm_radius", "finger_radius",
    *(f"finger_lengths[{r}][{c}]" for r in range(2) for c in range(3)),
    *(f"finger_xyz[{r}][{c}]" for r in range(5) for c in range(3)),
    *(f"little_extra_origin[{c}]" for c in range(6)),
    *(f"thumb_rpy[{c}]" for c in range(3)),
)
# Parameter groups of the continuous part and their units (benchmark reports).
CONT_GROUPS: dict[str, tuple[slice, str]] = {
    "palm_radius": (slice(0, 1), "m"),
    "finger_radius": (slice(1, 2), "m"),
    "finger_lengths": (slice(2, 8), "m"),
    "finger_xyz": (slice(8, 23), "m"),
    "little_extra_xyz": (slice(23, 26), "m"),
    "little_extra_rpy": (slice(26, 29), "rad"),
    "thumb_rpy": (slice(29, 32), "rad"),
}

# Box into which decoding clips the continuous values: every valid, physically plausible hand lies
# well inside it (sampler support and all registered hands), and it lies inside the validation
# bounds of BaseParams, so even a latent far outside the prior decodes to a valid hand.
_BOUNDS = np.array(
    [[0.01, 0.15], [0.002, 0.05]]  # palm radius, finger radius
    + [[0.0, 0.25]] * 6  # lengths
    + [[-0.25, 0.25]] * 15  # knuckle / thumb base positions
    + [[-0.25, 0.25]] * 3 + [[-2 * math.pi, 2 * math.pi]] * 3  # little extra origin
    + [[-2 * math.pi, 2 * math.pi]] * 3  # thumb rpy
)
DECODE_LOWER, DECODE_UPPER = _BOUNDS[:, 0].copy(), _BOUNDS[:, 1].copy()
assert DECODE_UPPER[-1] <= MAX_ANGLE


class AxisSnapWarning(UserWarning):
    """A thumb axis was not a signed basis axis and was snapped to the nearest one."""


class OutOfSupportWarning(UserWarning):
    """A hand lies outside the hands a learned model was trained on: encoded by the VAE, outside the sampler's
    support; sampled by a grasp model, outside its training hands' conditions (``GraspModel.support``)."""


class LatentError(OhraError, ValueError):
    """A latent vector or encoding array has the wrong shape or non-finite values."""


# -- encoding ---------------------------------------------------------------------------------------
def _as_batch(v: Any, width: int, what: str) -> tuple[np.ndarray, bool]:
    try:
        arr = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise LatentError(f"{what}: expected a numeric array with last dimension {width}") from None
    single = arr.ndim == 1
    arr = np.atleast_2d(arr)
    if arr.ndim != 2 or arr.shape[1] != width:
        raise LatentError(f"{what}: expected shape ({width},) or (N, {width}), got {np.shape(v)}")
    if not np.all(np.isfinite(arr)):  # a NaN input gave a NaN latent, silently
        rows, cols = np.nonzero(~np.isfinite(arr))
        raise LatentError(f"{what} has non-finite values (NaN or infinity at row {int(rows[0])}, entry {int(cols[0])})")
    return arr, single


def axis_categories(axes: np.ndarray, warn: bool = True, names: Sequence[str] | None = None) -> np.ndarray:
    """Category index (0..5 for +x, -x, +y, -y, +z, -z) of each axis in ``axes`` (..., 3).

    A zero axis (absent joint) is category 0 (+x, as in the reference). Any other axis goes to the
    signed basis axis closest in angle; if it was not already one, an :class:`AxisSnapWarning`
    names it (``names[i]`` labels the i-th axis in the message), attributed to the first caller outside ohra.
    """
    a = np.asarray(axes, dtype=float)
    flat = a.reshape(-1, 3)
    cos = flat @ BASIS_AXES.T  # (M, 6); BASIS_AXES rows are unit vectors
    cat = np.argmax(cos, axis=1)
    zero = ~np.any(flat != 0.0, axis=1)
    cat[zero] = 0
    if warn:
        snapped = ~zero & np.any(np.abs(flat - BASIS_AXES[cat]) > SNAP_TOL, axis=1)
        if snapped.any():
            idx = np.flatnonzero(snapped)
            norm = np.linalg.norm(flat[idx], axis=1)
            ang = np.degrees(np.arccos(np.clip(cos[idx, cat[idx]] / norm, -1.0, 1.0)))
            label = (lambda i: names[i]) if names is not None else (lambda i: f"axis {i}")
            shown = ", ".join(f"{label(int(i))} = {np.round(flat[i], 4).tolist()} -> {AXIS_CATEGORIES[cat[i]]} ({g:.1f} deg)"
                              for i, g in zip(idx[:4], ang[:4]))
            more = f" (and {idx.size - 4} more)" if idx.size > 4 else ""
            warnings.warn(f"thumb axes that are not signed basis axes snapped to the nearest one: {shown}{more}",
                          AxisSnapWarning, stacklevel=user_stacklevel())
    return cat.reshape(a.shape[:-1])


def _encode_discrete(out: np.ndarray, v: np.ndarray, axis1: slice, axis2: slice, flags: slice, warn: bool) -> None:
    """In place: the one-hot thumb axis categories and the joint flags of base vectors ``v`` (N, 82)
    into the ``axis1``, ``axis2`` and ``flags`` columns of the encodings ``out`` (N, D) (shared by
    the 66-D encoding and :mod:`ohra.learn.encoding_rot6d`, whose blocks sit at other columns)."""
    n = len(v)
    axes = v[:, THUMB_AXES].reshape(n, 2, 3)
    names = [f"thumb_axes[{k}] of hand {i}" if n > 1 else f"thumb_axes[{k}]" for i in range(n) for k in range(2)]
    cat = axis_categories(axes, warn=warn, names=names)
    rows = np.arange(n)
    out[rows, axis1.start + cat[:, 0]] = 1.0
    out[rows, axis2.start + cat[:, 1]] = 1.0
    out[:, flags] = (v[:, LOWERS] != v[:, UPPERS]).astype(float)


def encode_vectors(v82: Any, warn: bool = True) -> np.ndarray:
    """Base vectors (82,) or (N, 82) -> encodings (66,) or (N, 66) (raw units, see module doc)."""
    v, single = _as_batch(v82, BaseParams.SIZE, "base vector")
    n = v.shape[0]
    out = np.zeros((n, ENCODING_DIM))
    out[:, CONT] = v[:, :CONT_DIM]
    _encode_discrete(out, v, AXIS1, AXIS2, FLAGS, warn)
    return out[0] if single else out


def as_base(params: Any) -> BaseParams:
    """``params`` as :class:`BaseParams` (extended params are converted when representable)."""
    if isinstance(params, BaseParams):
        return params
    if isinstance(params, ExtendedParams):
        try:
            return params.to_base()
        except ParamsError as exc:
            raise ParamsError(f"the morphology VAE works on base-form params; this extended hand has no base form ({exc})") from None
    raise ParamsError(f"expected BaseParams (or ExtendedParams with a base form), got {type(params).__name__}")


def encode_params(params: Any, warn: bool = True) -> np.ndarray:
    """One hand (BaseParams, or representable ExtendedParams) -> (66,) encoding."""
    return encode_vectors(as_base(params).to_vector(), warn=warn)


# -- decoding ---------------------------------------------------------------------------------------
def _limits(limits: Any, flags: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lowers, uppers), each (N, 22), from a limits source or the flags."""
    n = flags.shape[0]
    if limits is None:
        up = np.where(flags, DEFAULT_UPPER, 0.0)
        return np.zeros((n, 22)), up
    if isinstance(limits, (BaseParams, ExtendedParams)):
        lo, up = limits.joint_lowers, limits.joint_uppers
    elif isinstance(limits, (list, tuple)) and len(limits) and all(isinstance(p, (BaseParams, ExtendedParams)) for p in limits):
        lo = np.stack([p.joint_lowers for p in limits])
        up = np.stack([p.joint_uppers for p in limits])
    elif isinstance(limits, tuple) and len(limits) == 2:
        lo, up = np.asarray(limits[0], dtype=float), np.asarray(limits[1], dtype=float)
    else:
        arr = np.asarray(limits, dtype=float)
        if arr.shape[-1:] != (44,):
            raise ParamsError(f"limits: expected params, a (lowers, uppers) pair or a (44,) / (N, 44) array, got shape {arr.shape}")
        lo, up = arr[..., :22], arr[..., 22:]
    try:
        lo = np.broadcast_to(np.asarray(lo, dtype=float), (n, 22)).copy()
        up = np.broadcast_to(np.asarray(up, dtype=float), (n, 22)).copy()
    except ValueError:
        raise ParamsError(f"limits: expected (22,) or ({n}, 22) lowers and uppers, got {np.shape(lo)} and {np.shape(up)}") from None
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(up))) or np.any(lo > up):
        raise ParamsError("limits: lowers and uppers must be finite with lowers <= uppers")
    return lo, up


def _decode_discrete(x: np.ndarray, axis1: slice, axis2: slice, flags: slice,
                     limits: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thumb axes (N, 6) and joint (lowers, uppers) (N, 22) each [rad] from the ``axis1``, ``axis2``
    (argmax) and ``flags`` (> 0.5) columns of encodings ``x`` (N, D), ``limits`` as in
    :func:`decode_vectors` (the inverse of :func:`_encode_discrete`)."""
    lo, up = _limits(limits, x[:, flags] > 0.5)
    cats = np.stack([np.argmax(x[:, axis1], axis=1), np.argmax(x[:, axis2], axis=1)], axis=1)
    return BASIS_AXES[cats].reshape(len(x), 6), lo, up


def decode_vectors(x66: Any, limits: Any = None) -> np.ndarray:
    """Encodings (66,) or (N, 66) -> valid base vectors (82,) or (N, 82).

    The axis groups may hold one-hot vectors, probabilities or logits (argmax is taken); flags are
    present when > 0.5. The continuous part is in raw units. ``limits``: None (flags -> [0, pi/2]),
    params (or a list of N params) whose limits are copied, a ``(lowers, uppers)`` pair, or a (44,)
    / (N, 44) array of lowers then uppers. The result is projected by :func:`project_vectors`.
    """
    x, single = _as_batch(x66, ENCODING_DIM, "encoding")
    if not np.all(np.isfinite(x)):
        raise LatentError("encoding has non-finite values")
    n = x.shape[0]
    axes, lo, up = _decode_discrete(x, AXIS1, AXIS2, FLAGS, limits)
    v = np.zeros((n, 82))
    v[:, :CONT_DIM] = x[:, CONT]
    v[:, THUMB_AXES] = axes
    v[:, LOWERS] = lo
    v[:, UPPERS] = up
    v = project_vectors(v)
    return v[0] if single else v


def decode_params(x66: Any, limits: Any = None) -> BaseParams | list[BaseParams]:
    """Like :func:`decode_vectors`, returning validated :class:`BaseParams` (a list for a batch)."""
    v = decode_vectors(x66, limits)
    if v.ndim == 1:
        return BaseParams.from_vector(v)
    return [BaseParams.from_vector(row) for row in v]


def segment_presence(present: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """From joint presence (N, 22): thumb segments (N, 3), non-thumb segments (N, 4, 3), fingers (N, 5).

    The base template's link rules, from :func:`ohra.canonical.params.segment_mask` (their one
    definition), split the way the encoding uses them.
    """
    seg = segment_mask(present)
    return seg[:, 0], seg[:, 1:], seg.any(axis=2)


def project_vectors(v82: np.ndarray, min_gap_tol: float = 1e-9) -> np.ndarray:
    """Make base vectors (N, 82) canonical and physically sensible; returns a new array.

    With joint presence taken from the limits (template rule ``lower != 0 or upper != 0``):

    1. parts without geometry are zeroed (axes of absent thumb joints 1/2, positions of fingers
       without links, the little extra origin without ``little_joint0``, lengths of segments
       that no finger has);
    2. continuous values are clipped into ``[DECODE_LOWER, DECODE_UPPER]`` and the finger radius
       to at most half the palm radius;
    3. present thumb axes are unit signed basis axes (the nearest one);
    4. every present segment is at least as long as its capsule's diameter;
    5. knuckles of present non-thumb fingers are spread along y so that neighbours (in index ->
       little order) are at least one finger diameter apart, keeping their order (and their
       centroid, unless that would leave the bounds);
    6. a present finger never sits exactly at the origin.

    A vector that already satisfies all of this is returned unchanged (bit for bit).
    """
    v = np.array(v82, dtype=float, copy=True)
    n = v.shape[0]
    present = (v[:, LOWERS] != 0.0) | (v[:, UPPERS] != 0.0)
    seg_t, seg_f, fingers = segment_presence(present)

    # 2. bounds
    v[:, :CONT_DIM] = np.clip(v[:, :CONT_DIM], DECODE_LOWER, DECODE_UPPER)
    v[:, FINGER_RADIUS] = np.minimum(v[:, FINGER_RADIUS], 0.5 * v[:, PALM])
    r = v[:, FINGER_RADIUS]

    # 1 + 3. thumb axes
    axes = v[:, THUMB_AXES].reshape(n, 2, 3)
    nonzero = np.any(axes != 0.0, axis=2)
    exact = np.all(np.isin(axes, (-1.0, 0.0, 1.0)), axis=2) & (np.abs(axes).sum(axis=2) == 1.0)
    cat = axis_categories(axes, warn=False)
    fixed = np.where((nonzero & exact)[..., None], axes, BASIS_AXES[cat])
    fixed[~present[:, :2]] = 0.0
    v[:, THUMB_AXES] = fixed.reshape(n, 6)

    # 1 + 4. segment lengths
    lengths = v[:, LENGTHS].reshape(n, 2, 3)
    seg = np.stack([seg_t, seg_f.any(axis=1)], axis=1)  # (N, 2, 3)
    lengths = np.where(seg, np.maximum(lengths, 2.0 * r[:, None, None]), 0.0)
    v[:, LENGTHS] = lengths.reshape(n, 6)

    # 1. positions of fingers without links, the little extra frame without little_joint0
    xyz = v[:, XYZ].reshape(n, 5, 3)
    xyz[~fingers] = 0.0
    v[~present[:, 17], EXTRA] = 0.0

    # 5. non-overlapping knuckles
    _spread_knuckles(xyz, fingers, r, min_gap_tol)

    # 6. a present finger needs a non-zero base position
    at_origin = fingers & ~np.any(xyz != 0.0, axis=2)
    xyz[at_origin, 2] = 1e-4
    v[:, XYZ] = xyz.reshape(n, 15)
    return v


def _spread_knuckles(xyz: np.ndarray, fingers: np.ndarray, r: np.ndarray, tol: float) -> None:
    """In place: neighbouring present non-thumb knuckles at least 2r apart along y (see project_vectors)."""
    lim = DECODE_UPPER[8 + 1]
    for i in range(xyz.shape[0]):
        idx = np.flatnonzero(fingers[i, 1:]) + 1
        if idx.size < 2:
            continue
        y = xyz[i, idx, 1]
        d = 2.0 * r[i]
        # index -> little runs towards -y on a right hand (y decreasing): work in u = sign * y, increasing.
        sign = -1.0 if y[0] > y[-1] or (y[0] == y[-1] and xyz[i, 0, 1] > 0) else 1.0
        u = sign * y
        if np.all(np.diff(u) >= d - tol):
            continue
        new = u.copy()
        for k in range(1, new.size):  # push outward to at least d apart
            new[k] = max(new[k], new[k - 1] + d)
        new = np.clip(new + np.mean(u - new), -lim, lim)  # keep the centroid, stay in the bounds
        for k in range(1, new.size):
            new[k] = max(new[k], new[k - 1] + d)
        new[-1] = min(new[-1], lim)
        for k in range(new.size - 2, -1, -1):  # feasible: 3 d <= 2 lim, so this keeps new >= -lim
            new[k] = min(new[k], new[k + 1] - d)
        xyz[i, idx, 1] = sign * new


# -- standardisation --------------------------------------------------------------------------------
@dataclass
class Standardizer:
    """Per-dimension z-scores of an encoding's continuous values: ``(x - mean) / std``.

    Constant dimensions (e.g. little-extra pitch and yaw, always 0 in the sampler) get ``std = 1``:
    they carry no information, and unit scale keeps small real-hand deviations small.
    """

    mean: np.ndarray
    std: np.ndarray

    @classmethod
    def fit(cls, cont: np.ndarray) -> "Standardizer":
        c = np.asarray(cont, dtype=float)
        mean = c.mean(axis=0)
        std = c.std(axis=0)
        std = np.where(std < 1e-8, 1.0, std)
        return cls(mean, std)

    def transform(self, cont: np.ndarray) -> np.ndarray:
        return (np.asarray(cont, dtype=float) - self.mean) / self.std

    def inverse(self, z: np.ndarray) -> np.ndarray:
        return np.asarray(z, dtype=float) * self.std + self.mean

    def to_dict(self) -> dict[str, list[float]]:
        return {"mean": self.mean.tolist(), "std": self.std.tolist()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Standardizer":
        mean, std = np.asarray(d["mean"], dtype=float), np.asarray(d["std"], dtype=float)
        if mean.ndim != 1 or mean.shape != std.shape or not np.all(np.isfinite(mean)) or np.any(~(std > 0)):
            raise ParamsError(f"standardiser: expected equally many means and positive stds, got shapes {mean.shape} and {std.shape}")
        return cls(mean, std)
