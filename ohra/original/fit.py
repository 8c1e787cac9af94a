"""Least-squares refinement of canonical parameters against the original hand's kinematics.

The fit refines the continuous kinematic parameters (lengths, base positions and orientations, free
axes) with ``scipy.optimize.least_squares`` so that canonical fingertips and joint positions match
the original ones over seeded random configurations mapped with the ActionMap; capsule lengths stay
>= their diameter. Joint positions are compared as the distance from the canonical joint origin to
the original joint's axis line (a revolute joint's position along its own axis carries no
kinematic meaning). The fit is deterministic (seeded sampling, deterministic solver).

Base form: the template's non-thumb fingers are parallel, so two bases closer in y than two radii
plus :data:`FINGER_GAP` intersect at rest. When the fit would bring measured-apart neighbours that
close (it averages motion the canonical hand cannot follow, e.g. a palm piece that carries fingers,
into their bases), the group is refitted with each base y bounded to half the measured slack, and a
note says so; otherwise the result is exactly the unbounded fit's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from ohra.canonical.params import EXT_ROW_JOINTS, EXT_ROW_START, FINGERS, FINGER_GAP, FINGER_SLICES, JOINT_INDEX, BaseParams, ExtendedParams, Params
from ohra.original.estimate import MIN_CAPSULE_MARGIN
from ohra.original.keypoints import OriginalKeypoints, canonical_keypoints, ext_arrays_from_base, original_keypoints, sample_original
from ohra.original.measure import Measurement

DECIMALS = 6  # committed numbers: micrometres / microradians
JOINT_WEIGHT = 0.5  # joint-position residuals relative to fingertip residuals
ALONG_AXIS_WEIGHT = 0.2
REG_WEIGHT = 1e-3  # pull toward the measured values (fixes directions the data cannot see)


@dataclass
class FitResult:
    """Keypoint RMS before and after the fit [mm], solver evaluations, configurations used."""

    initial_rms_mm: float
    final_rms_mm: float
    iterations: int
    samples: int
    notes: list[str] = field(default_factory=list)  # "approximation: ..." lines (bounded finger bases)


def _free_mask_base(p: BaseParams) -> tuple[np.ndarray, np.ndarray]:
    """Free entries of the 82-vector and lower bounds (capsule >= diameter)."""
    v = p.to_vector()
    free = np.zeros(v.size, dtype=bool)
    lb = np.full(v.size, -np.inf)
    links = p.link_presence()
    a = p.present_joints
    r = p.finger_radius
    for s in range(3):
        if links["thumb"][s]:
            free[2 + s] = True
            lb[2 + s] = 2 * r + MIN_CAPSULE_MARGIN
        if any(links[f][s] for f in FINGERS[1:]):
            free[5 + s] = True
            lb[5 + s] = 2 * r + MIN_CAPSULE_MARGIN
    for fi, f in enumerate(FINGERS):
        if any(links[f]):
            free[8 + 3 * fi : 11 + 3 * fi] = True
    if a[17]:
        free[23:29] = True
    if any(links["thumb"]):
        free[29:32] = True
    if a[0]:
        free[32:35] = True
    if a[1]:
        free[35:38] = True
    return free, lb


def _free_mask_ext(p: ExtendedParams) -> tuple[np.ndarray, np.ndarray]:
    """Free entries of the 173-vector and lower bounds (capsule >= diameter)."""
    v = p.to_vector()
    free = np.zeros(v.size, dtype=bool)
    lb = np.full(v.size, -np.inf)
    links = p.link_presence()
    a = p.present_joints
    OFF_L, OFF_O, OFF_A = 6, 21, 93
    for fi, f in enumerate(FINGERS):
        if not any(links[f]):
            continue
        r = p.finger_radii[fi]
        for s in range(3):
            if links[f][s]:
                free[OFF_L + 3 * fi + s] = True
                lb[OFF_L + 3 * fi + s] = 2 * r + MIN_CAPSULE_MARGIN
        start = EXT_ROW_START[fi]
        rows = range(start, start + (3 if fi in (0, 4) else 2))
        for row in rows:
            free[OFF_O + 6 * row : OFF_O + 6 * row + 6] = True
        for row in rows:  # free axes of present joints
            if a[JOINT_INDEX[EXT_ROW_JOINTS[row]]]:
                free[OFF_A + 3 * row : OFF_A + 3 * row + 3] = True
    # little metacarpal frame only matters when j0 is present
    if not a[17]:
        free[OFF_O + 6 * 9 : OFF_O + 6 * 10] = False
    # redundant rotations (the j1 frame's rotation and the free axes already span them): keep at 0
    for row in (1, 2, 4, 6, 8, 11):
        free[OFF_O + 6 * row + 3 : OFF_O + 6 * row + 6] = False
    return free, lb


def _group_masks(base: bool) -> list[tuple[tuple[str, ...], np.ndarray]]:
    """Independent parameter groups: (fingers, mask over the parameter vector).

    Extended fingers share nothing, so each is fitted alone; base non-thumb fingers share their
    lengths and are fitted together.
    """
    size = 82 if base else 173
    out = []
    if base:
        thumb = np.zeros(size, dtype=bool)
        thumb[[2, 3, 4, 8, 9, 10, *range(29, 38)]] = True
        out.append((("thumb",), thumb))
        out.append((FINGERS[1:], ~thumb))
        return out
    for fi, f in enumerate(FINGERS):
        mk = np.zeros(size, dtype=bool)
        mk[1 + fi] = True
        mk[6 + 3 * fi : 9 + 3 * fi] = True
        start = EXT_ROW_START[fi]
        for row in range(start, start + (3 if fi in (0, 4) else 2)):
            mk[21 + 6 * row : 27 + 6 * row] = True
            mk[93 + 3 * row : 96 + 3 * row] = True
        out.append(((f,), mk))
    return out


_SIDE = ("index", "middle", "ring", "little")


def _base_spacing(p: BaseParams) -> list[tuple[str, str, int, int, float, float]]:
    """Neighbouring non-thumb fingers of the base form whose measured bases are far enough apart:
    (finger, neighbour, index of its base y, index of the neighbour's, measured y difference, the
    least allowed |difference|: two finger radii + :data:`FINGER_GAP`).

    The base template's fingers are parallel, so two bases closer than that in y intersect at rest.
    The little finger counts only without ``little_joint0`` (its base is then in the palm frame).
    Pairs already closer in the measured layout are left out (the parser caps the radius for them).
    """
    links = p.link_presence()
    side = [f for f in _SIDE if any(links[f]) and not (f == "little" and p.present_joints[17])]
    least = 2.0 * float(p.finger_radius) + FINGER_GAP
    out = []
    for f, g in zip(side, side[1:]):
        i, k = 8 + 3 * FINGERS.index(f) + 1, 8 + 3 * FINGERS.index(g) + 1
        d0 = float(p.finger_xyz[FINGERS.index(f), 1] - p.finger_xyz[FINGERS.index(g), 1])
        if abs(d0) >= least:
            out.append((f, g, i, k, d0, least))
    return out


def _spacing_bounds(v: np.ndarray, pairs) -> tuple[np.ndarray, np.ndarray]:
    """Bounds on the base y entries of ``v`` that keep every pair of :func:`_base_spacing` apart: each
    finger may move toward its neighbour by half the measured slack."""
    lb, ub = np.full(v.size, -np.inf), np.full(v.size, np.inf)
    for _, _, i, k, d0, least in pairs:
        half = 0.5 * (abs(d0) - least)
        if d0 > 0:  # f on +y of g
            lb[i], ub[k] = max(lb[i], v[i] - half), min(ub[k], v[k] + half)
        else:
            ub[i], lb[k] = min(ub[i], v[i] + half), max(lb[k], v[k] - half)
    return lb, ub


def _fit_group(v, free, lb_all, fingers, ok: OriginalKeypoints, qc, present, base: bool, ub_all=None):
    """Fit the ``free`` entries of ``v`` for ``fingers``; returns (x, sq0, sq1, n_err, nfev)."""
    fidx = [FINGERS.index(f) for f in fingers]
    jmask = np.zeros(22, dtype=bool)
    for f in fingers:
        jmask[FINGER_SLICES[f]] = True
    jmask &= ~np.isnan(ok.joints[0, :, 0])
    tmask = np.zeros(5, dtype=bool)
    tmask[fidx] = True
    tmask &= ~np.isnan(ok.tips[0, :, 0])
    lb = lb_all[free]
    ub = np.full_like(lb, np.inf) if ub_all is None else ub_all[free]
    x0 = np.minimum(np.maximum(v[free], lb), ub)
    ref = v.copy()

    def arrays(x):
        w = ref.copy()
        w[free] = x
        if base:
            return ext_arrays_from_base(w, present)
        return {"lengths": w[6:21].reshape(5, 3), "origins": w[21:93].reshape(12, 6), "axes": w[93:129].reshape(12, 3)}

    def residuals(x):
        J, tips = canonical_keypoints(arrays(x), present, qc, fingers)
        rt = (tips[:, tmask] - ok.tips[:, tmask]).ravel()
        dj = J[:, jmask] - ok.joints[:, jmask]
        ax = ok.axes[:, jmask]
        along = np.sum(dj * ax, axis=-1, keepdims=True) * ax
        # a joint's position along its own axis is kinematically free: weigh it lightly
        rj = JOINT_WEIGHT * ((dj - along) + ALONG_AXIS_WEIGHT * along).ravel()
        return np.concatenate([rt, rj, REG_WEIGHT * (x - x0)])

    r0 = residuals(x0)
    sol = least_squares(residuals, x0, bounds=(lb, ub), method="trf",
                        max_nfev=300, ftol=1e-9, xtol=1e-9, gtol=1e-9)
    k = x0.size
    n_err = int(tmask.sum() + jmask.sum()) * qc.shape[0]
    return sol.x, float(np.sum(r0[:-k] ** 2)), float(np.sum(sol.fun[:-k] ** 2)), n_err, int(sol.nfev)


def fit(params: Params, m: Measurement, samples: int = 96, seed: int = 0) -> tuple[Params, FitResult]:
    """Least-squares refinement of the continuous kinematic parameters (see module docstring)."""
    base = isinstance(params, BaseParams)
    present = params.present_joints
    ok = original_keypoints(m, sample_original(m, samples, seed))
    qc = np.clip(ok.q_canon, params.joint_lowers, params.joint_uppers)
    free_all, lb_all = _free_mask_base(params) if base else _free_mask_ext(params)  # type: ignore[arg-type]
    v = params.to_vector().copy()
    pairs = _base_spacing(params) if base else []  # type: ignore[arg-type]
    sq0 = sq1 = 0.0
    n_err = nfev = 0
    notes: list[str] = []
    for fingers, group in _group_masks(base):
        free = free_all & group
        if not free.any():
            continue
        x, s0, s1, ne, nf = _fit_group(v, free, lb_all, fingers, ok, qc, present, base)
        w = v.copy()
        w[free] = x
        # base form: a fit that pulls a finger's base onto its neighbour's (a palm piece the canonical
        # hand cannot follow, e.g. the Schunk SVH's ring/little carrier) would leave parallel fingers
        # intersecting at rest: refit with each base kept within half the measured slack of its place
        close = [(f, g, i, k) for f, g, i, k, d0, least in pairs if free[i] and free[k]
                 and np.sign(d0) * (w[i] - w[k]) < least - 1e-9]
        if close:
            lb_s, ub_s = _spacing_bounds(v, pairs)
            x, s0, s1, ne, nf2 = _fit_group(v, free, np.maximum(lb_all, lb_s), fingers, ok, qc, present, base, ub_s)
            nf += nf2
            for f, g, i, k in close:
                notes.append(f"approximation: the base fit would move the {f} and {g} finger bases to "
                             f"y = {w[i] * 1e3:+.1f} / {w[k] * 1e3:+.1f} mm (measured {v[i] * 1e3:+.1f} / {v[k] * 1e3:+.1f}), "
                             f"intersecting at rest: fitted with each base kept near its measured place instead")
        v[free] = x
        sq0, sq1, n_err, nfev = sq0 + s0, sq1 + s1, n_err + ne, nfev + nf
    v = normalise(v, base)
    new = (BaseParams if base else ExtendedParams).from_vector(np.round(v, DECIMALS) + 0.0)
    rms0 = float(np.sqrt(sq0 / max(n_err, 1)) * 1e3)
    rms1 = float(np.sqrt(sq1 / max(n_err, 1)) * 1e3)
    return new, FitResult(rms0, rms1, nfev, samples, notes)


def normalise(v: np.ndarray, base: bool) -> np.ndarray:
    """Unit axes and rpy wrapped into (-pi, pi] (a copy of the parameter vector ``v``)."""
    v = v.copy()
    if base:
        for s in (slice(32, 35), slice(35, 38)):
            n = np.linalg.norm(v[s])
            if n > 1e-12:
                v[s] /= n
    else:
        axes = v[93:129].reshape(12, 3)
        n = np.linalg.norm(axes, axis=1, keepdims=True)
        axes = np.where(n > 1e-12, axes / np.maximum(n, 1e-12), axes)
        v[93:129] = axes.ravel()
        o = v[21:93].reshape(12, 6)
        o[:, 3:] = (o[:, 3:] + np.pi) % (2 * np.pi) - np.pi
        v[21:93] = o.ravel()
    return v


def rounded(params: Params) -> Params:
    """``params`` normalised and rounded to :data:`DECIMALS` (what is committed without a fit)."""
    base = isinstance(params, BaseParams)
    return type(params).from_vector(np.round(normalise(params.to_vector(), base), DECIMALS) + 0.0)


__all__ = ["fit", "FitResult", "normalise", "rounded", "DECIMALS"]
