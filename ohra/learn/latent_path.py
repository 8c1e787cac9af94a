"""Paths through the morphology VAE's latent space between two hands, measured in fingertips.

A path's length is the distance the q = 0 fingertips of its decoded hands travel (:func:`tip_moves`).
Three ways to place ``n`` hands between two mean latents (``VAEBundle.interpolate``'s ``spacing``):

* ``"even"``: the straight latent line at even steps;
* ``"arc"``: the straight line at equal fingertip arc length (:func:`arc_length_alphas`);
* ``"geodesic"``: a bent latent path that shortens the fingertips' way (:func:`geodesic_latents`):
  the interior hands start on the ``"arc"`` line and move to lower the discrete path energy (the
  sum over consecutive hands of their squared fingertip moves, through the differentiable decoder
  and q = 0 tips in closed form, equal to the batched torch FK the training loss uses), then the
  bent path is placed at equal fingertip arc length again and decoded the usual way
  (``project_plausible`` included); it is kept only where it beats the straight ``"arc"`` path.

Why bend: a straight latent line turns Barrett's thumb (pointing to the wrist) towards Shadow's
thumb keeping roughly its length, and a thumb of constant length turning the shortest way cannot
move its tip less than ~21 mm per step over 15 steps (``benchmarks/bench_vae.py``,
``turning_thumb_bound``); a hand in between may have a shorter thumb, whose tip then cuts the
corner (the chord between the two thumb tips is ~19 % shorter than the arc).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

from ohra.learn.fk_torch import finger_presence, link_presence
from ohra.learn.sampler import LENGTHS, LOWERS, PALM, UPPERS, XYZ

if TYPE_CHECKING:  # pragma: no cover
    from ohra.learn.morph import VAEBundle

ARC_DENSITY = 16  # dense samples of the latent path per interpolation step, for the arc length
GEODESIC_ITERATIONS = 300  # Adam steps of the path energy (cosine-decayed step; 400-800 gave no better worst pair)
GEODESIC_LR = 0.05  # first Adam step in latent units (registered hands' latents have norm ~3-8)
GEODESIC_CHECKS = 8  # times the bent path is decoded the usual way and kept if it is the best so far
TIP_SCALE_M = 0.01  # fingertip moves in cm inside the energy (well-scaled gradients)
THUMB_MARGIN = 0.05  # cosine kept between the raw thumb and the palm-centre direction (see _energy)
PRESENCE_WEIGHT = 0.1  # weak: at 10 the path kept every jump where it was and stayed ~21 mm
THUMB_WEIGHT = 100.0
PRIOR_WEIGHT = 1.0
THUMB_BOX_MARGIN_M = 0.005  # how far a thumb base on the path may leave the sampler's thumb box (or the ends')


# -- measuring ------------------------------------------------------------------------------------
def structure(v82: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Joint presence (N, 22) and the left-hand flag (N,) of base vectors (N, 82)."""
    from ohra.learn.encoding_rot6d import is_left

    v = np.atleast_2d(v82)
    return (v[:, LOWERS] != 0) | (v[:, UPPERS] != 0), is_left(v)


def structure_changes(v82: np.ndarray) -> np.ndarray:
    """(N - 1,) True where a step between consecutive hands gains or loses a joint or turns the hand
    from left to right (a jump of the decoded structure)."""
    present, left = structure(v82)
    return ~(np.all(present[1:] == present[:-1], axis=1) & (left[1:] == left[:-1]))


def tip_moves(v82: np.ndarray) -> np.ndarray:
    """(N - 1,) largest q = 0 fingertip move [m] between consecutive hands (N, 82) over the fingers
    present in both, or 0 where a joint appears or vanishes or the hand turns from left to right:
    such a step is a jump of the decoded structure (a segment gains its length, the thumb is
    mirrored) that no spacing of the latent path can make smaller."""
    from ohra.learn.geometry import tips_q0

    v = np.atleast_2d(v82)
    d = np.linalg.norm(np.diff(tips_q0(v), axis=0), axis=-1)  # NaN where a finger is absent at either end
    return np.where(structure_changes(v), 0.0, np.where(np.isnan(d), 0.0, d).max(axis=1))


def _thumb_bases(v82: np.ndarray) -> np.ndarray:
    """(N, 3) thumb bases [m] of base vectors, right-hand form (|y|)."""
    t = np.array(np.atleast_2d(v82)[:, XYZ][:, :3], dtype=float)
    t[:, 1] = np.abs(t[:, 1])
    return t


def thumb_box(v_ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (3,) [m], right-hand form: the sampler's thumb base ranges (the training data's), widened
    to hold the thumb bases of the two end hands (2, 82), which a user's hand may put outside them."""
    from ohra.learn.sampler import DEFAULT_CONFIG as C

    t = _thumb_bases(v_ends)
    lo = np.array([C.thumb_x[0], C.thumb_y[0], C.thumb_z[0]])
    hi = np.array([C.thumb_x[1], C.thumb_y[1], C.thumb_z[1]])
    return np.minimum(lo, t.min(axis=0)), np.maximum(hi, t.max(axis=0))


def thumb_excursion(v82: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Largest distance [m] by which a hand's thumb base (right-hand form) lies outside the box ``lo``-``hi``.
    A tip-only path measure lets a thumb fold back from a base flung out of the palm (Ability -> Shadow: 127 mm
    out on a 55 mm palm; Barrett -> Shadow: 93 mm behind the wrist)."""
    t = _thumb_bases(v82)
    out = np.maximum(lo - t, 0.0) + np.maximum(t - hi, 0.0)
    return float(np.linalg.norm(out, axis=1).max(initial=0.0))


# -- equal arc length -----------------------------------------------------------------------------
def arc_length_resample(vae: "VAEBundle", knots: np.ndarray, n: int, density: int = ARC_DENSITY) -> tuple[np.ndarray, np.ndarray]:
    """``n`` latents on the polyline through ``knots`` (K, d) at equal fingertip arc length, first
    and last knot included, and their parameters (n,) along the polyline (0 at the first knot, 1 at
    the last, knots evenly spaced in the parameter).

    The polyline is decoded at ``density * (n - 1) + 1`` even parameters; the arc length is the
    running sum of :func:`tip_moves` (the largest fingertip move of each dense step, so that it
    bounds every fingertip's path), and the parameters are its inverse at ``n`` equal lengths
    (linear within a dense step). A change of structure costs nothing (see :func:`tip_moves`): it
    stays inside one dense step, and were it counted, steps would crowd round it and be lost to the
    rest of the path (measured: 63 mm steps). Deterministic.
    """
    knots = np.asarray(knots, dtype=float)
    m = max(int(density), 1) * (n - 1) + 1
    t = np.linspace(0.0, 1.0, m)
    Z = _polyline(knots, t)
    cost = tip_moves(vae.decode_vectors(Z))
    total = float(cost.sum())
    if not np.isfinite(total) or total <= 0.0:
        s = np.linspace(0.0, 1.0, n)
    else:
        cost = cost + 1e-6 * total / len(cost)  # strictly increasing arc length, for the inverse
        arc = np.concatenate([[0.0], np.cumsum(cost)])
        s = np.interp(np.linspace(0.0, arc[-1], n), arc, t)
    s[0], s[-1] = 0.0, 1.0
    z = _polyline(knots, s)
    z[0], z[-1] = knots[0], knots[-1]  # exactly the endpoints, not a rounding of them
    return z, s


def _polyline(knots: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Points (len(t), d) at parameters ``t`` in [0, 1] of the polyline through ``knots`` (K, d)."""
    x = t * (len(knots) - 1)
    i = np.minimum(np.floor(x).astype(int), len(knots) - 2)
    f = (x - i)[:, None]
    return (1.0 - f) * knots[i] + f * knots[i + 1]


def arc_length_alphas(vae: "VAEBundle", mu_a: np.ndarray, mu_b: np.ndarray, n: int, density: int = ARC_DENSITY) -> np.ndarray:
    """(n,) increasing alphas in [0, 1] (0 and 1 included) that split the straight latent line from
    ``mu_a`` to ``mu_b`` into ``n - 1`` steps of equal fingertip arc length
    (:func:`arc_length_resample` on the two-knot polyline). A step then moves every fingertip by
    about ``total / (n - 1)`` at most, where even alphas put the decoder's fast stretches into one or
    two steps (measured: a 34.8 mm step on a path that allows 21 mm)."""
    return arc_length_resample(vae, np.stack([mu_a, mu_b]), n, density)[1]


# -- geodesic -------------------------------------------------------------------------------------
def geodesic_latents(vae: "VAEBundle", mu_a: np.ndarray, mu_b: np.ndarray, n: int,
                     iterations: int = GEODESIC_ITERATIONS, lr: float = GEODESIC_LR) -> tuple[np.ndarray, np.ndarray]:
    """``n`` latents (n, d) from ``mu_a`` to ``mu_b`` (both exactly) on a bent path of short fingertip
    travel, and their parameters (n,) (fraction of the path, 0 to 1); see the module docstring.

    The ``n - 2`` interior latents start on the straight line at equal arc length and take
    ``iterations`` Adam steps (deterministic: no noise) on :func:`_energy`; ``GEODESIC_CHECKS`` times
    (and at the start) the path so far is placed at equal arc length (:func:`arc_length_resample`
    through the latents as knots), decoded the usual way, and kept if its largest fingertip step
    (:func:`tip_moves`) is the smallest yet and it has no more structure changes than the straight
    path. So the result is never worse than ``spacing="arc"`` by that measure, and the optimiser
    cannot add a jump (a joint appearing, a hand turning left/right).
    """
    from ohra.learn.vae import GeometryLoss

    mu_a, mu_b = np.asarray(mu_a, dtype=float), np.asarray(mu_b, dtype=float)
    alphas = arc_length_alphas(vae, mu_a, mu_b, n)
    best_z = (1.0 - alphas)[:, None] * mu_a + alphas[:, None] * mu_b
    best_s = alphas
    V0 = vae.decode_vectors(best_z)
    best = float(tip_moves(V0).max())
    jumps = int(structure_changes(V0).sum())
    if n < 3 or best == 0.0:
        return best_z, best_s
    lo, hi = thumb_box(V0[[0, -1]])
    excursion = max(thumb_excursion(V0, lo, hi), THUMB_BOX_MARGIN_M)
    z0 = best_z
    geom = GeometryLoss(vae.model.config, vae.standardizer.mean, vae.standardizer.std)
    ends = torch.as_tensor(z0[[0, -1]], dtype=torch.float32)
    with torch.no_grad():
        logits0 = vae.model.decode(torch.as_tensor(z0, dtype=torch.float32))["presence"]
    radius = float(max(np.linalg.norm(mu_a), np.linalg.norm(mu_b)))
    box = (torch.as_tensor(lo - THUMB_BOX_MARGIN_M, dtype=torch.float32), torch.as_tensor(hi + THUMB_BOX_MARGIN_M, dtype=torch.float32))
    inner = torch.as_tensor(z0[1:-1], dtype=torch.float32).clone().requires_grad_(True)
    opt = torch.optim.Adam([inner], lr=lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, max(int(iterations), 1))
    every = max(int(iterations) // GEODESIC_CHECKS, 1)
    for it in range(1, int(iterations) + 1):
        z = torch.cat([ends[:1], inner, ends[1:]])
        # autograd.grad, not backward: the shared model's parameters get no .grad
        (inner.grad,) = torch.autograd.grad(_energy(vae, geom, z, logits0, radius, box), inner)
        opt.step()
        sched.step()
        if it % every == 0 or it == iterations:
            knots = np.concatenate([mu_a[None], inner.detach().double().numpy(), mu_b[None]])
            # the latents as they are (equal energy steps), and re-placed at equal arc length
            for z_s, s in ((knots, np.linspace(0.0, 1.0, n)), arc_length_resample(vae, knots, n)):
                V = vae.decode_vectors(z_s)
                worst = float(tip_moves(V).max())
                if worst < best and int(structure_changes(V).sum()) <= jumps and thumb_excursion(V, lo, hi) <= excursion:
                    best, best_z, best_s = worst, z_s, s
    return best_z, best_s


def _energy(vae: "VAEBundle", geom, z: torch.Tensor, logits0: torch.Tensor, radius: float,
            box: tuple[torch.Tensor, torch.Tensor] | None = None) -> torch.Tensor:
    """Discrete path energy of latents ``z`` (n, d) and the terms that keep the path where the
    decoder's plain output is what ``decode`` returns.

    * path: sum over consecutive hands of squared q = 0 fingertip moves [cm^2] of the fingers present
      in both (links of the presence both share, from the starting path), right-hand form;
    * presence: each joint / left-flag logit keeps the side it had on the starting path (hinge at half
      its starting size, at most 0.5), so no joint appears, vanishes or flips handedness elsewhere;
    * thumb: the raw thumb keeps ``THUMB_MARGIN`` of cosine away from the palm centre and its base at
      y >= 0 (``project_plausible`` would turn or clamp it there, which the energy cannot see);
    * prior: latents stay within the larger endpoint norm (decoded hands stay like the training data);
    * box: the raw thumb base stays in ``box`` (lo, hi) (:func:`thumb_box`, right-hand form), inside the
      same thumb term's weight (the path term alone flung a thumb base 93 mm behind the wrist).
    """
    out = vae.model.decode(z)
    present = logits0[:, :22] > 0
    both = present[1:] & present[:-1]
    raw = out["cont"] * geom.std + geom.mean
    direction = geom.thumb_rotation(raw)[:, :, 2]  # (n, 3) the thumb's q = 0 direction
    t0, t1 = _tips_q0(raw[:-1], direction[:-1], both), _tips_q0(raw[1:], direction[1:], both)
    sq = ((t1 - t0) / TIP_SCALE_M).pow(2).sum(-1) * finger_presence(both)  # (n - 1, 5) [cm^2]
    path = sq.sum()
    sign = torch.sign(logits0)
    presence = torch.relu(0.5 * logits0.abs().clamp(max=1.0) - sign * out["presence"]).sum()
    base = raw[:, XYZ.start : XYZ.start + 3]
    to_centre = torch.stack([-base[:, 0], -base[:, 1], raw[:, PALM] - base[:, 2]], dim=1)
    cos = (direction * to_centre).sum(-1) / to_centre.norm(dim=-1).clamp(min=1e-9)
    thumb = (torch.relu(cos + THUMB_MARGIN).pow(2) + torch.relu(-base[:, 1] / TIP_SCALE_M).pow(2)).sum()
    if box is not None:
        thumb = thumb + ((torch.relu(box[0] - base) + torch.relu(base - box[1])) / TIP_SCALE_M).pow(2).sum()
    prior = torch.relu(z.norm(dim=1) - radius).pow(2).sum()
    return path + PRESENCE_WEIGHT * presence + THUMB_WEIGHT * thumb + PRIOR_WEIGHT * prior


def _tips_q0(raw: torch.Tensor, thumb_dir: torch.Tensor, present: torch.Tensor) -> torch.Tensor:
    """q = 0 fingertips (B, 5, 3) [m] of raw decoded continuous blocks (B, C) with joint presence
    (B, 22): at q = 0 every finger is straight, so a tip is its base plus its reach along its
    direction (the thumb's mounting z, +z for the others; the little metacarpal joint at 0 leaves
    the knuckle in place), as :func:`ohra.learn.geometry.tips_q0` and the full torch FK
    (:func:`ohra.learn.fk_torch.base_fk`, several times slower per step) compute it."""
    links = link_presence(present).to(raw.dtype)  # (B, 5, 3)
    n = len(raw)
    lengths = raw[:, LENGTHS].reshape(n, 2, 3)
    reach = torch.cat([(lengths[:, :1] * links[:, :1]).sum(-1), (lengths[:, 1:] * links[:, 1:]).sum(-1)], dim=1)  # (B, 5)
    d = torch.zeros(n, 5, 3, dtype=raw.dtype)
    d[:, 1:, 2] = 1.0
    d = torch.cat([thumb_dir[:, None], d[:, 1:]], dim=1)
    return raw[:, XYZ].reshape(n, 5, 3) + d * reach[..., None]


__all__ = ["ARC_DENSITY", "tip_moves", "thumb_box", "thumb_excursion", "structure_changes", "arc_length_resample", "arc_length_alphas", "geodesic_latents"]
