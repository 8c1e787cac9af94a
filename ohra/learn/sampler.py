"""Synthetic hand sampler: random valid base-form hands for training the morphology VAE.

The joint patterns follow the reference sampler (``ohra_reference.md`` §7.1) with its quirks fixed
(DESIGN decision 4, reference §11 item 12): seeded and vectorised; no shared mutable template; the
little finger's extra (metacarpal) joint on the little finger's side; parts without geometry carry
zeros, as in the registered real hands (absent fingers have ``finger_xyz = 0``, absent thumb joints
1/2 a zero axis, the little extra origin is zero without ``little_joint0``, segments without geometry
length 0); vectors in the canonical key order of :class:`ohra.canonical.params.BaseParams`.

The continuous distributions are wider than the reference's and shaped so that **every registered
base-form hand lies inside the support** (:func:`support_violations` says why one would not; the
README lists them). The reference's ranges missed most real hands: its finger radius stops at 12 mm
(LEAP: 17 mm), its knuckle heights at ``2 R - 1 cm +- 5 mm`` (Barrett's knuckles sit at the palm
centre, 8 standard deviations lower; Sharpa's 3 higher), its little metacarpal frame below 2.5 cm
(Sharpa: 8.5 cm), and it never draws a thumb without joint 1 (Barrett). Its thumb mounting rotation
was uniform in the Euler cube ``[-pi, pi]^3``, which covers every rotation twice and points half the
thumbs into the palm. Here:

* the thumb mounting rotation is uniform over the rotations whose z axis (the thumb's direction at
  q = 0) does not point towards the palm centre from the thumb base (a uniform rotation is turned by
  pi about an axis perpendicular to that direction when it does: a measure-preserving map from one
  half onto the other), and a thumb that would touch a finger at q = 0 is drawn again;
* knuckles sit in one row at height ``2 R + o R`` (``o`` shared by the hand) with a small per-finger
  jitter in height and depth, spread across a row of half-width ``s (R - r)`` with Dirichlet gaps,
  never closer than one finger diameter;
* left hands are exact mirror images of right hands (:func:`mirror_vectors`).

Kept from the reference on purpose: one joint pattern shared by all non-thumb fingers, limits
``[0, pi/2]`` for present joints, signed basis axes for thumb joints 1 and 2. The full thumb and
finger patterns are drawn three times as often as each other pattern (:func:`_pattern_odds`).

Units: metres and radians, canonical palm frame (+x palm normal, +y thumb side of a right hand,
+z finger-forward). A right hand has its thumb at ``+y``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ohra.errors import ParamsError, require_seed
from ohra.canonical.params import BaseParams

# Slices of the flat (82,) base vector (canonical key order, reference §3.1).
PALM = 0
FINGER_RADIUS = 1
LENGTHS = slice(2, 8)  # (2,3): thumb p,m,d | non-thumb p,m,d
XYZ = slice(8, 23)  # (5,3)
EXTRA = slice(23, 29)  # little_extra_origin xyz rpy
THUMB_RPY = slice(29, 32)
THUMB_AXES = slice(32, 38)  # (2,3)
LOWERS = slice(38, 60)
UPPERS = slice(60, 82)

# Thumb joint patterns (j1..j5): the reference's six, plus Barrett's thumb without base joints.
THUMB_PATTERNS = np.array(
    [[1, 1, 1, 1, 1], [1, 1, 0, 1, 1], [1, 1, 0, 0, 1], [1, 0, 0, 1, 1], [1, 0, 0, 1, 0], [1, 0, 0, 0, 1],
     [0, 0, 0, 1, 1]], dtype=bool
)
_ALL4 = np.array([[(k >> (3 - b)) & 1 for b in range(4)] for k in range(16)], dtype=bool)
FINGER_PATTERNS = _ALL4[_ALL4[:, 1:].sum(axis=1) >= 2]  # 8 patterns, uniform (= rejection sampling)
# Signed basis axes in the one-hot category order used by the VAE: +x, -x, +y, -y, +z, -z.
BASIS_AXES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)


@dataclass(frozen=True)
class SamplerConfig:
    """Ranges of the sampler [m, rad, or as noted]; ``U(a, b)`` unless noted. Right-hand values
    (left hands mirror them)."""

    p_finger: float = 0.75  # each non-thumb finger present (at least 2 of 4 forced)
    p_little_joint0: float = 0.8  # extra little joint, only when >= 20 joints are present
    full_pattern_weight: float = 3.0  # odds of the full thumb / finger pattern against each other one
    palm_radius: tuple[float, float] = (0.04, 0.06)
    finger_radius: tuple[float, float] = (0.007, 0.018)  # upper bound also <= max_radius_ratio * palm radius
    max_radius_ratio: float = 1.0 / 3.0
    thumb_lengths: tuple[float, float] = (0.02, 0.075)  # Inspire: a 23 mm middle thumb link
    finger_lengths: tuple[float, float] = (0.02, 0.075)
    thumb_x: tuple[float, float] = (-0.025, 0.025)
    thumb_y: tuple[float, float] = (0.0, 0.045)  # |y|, on the thumb side
    thumb_z: tuple[float, float] = (0.0, 0.07)  # Inspire mounts its thumb 6 cm up the palm
    knuckle_x: tuple[float, float] = (-0.006, 0.012)  # shared by the non-thumb fingers
    knuckle_x_jitter: float = 0.003  # U(-a, a) per finger (Inspire's knuckles spread 4.6 mm in x)
    knuckle_row: tuple[float, float] = (-1.05, 0.5)  # row height 2 R + o R, o in palm radii (Inspire: 0.46)
    knuckle_z_jitter: float = 0.007  # U(-a, a) per finger
    knuckle_span: tuple[float, float] = (0.85, 1.3)  # half-width of the knuckle row / (R - r)
    finger_gap: float = 2e-4  # least free space between neighbouring knuckles' capsules [m]
    extra_x: tuple[float, float] = (-0.015, 0.015)
    extra_y: tuple[float, float] = (0.02, 0.045)  # |y|, on the little finger's side
    extra_z: tuple[float, float] = (0.015, 0.09)
    extra_roll: tuple[float, float] = (0.9, 1.45)  # right hand; left: negated
    extra_pitch: tuple[float, float] = (-0.1, 0.1)
    extra_yaw: tuple[float, float] = (-1.65, 0.15)  # right hand; left: negated
    joint_upper: float = math.pi / 2
    thumb_clearance: float = 5e-4  # m: a thumb closer than this to a finger at q = 0 is drawn again
    max_redraws: int = 100  # redraw rounds before giving up (each round redraws only the failing thumbs)

    def knuckle_z_bounds(self, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lowest and highest knuckle height [m] for palm radii ``R``."""
        R = np.asarray(R, dtype=float)
        return (2.0 + self.knuckle_row[0]) * R - self.knuckle_z_jitter, (2.0 + self.knuckle_row[1]) * R + self.knuckle_z_jitter


DEFAULT_CONFIG = SamplerConfig()


def _pattern_odds(patterns: np.ndarray, c: SamplerConfig) -> np.ndarray:
    """Probabilities of the patterns (K, J): the full one (every joint) ``full_pattern_weight`` times
    as likely as each other one. Most real hands have full fingers (6 of the 13 registered base
    hands have a full thumb or full fingers), and the full 22-joint hand with a little metacarpal
    joint would otherwise be 0.4 % of the samples."""
    w = np.where(patterns.all(axis=1), c.full_pattern_weight, 1.0)
    return w / w.sum()


def _finger_use(rng: np.random.Generator, n: int, p_finger: float) -> np.ndarray:
    """Which non-thumb fingers (n, 4) are used: each with ``p_finger``, then random ones forced on
    until every hand has at least 2 (the thumb is always present)."""
    use = rng.random((n, 4)) < p_finger
    while True:
        short = np.flatnonzero(use.sum(axis=1) < 2)
        if short.size == 0:
            return use
        use[short, rng.integers(0, 4, short.size)] = True


def _joint_presence(rng: np.random.Generator, thumb_pat: np.ndarray, finger_pat: np.ndarray, use: np.ndarray,
                    p_little_joint0: float) -> np.ndarray:
    """Joint presence (n, 22) from the thumb pattern (n, 5), the shared finger pattern (n, 4) and the
    fingers used (n, 4); the little metacarpal joint drawn with ``p_little_joint0`` in hands with
    >= 20 other joints."""
    n = len(use)
    present = np.zeros((n, 22), dtype=bool)
    present[:, 0:5] = thumb_pat
    for fi, start in enumerate((5, 9, 13, 18)):  # index, middle, ring, little (joint1..4)
        present[:, start : start + 4] = finger_pat & use[:, fi : fi + 1]
    full = present.sum(axis=1) >= 20
    present[:, 17] = full & (rng.random(n) < p_little_joint0)
    return present


def _patterns(rng: np.random.Generator, n: int, c: SamplerConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint presence (n, 22), non-thumb fingers used (n, 4) and the shared finger pattern (n, 4)."""
    use = _finger_use(rng, n, c.p_finger)
    thumb_pat = THUMB_PATTERNS[rng.choice(len(THUMB_PATTERNS), n, p=_pattern_odds(THUMB_PATTERNS, c))]
    finger_pat = FINGER_PATTERNS[rng.choice(len(FINGER_PATTERNS), n, p=_pattern_odds(FINGER_PATTERNS, c))]
    return _joint_presence(rng, thumb_pat, finger_pat, use, c.p_little_joint0), use, finger_pat


def _dirichlet_gaps(rng: np.random.Generator, k: np.ndarray) -> np.ndarray:
    """Cumulative Dirichlet(1, ..., 1) shares (n, 5) of the free space over the k + 1 gaps before,
    between and after k = 2..4 knuckles: column i is the share of the first i + 1 gaps."""
    w = np.zeros((len(k), 5))
    for kk in (2, 3, 4):
        rows = np.flatnonzero(k == kk)
        if rows.size:
            w[rows, : kk + 1] = rng.dirichlet(np.ones(kk + 1), rows.size)
    return np.cumsum(w, axis=1)


def _thumb_axes(rng: np.random.Generator, present: np.ndarray) -> np.ndarray:
    """Axes (n, 2, 3) of thumb joints 1 and 2: two different signed basis axes (axis2 == -axis1 is
    allowed), zero where the joint is absent."""
    n = len(present)
    a1 = rng.integers(0, 6, n)
    a2 = rng.integers(0, 5, n)
    a2 = a2 + (a2 >= a1)  # uniform over the 5 categories != a1
    axes = np.stack([BASIS_AXES[a1], BASIS_AXES[a2]], axis=1)
    axes[~present[:, 0], 0] = 0.0
    axes[~present[:, 1], 1] = 0.0
    return axes


def _segment_mask(present: np.ndarray, finger_pat: np.ndarray) -> np.ndarray:
    """Which of the 6 length segments (thumb p, m, d | finger p, m, d) have geometry (n, 6): segments
    without geometry have no length (link rules of the base template)."""
    t = present[:, 0:5]
    seg_t = np.stack([t[:, 0] | t[:, 1], t[:, 2] | t[:, 3], t[:, 4]], axis=1)
    seg_f = np.stack([finger_pat[:, 0] | finger_pat[:, 1], finger_pat[:, 2], finger_pat[:, 3]], axis=1)
    return np.concatenate([seg_t, seg_f], axis=1)


def _base_vectors(R: np.ndarray, r: np.ndarray, lengths: np.ndarray, xyz: np.ndarray, extra: np.ndarray,
                  thumb_rpy: np.ndarray, axes: np.ndarray, present: np.ndarray, joint_upper: float) -> np.ndarray:
    """The (n, 82) base vectors (canonical key order) from their parts; lower limits 0, upper limits
    ``joint_upper`` for present joints [rad]."""
    n = len(R)
    out = np.zeros((n, 82))
    out[:, PALM] = R
    out[:, FINGER_RADIUS] = r
    out[:, LENGTHS] = lengths
    out[:, XYZ] = xyz.reshape(n, 15)
    out[:, EXTRA] = extra
    out[:, THUMB_RPY] = thumb_rpy
    out[:, THUMB_AXES] = axes.reshape(n, 6)
    out[:, UPPERS] = np.where(present, joint_upper, 0.0)
    return out


def _knuckles(rng: np.random.Generator, R: np.ndarray, r: np.ndarray, use: np.ndarray, c: SamplerConfig) -> np.ndarray:
    """Right-hand knuckle positions (n, 4, 3) of index..little (zeros where unused).

    k fingers of diameter 2 r in a row of half-width W = s (R - r), index at the +y (thumb) end,
    with Dirichlet(1, ..., 1) free space before, between and after them (centres never closer than
    d = 2 r + ``finger_gap``).
    """
    n = len(R)
    k = use.sum(axis=1)
    W = (R - r) * rng.uniform(*c.knuckle_span, n)
    d = 2.0 * r + c.finger_gap
    space = np.maximum(2.0 * W - (k - 1) * d, 0.0)
    cum = _dirichlet_gaps(rng, k)
    rank = np.clip(np.cumsum(use, axis=1) - 1, 0, 3)  # rank of each used finger, index -> little
    xyz = np.zeros((n, 4, 3))
    xyz[:, :, 1] = W[:, None] - np.take_along_axis(cum, rank, axis=1) * space[:, None] - rank * d[:, None]
    xyz[:, :, 0] = rng.uniform(*c.knuckle_x, n)[:, None] + rng.uniform(-c.knuckle_x_jitter, c.knuckle_x_jitter, (n, 4))
    row = (2.0 + rng.uniform(*c.knuckle_row, n)) * R
    xyz[:, :, 2] = row[:, None] + rng.uniform(-c.knuckle_z_jitter, c.knuckle_z_jitter, (n, 4))
    xyz[~use] = 0.0
    return xyz


def _outward_rotations(rng: np.random.Generator, base: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Uniform random rotations (n, 3, 3) whose z axis does not point towards the palm centre
    ``(0, 0, R)`` from ``base`` (n, 3); see the module docstring."""
    from ohra.learn.geometry import rotation_about  # geometry imports this module's constants

    n = len(base)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    from scipy.spatial.transform import Rotation

    M = Rotation.from_quat(q).as_matrix()
    w = np.stack([np.zeros(n), np.zeros(n), R], axis=1) - base
    inward = np.sum(M[:, :, 2] * w, axis=1) > 0.0
    if inward.any():
        wi = w[inward] / np.linalg.norm(w[inward], axis=1, keepdims=True)
        helper = np.where(np.abs(wi[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        u = np.cross(wi, helper)
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        M[inward] = rotation_about(u, np.full(len(u), math.pi)) @ M[inward]  # maps w -> -w
    return M


def _thumbs(rng: np.random.Generator, R: np.ndarray, c: SamplerConfig) -> tuple[np.ndarray, np.ndarray]:
    """Right-hand thumb bases (n, 3) and mounting rotations (n, 3, 3)."""
    n = len(R)
    base = np.stack([rng.uniform(*c.thumb_x, n), rng.uniform(*c.thumb_y, n), rng.uniform(*c.thumb_z, n)], axis=1)
    return base, _outward_rotations(rng, base, R)


def _little_extra(rng: np.random.Generator, n: int, c: SamplerConfig) -> np.ndarray:
    """Right-hand little metacarpal origins (n, 6): xyz at -y, rpy."""
    return np.stack([rng.uniform(*c.extra_x, n), -rng.uniform(*c.extra_y, n), rng.uniform(*c.extra_z, n),
                     rng.uniform(*c.extra_roll, n), rng.uniform(*c.extra_pitch, n), rng.uniform(*c.extra_yaw, n)], axis=1)


def _redraw_touching_thumbs(rng: np.random.Generator, out: np.ndarray, c: SamplerConfig) -> None:
    """In place: draw thumb base and rotation again where the thumb is closer than ``c.thumb_clearance``
    to a finger at q = 0, until none is."""
    from ohra.learn.geometry import thumb_clearance
    from ohra.transforms import matrix_to_rpy

    bad = np.arange(len(out))
    for _ in range(c.max_redraws):
        bad = bad[thumb_clearance(out[bad]) < c.thumb_clearance]
        if bad.size == 0:
            return
        base, rot = _thumbs(rng, out[bad, PALM], c)
        out[bad, XYZ.start : XYZ.start + 3] = base
        out[bad, THUMB_RPY] = matrix_to_rpy(rot)
    raise ParamsError(f"sampler: {bad.size} thumbs still touch a finger after {c.max_redraws} redraws; widen the thumb ranges")


def _start(n: int, seed: int) -> tuple[int, np.random.Generator, np.ndarray]:
    """The checked sample count, the seeded generator and its first draw, the handedness (n,) (True:
    right hand, probability 1/2)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        raise ParamsError(f"number of samples must be a whole number >= 0, got {n!r}")
    n = int(n)
    rng = np.random.default_rng(require_seed(seed, ParamsError, "sampler seed"))
    return n, rng, rng.random(n) < 0.5


def sample_vectors(n: int, seed: int, config: SamplerConfig = DEFAULT_CONFIG, return_handedness: bool = False):
    """``n`` random hands as an (n, 82) array of base vectors (canonical key order).

    Deterministic given ``seed``. With ``return_handedness`` also returns an (n,) bool array, True
    for right hands. Every row is a valid :class:`BaseParams` vector.
    """
    from ohra.transforms import matrix_to_rpy

    n, rng, right = _start(n, seed)
    c = config
    present, use, finger_pat = _patterns(rng, n, c)

    R = rng.uniform(*c.palm_radius, n)
    r = rng.uniform(c.finger_radius[0], np.minimum(c.finger_radius[1], c.max_radius_ratio * R))
    lo = np.maximum(np.array([c.thumb_lengths[0]] * 3 + [c.finger_lengths[0]] * 3), 2.0 * r[:, None])  # capsule >= diameter
    hi = np.array([c.thumb_lengths[1]] * 3 + [c.finger_lengths[1]] * 3)
    lengths = rng.uniform(lo, hi) * _segment_mask(present, finger_pat)

    xyz = np.zeros((n, 5, 3))
    xyz[:, 1:] = _knuckles(rng, R, r, use, c)
    xyz[:, 0], thumb_rot = _thumbs(rng, R, c)

    axes = _thumb_axes(rng, present)
    extra = _little_extra(rng, n, c)
    extra[~present[:, 17]] = 0.0

    out = _base_vectors(R, r, lengths, xyz, extra, matrix_to_rpy(thumb_rot), axes, present, c.joint_upper)
    _redraw_touching_thumbs(rng, out, c)
    out[~right] = mirror_vectors(out[~right])
    if return_handedness:
        return out, right
    return out


def sample_params(n: int, seed: int, config: SamplerConfig = DEFAULT_CONFIG) -> list[BaseParams]:
    """``n`` random hands as validated :class:`BaseParams` (see :func:`sample_vectors`).

    Args:
        n: number of hands, >= 0.
        seed: seed of the generator (``numpy.random.default_rng``); the same seed and config give the
            same hands.
        config: the sampler's ranges [m, rad] (:class:`SamplerConfig`).

    Returns:
        ``n`` base-form hands, left or right with probability 1/2 each; lengths and positions in
        metres, angles in radians, in the canonical palm frame.

    Raises:
        ParamsError: ``n < 0``, or a thumb still touches a finger at q = 0 after ``config.max_redraws``
            redraws.
    """
    return [BaseParams.from_vector(v) for v in sample_vectors(n, seed, config)]


def sample_hand(seed: int, config: SamplerConfig = DEFAULT_CONFIG) -> BaseParams:
    """One random hand."""
    return sample_params(1, seed, config)[0]


def mirror_vectors(v: np.ndarray) -> np.ndarray:
    """Mirror hands through the palm's x-z plane (right <-> left): negate every y coordinate and
    the rotations that the mirror flips (little extra roll/yaw, thumb roll/yaw). Thumb axes are
    left as they are (their distribution is symmetric under any sign change).

    Used by the symmetry test: mirrored left samples follow the right-hand distribution.
    """
    m = np.array(v, dtype=float, copy=True)
    m[:, XYZ.start + 1 : XYZ.stop : 3] *= -1.0
    m[:, EXTRA.start + 1] *= -1.0
    m[:, EXTRA.start + 3] *= -1.0
    m[:, EXTRA.start + 5] *= -1.0
    m[:, THUMB_RPY.start] *= -1.0
    m[:, THUMB_RPY.start + 2] *= -1.0
    return m


def in_support(flags: np.ndarray) -> bool:
    """Whether a joint pattern (22 bools, e.g. the VAE flags) can come out of the sampler.

    The sampler's patterns: thumb one of ``THUMB_PATTERNS``; 2-4 non-thumb fingers sharing one of
    ``FINGER_PATTERNS``; ``little_joint0`` only with at least 20 other joints. Hands outside this support
    are encoded fine but reconstructed less reliably.
    """
    f = np.asarray(flags, dtype=bool).reshape(22)
    if not any(np.array_equal(f[0:5], t) for t in THUMB_PATTERNS):
        return False
    pats = [f[s : s + 4] for s in (5, 9, 13, 18)]
    used = [p for p in pats if p.any()]
    if len(used) < 2 or any(not np.array_equal(p, used[0]) for p in used):
        return False
    if not any(np.array_equal(used[0], p) for p in FINGER_PATTERNS):
        return False
    return not f[17] or int(f.sum()) - 1 >= 20


def _range(out: list[str], name: str, values: np.ndarray, lo: float, hi: float, tol: float = 1e-9) -> None:
    for i, x in enumerate(np.atleast_1d(values)):
        if not lo - tol <= x <= hi + tol:
            label = name if np.size(values) == 1 else f"{name}[{i}]"
            out.append(f"{label} = {x:.4g} outside [{lo:.4g}, {hi:.4g}]")


def violations_text(why: list[str], shown: int = 3) -> str:
    """The first ``shown`` of :func:`support_violations`' lines joined, with how many more there are."""
    return "; ".join(why[:shown]) + (f"; and {len(why) - shown} more" if len(why) > shown else "")


def support_violations(params: BaseParams, config: SamplerConfig = DEFAULT_CONFIG) -> list[str]:
    """Why a base-form hand lies outside the sampler's support: one line per violated range or rule
    (right-hand values: a left hand is mirrored first). An empty list means the sampler can draw it,
    up to its thumb axes, which the encoding snaps to signed basis axes anyway.
    """
    from ohra.learn.geometry import thumb_clearance, thumb_inwardness

    c = config
    v = params.to_vector()[None]
    if params.handedness == "left":
        v = mirror_vectors(v)
    v0 = v[0]
    out: list[str] = []
    flags = v0[LOWERS] != v0[UPPERS]
    if not in_support(flags):
        out.append(f"joint pattern {flags.astype(int).tolist()} is not one the sampler draws")
    R, r = v0[PALM], v0[FINGER_RADIUS]
    _range(out, "palm_radius", R, *c.palm_radius)
    _range(out, "finger_radius", r, c.finger_radius[0], min(c.finger_radius[1], c.max_radius_ratio * R))
    L = v0[LENGTHS].reshape(2, 3)
    _range(out, "thumb lengths", L[0][L[0] > 0], max(c.thumb_lengths[0], 2 * r), c.thumb_lengths[1])
    _range(out, "finger lengths", L[1][L[1] > 0], max(c.finger_lengths[0], 2 * r), c.finger_lengths[1])
    xyz = v0[XYZ].reshape(5, 3)
    for k, (name, lim) in enumerate((("thumb x", c.thumb_x), ("thumb y", c.thumb_y), ("thumb z", c.thumb_z))):
        _range(out, name, xyz[0, k], *lim)
    used = params.present_fingers[1:]
    k = xyz[1:][used]
    if len(k) == 0:  # a thumb alone: no knuckle row (its joint pattern is out of the support already)
        out.append("no finger besides the thumb (the sampler draws at least 2)")
    else:
        jx, jz = c.knuckle_x_jitter, c.knuckle_z_jitter
        _range(out, "knuckle x", k[:, 0], c.knuckle_x[0] - jx, c.knuckle_x[1] + jx)
        _range(out, "knuckle x spread", np.ptp(k[:, 0]), 0.0, 2 * jx)
        zlo, zhi = c.knuckle_z_bounds(R)
        _range(out, "knuckle z", k[:, 2], float(zlo), float(zhi))
        _range(out, "knuckle z spread", np.ptp(k[:, 2]), 0.0, 2 * jz)
        wmax = c.knuckle_span[1] * (R - r)
        _range(out, "knuckle |y|", np.abs(k[:, 1]), 0.0, max(wmax, (len(k) - 1) * (2 * r + c.finger_gap)))  # a full row overflows
        _range(out, "knuckle gaps - finger diameter", -np.diff(k[:, 1]) - 2 * r, c.finger_gap, np.inf)
    if thumb_inwardness(v)[0] > 0:
        out.append("the thumb points into the palm at q = 0")
    clear = thumb_clearance(v)[0]
    if clear < c.thumb_clearance:
        out.append(f"the thumb is {1e3 * clear:.1f} mm from a finger at q = 0 (sampler: >= {1e3 * c.thumb_clearance:.1f} mm)")
    if flags[17]:
        e = v0[EXTRA]
        for i, (name, lim) in enumerate((("extra x", c.extra_x), ("extra -y", c.extra_y), ("extra z", c.extra_z),
                                         ("extra roll", c.extra_roll), ("extra pitch", c.extra_pitch), ("extra yaw", c.extra_yaw))):
            _range(out, name, -e[i] if i == 1 else e[i], *lim)
    return out
