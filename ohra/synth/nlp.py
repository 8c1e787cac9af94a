"""The force-closure grasp NLP (CasADi + IPOPT) for one canonical hand and one object.

Decision variables (:mod:`ohra.synth.constraints.variables`): palm translation ``t`` (object frame,
m), a rotation-vector increment ``w`` about a sampled initial orientation ``R0`` (``R = R0 Exp(w)``),
the movable joints, and one contact force per contact (object frame, normalised units). Contacts are
the end sphere of the last present segment of every present finger (plus the palm face for hands
with fewer than three fingers, whose point contacts cannot resist every wrench).

Constraints, one builder per family in :mod:`ohra.synth.constraints`, stacked in this order: contact
spheres on the surface (``-0.5 mm <= sdf - r <= 1 mm``), every other capsule sample and palm sample
at least 1 mm clear of the object, different fingers' capsules at least 1 mm apart (a separating
plane per capsule pair, whose 4 variables follow the forces in ``x``), friction cones with the design
friction ``mu`` (0.5, well below the simulator's 3.0) and a unit minimum normal force, and force and
torque balance. Objective: small forces plus a posture prior. The object is a C2 cubic B-spline that
interpolates its SDF grid (coefficients by scipy's prefilter, milliseconds). One solver per (hand,
object) is reused across all restarts, which differ only in their parameters (``R0``, posture prior)
and initial guesses (palm pose and joints from :mod:`ohra.synth.init`; every force a unit push toward
the object's centre); building one takes ~0.2 s for a 4-finger hand (~0.5 s for a hand's first
object), so it is rebuilt per object rather than carrying a ~100k-coefficient SDF as an NLP
parameter. IPOPT runs with an L-BFGS Hessian by default (see :class:`NLPSettings`).

The row order is part of the behaviour: under a permutation of the same rows IPOPT and MUMPS round
differently, and about half of the starts then end in another local optimum (with the same
statistics: converged share, objective, iterations). Stacking by family replaced the earlier
per-link interleaving of contact and clearance rows this way (rows permuted back to the old order
reproduce the old solutions bit for bit).
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ohra.canonical.couplings import Coupling, project, residual
from ohra.canonical.kinematics import HandModel
from ohra.canonical.params import FINGER_GAP
from ohra.errors import OhraError, is_finite_real, is_whole
from ohra.objects.model import ObjectModel
from ohra.rotations import matrix_to_rot6d
from ohra.synth.constraints import ConstraintBlock, stack
from ohra.synth.constraints.clearance import clearance
from ohra.synth.constraints.contact import contact_band
from ohra.synth.constraints.coupling import couplings as coupling_rows
from ohra.synth.constraints.finger_pairs import (capsule_pairs, capsule_reach, finger_pairs, initial_planes, pair_reach,
                                                 select_capsule_pairs, select_pairs)
from ohra.synth.constraints.friction import friction_cones
from ohra.synth.constraints.objective import grasp_objective
from ohra.synth.constraints.sdf import SdfQuery, sdf_bspline
from ohra.synth.constraints.variables import GraspVariables, grasp_variables
from ohra.synth.constraints.wrench import wrench_balance

SUCCESS_STATUSES = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
MAX_VIOLATION = 1e-3  # a solve counts as a success only if no row is violated by more than this


@dataclass(frozen=True)
class NLPSettings:
    """Settings of the force-closure NLP (:class:`GraspNLP`): design friction, contact band and clearances [m],
    cost weights, IPOPT options, how fingers are kept apart, and the hand's couplings. Checked on construction
    (:class:`~ohra.errors.OhraError` naming the setting)."""

    mu: float = 0.5  # design friction
    contact_band: tuple[float, float] = (-0.0005, 0.001)  # m, sdf - r at the contacts
    clearance: float = 0.001  # m, other links and palm
    finger_gap: float = FINGER_GAP  # m between different fingers
    w_force: float = 1e-2
    w_posture: float = 1e-1
    torque_length: float = 0.05  # m, torque normalisation
    max_iter: int = 300
    sdf_cells: int = 40
    tol: float = 1e-4  # IPOPT optimality tolerance; constraints keep constr_viol_tol 1e-4 (0.1 mm). 1e-6 cost 25 % more time for no feasibility gain
    palm_contact: bool = False  # also make the palm a contact for hands with three or more fingers
    pair_margin: float = 0.01  # m: finger-pair constraints only for spheres that can come this close to touching
    # which long links (core >= 2 cm) also keep their middles apart: "all", "fingertips" or "none".
    # "all" cut self-intersecting solutions from 13/23 to 7/24 (Shadow) and 0/24 (leap_3333) with no
    # slower solves (fewer iterations)
    middle_spheres: str = "all"
    # how different fingers are kept apart: "capsules" (exact: a separating plane per capsule pair,
    # every finger pair) or "spheres" (the capsules' end and middle spheres, neighbour fingers only;
    # ``pair_margin`` and ``middle_spheres`` apply to it). On 8 objects x 16 starts Shadow's exactly
    # self-colliding solutions fell from 28 % of starts to 0 (benchmarks/results/yield.md)
    finger_pairs: str = "capsules"
    # "limited-memory" (L-BFGS) or "exact". The exact Hessian through the SDF spline costs ~6 ms per
    # evaluation for a 4-finger hand; L-BFGS needs about as many iterations at a third of the time
    # and converged more often on YCB objects.
    hessian: str = "limited-memory"
    mu_oracle: str = "probing"  # IPOPT's barrier update; converged on 24/24 YCB starts where "quality-function" did 21/24
    # the hand's joint couplings (``ohra.get_couplings``); non-empty adds equality rows after every
    # other family (so an uncoupled hand's rows, and its solutions, are unchanged)
    couplings: tuple[Coupling, ...] = ()

    def __post_init__(self) -> None:
        choices = {"middle_spheres": ("all", "fingertips", "none"), "finger_pairs": ("capsules", "spheres"),
                   "hessian": ("limited-memory", "exact"), "mu_oracle": ("probing", "quality-function", "loqo")}
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise OhraError(f"NLPSettings.{name} must be one of {', '.join(allowed)}, got {getattr(self, name)!r}")
        for name in ("mu", "clearance", "finger_gap", "w_force", "w_posture", "torque_length", "tol", "pair_margin"):
            v = getattr(self, name)
            if not is_finite_real(v) or v < 0:
                raise OhraError(f"NLPSettings.{name} must be a finite number >= 0, got {v!r}")
        for name in ("max_iter", "sdf_cells"):
            v = getattr(self, name)
            if not is_whole(v) or v < 1:
                raise OhraError(f"NLPSettings.{name} must be a whole number >= 1, got {v!r}")
        lo, hi = self.contact_band
        if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
            raise OhraError(f"NLPSettings.contact_band must be (low, high) [m] with low <= high, got {self.contact_band!r}")


def capsule_pair_indices(hand: HandModel, v: GraspVariables, s: NLPSettings) -> list[tuple[int, int]]:
    """Capsule pairs (indices into ``v.capsules``) that get a separating plane (``finger_pairs="capsules"``)."""
    if s.finger_pairs != "capsules":
        return []
    return select_capsule_pairs([c[3] for c in v.capsules], [c[2] for c in v.capsules], capsule_reach(hand), s.finger_gap, s.pair_margin)


def _finger_pair_block(hand: HandModel, v: GraspVariables, s: NLPSettings, planes: ca.SX | None) -> ConstraintBlock:
    if s.finger_pairs == "capsules":
        pairs = capsule_pair_indices(hand, v, s)
        planes = ca.SX.sym("planes", 4 * len(pairs)) if planes is None else planes
        return capsule_pairs(v.capsules, pairs, planes, s.finger_gap)
    if s.finger_pairs != "spheres":
        raise OhraError(f"NLPSettings.finger_pairs must be 'capsules' or 'spheres', got {s.finger_pairs!r}")
    reach = pair_reach(hand, [(sp.link, sp.end) for sp in v.pair_spheres])
    pairs = select_pairs(v.pair_spheres, reach, s.finger_gap, s.pair_margin)
    return finger_pairs(v.pair_spheres, pairs, s.finger_gap)


def constraint_blocks(hand: HandModel, v: GraspVariables, center: np.ndarray, s: NLPSettings,
                      planes: ca.SX | None = None) -> list[ConstraintBlock]:
    """Every constraint family of the grasp NLP, in row order; ``planes``: the separating-plane
    variables of :func:`capsule_pair_indices` (4 per pair; fresh symbols when None)."""
    palm_gap = 0.0 if v.palm_contact else s.clearance  # a palm contact may touch
    return [
        contact_band(v.sdf, v.contacts, s.contact_band),
        clearance(v.sdf, v.clearance_spheres, s.clearance),
        clearance(v.sdf, v.palm_spheres, palm_gap, name="palm_clearance"),
        _finger_pair_block(hand, v, s, planes),
        friction_cones(v.contacts, s.mu),
        wrench_balance(v.contacts, ca.SX(center), s.torque_length),
    ] + ([coupling_rows(v.q, v.movable, hand.neutral(), s.couplings)] if s.couplings else [])


class GraspNLP:
    """A compiled IPOPT problem for one hand and one object, solved from many starts."""

    def __init__(self, hand: HandModel, obj: ObjectModel, settings: NLPSettings | None = None):
        self.hand, self.obj = hand, obj
        self.s = s = settings or NLPSettings()
        self.grid = obj.sdf(max_cells=s.sdf_cells)
        v = grasp_variables(hand, SdfQuery.from_grid(self.grid), s.palm_contact, s.middle_spheres)
        self.variables = v
        self.movable, self.nq = v.movable, len(v.movable)
        self.contact_links, self.palm_contact = list(v.contact_links), v.palm_contact
        self.n_contacts = len(v.contacts)
        self.pairs = capsule_pair_indices(hand, v, s)
        planes = ca.SX.sym("planes", 4 * len(self.pairs))
        blocks = constraint_blocks(hand, v, obj.center_mass, s, planes)
        g, self.lbg, self.ubg, self.rows = stack(blocks)
        x, p = ca.vertcat(v.x, planes), v.p
        self.force_slice = slice(6 + self.nq, 6 + self.nq + 3 * self.n_contacts)
        self.solver = ca.nlpsol("grasp", "ipopt", {"x": x, "p": p, "f": grasp_objective(v.f, v.q, v.q_pref, s.w_force, s.w_posture),
                                                   "g": v.sdf.resolve(g)}, self._ipopt_options())
        self.n_x = x.shape[0]
        self.lbx, self.ubx = np.full(self.n_x, -np.inf), np.full(self.n_x, np.inf)
        self.lbx[3:6], self.ubx[3:6] = -np.pi, np.pi
        self.lbx[6 : 6 + self.nq] = hand.lower[self.movable]
        self.ubx[6 : 6 + self.nq] = hand.upper[self.movable]
        plane_n = self.force_slice.stop + np.flatnonzero(np.arange(4 * len(self.pairs)) % 4 < 3)
        self.lbx[plane_n], self.ubx[plane_n] = -1.0, 1.0  # unit normals (the |n| <= 1 row keeps them so)
        points = ca.horzcat(*[c.point for c in v.contacts]).T
        normals = ca.horzcat(*[c.normal for c in v.contacts]).T
        self._pose_fn = ca.Function("grasp_geometry", [x, p], [v.R, points, normals])
        ends = ca.horzcat(*[e for c in v.capsules for e in c[:2]]).T if v.capsules else ca.SX(0, 3)
        self._ends_fn = ca.Function("capsule_ends", [x, p], [ends])
        self._radii = np.array([c[2] for c in v.capsules])

    def _ipopt_options(self) -> dict:
        s = self.s
        opts = {"ipopt.print_level": 0, "print_time": 0, "ipopt.sb": "yes", "ipopt.max_iter": s.max_iter,
                "ipopt.tol": s.tol, "ipopt.constr_viol_tol": 1e-4, "ipopt.mu_strategy": "adaptive",
                "ipopt.mu_oracle": s.mu_oracle}
        if s.hessian != "exact":
            opts["ipopt.hessian_approximation"] = "limited-memory"
        return opts

    def _initial_guess(self, p: np.ndarray, t0: np.ndarray, q0: np.ndarray) -> np.ndarray:
        """x0: the start's palm translation and joints, no rotation increment, and every contact force
        a unit push from its contact's position at the start toward the object's centre of mass.

        Against zero forces this cut IPOPT iterations by ~15 % and Shadow's self-intersecting
        solutions by half at the same convergence (``benchmarks/results/synth_force_start.md``).
        """
        x0 = np.zeros(self.n_x)
        x0[:3] = t0
        x0[6 : 6 + self.nq] = q0[self.movable]
        _, points, _ = self._pose_fn(x0, p)
        d = self.obj.center_mass - np.asarray(points)
        x0[self.force_slice] = (d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)).ravel()
        if self.pairs:  # each pair's plane between the closest points of the two cores at the start
            ends = np.asarray(self._ends_fn(x0, p)).reshape(-1, 2, 3)
            x0[self.force_slice.stop :] = initial_planes(ends, self._radii, self.pairs)
        return x0

    def _couple(self, q: np.ndarray) -> tuple[np.ndarray, float]:
        """(q projected onto the couplings, largest |residual| before) [rad]. The equality rows hold to
        IPOPT's ``constr_viol_tol`` (1e-4) in the worst case; projecting moves a coupled joint by at
        most that, and makes the grasp exactly coupled for the simulator and the original hand."""
        cs = self.s.couplings
        if not cs:
            return q, 0.0
        res = residual(cs, q)
        return project(cs, q), float(np.abs(res).max()) if res.size else 0.0

    def solve(self, R0: np.ndarray, t0: np.ndarray, q0: np.ndarray, q_pref: np.ndarray) -> dict:
        """Solve from one start.

        Args:
            R0: (3,3) sampled palm orientation in the object frame; the solution is ``R0 Exp(w)``.
            t0: (3,) initial palm translation [m, object frame].
            q0, q_pref: (22,) initial joints and posture prior [rad, canonical order].

        Returns:
            dict with ``grasp`` (31,) (translation, rot6d, 22 joints clipped into the limits),
            IPOPT ``status``, ``success`` (converged and no row violated by more than 1e-3),
            ``violation`` (largest row violation), ``violations`` (per constraint family),
            ``iterations``, ``coupling_residual`` (largest |residual| of the hand's couplings at the
            solver's joints before projection, rad; the returned joints are projected onto the
            couplings, so their residual is rounding), and per contact ``contacts`` (K,3) points [m], ``normals`` (K,3) and
            ``forces`` (K,3) (object frame).
        """
        p = np.concatenate([np.asarray(R0, dtype=float).reshape(-1, order="F"), q_pref[self.movable]])
        x0 = self._initial_guess(p, t0, q0)
        with _interrupts() as interrupted:
            sol = self.solver(x0=x0, p=p, lbx=self.lbx, ubx=self.ubx, lbg=self.lbg, ubg=self.ubg)
        if interrupted():  # CasADi turns Ctrl-C into a failed solve ("NonIpopt_Exception_Thrown"): stop instead
            raise KeyboardInterrupt
        stats = self.solver.stats()
        x = np.asarray(sol["x"]).ravel()
        over = np.maximum(np.maximum(self.lbg - np.asarray(sol["g"]).ravel(), np.asarray(sol["g"]).ravel() - self.ubg), 0.0)
        viol = float(over.max()) if over.size else 0.0
        R, contacts, normals = (np.asarray(a) for a in self._pose_fn(x, p))
        q = self.hand.neutral()
        # IPOPT may relax bounds by ~1e-8; clip so the grasp is exactly within the limits
        q[self.movable] = np.clip(x[6 : 6 + self.nq], self.hand.lower[self.movable], self.hand.upper[self.movable])
        q, coupling_res = self._couple(q)
        return {
            "grasp": np.concatenate([x[:3], matrix_to_rot6d(R), q]), "status": stats.get("return_status", "unknown"),
            "success": bool(stats.get("success", False)) and viol <= MAX_VIOLATION, "violation": viol,
            "violations": {name: float(over[sl].max()) if sl.stop > sl.start else 0.0 for name, sl in self.rows.items()},
            "iterations": int(stats.get("iter_count", -1)), "coupling_residual": coupling_res, "contacts": contacts, "normals": normals,
            "forces": x[self.force_slice].reshape(-1, 3),
        }


@contextmanager
def _interrupts():
    """Yield a function telling whether Ctrl-C (SIGINT) arrived inside the block.

    CasADi catches the KeyboardInterrupt raised inside IPOPT's callbacks and returns a failed solve, so a run
    would go on, store that solve as a failure and exit 0. Where SIGINT is ignored (pool workers leave it to
    the driver) or this is not the main thread, nothing is installed."""
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or previous in (signal.SIG_IGN, None):
        yield lambda: False
        return
    hit: list[int] = []

    def handler(signum, frame):
        hit.append(signum)
        if callable(previous):
            previous(signum, frame)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, handler)
    try:
        yield lambda: bool(hit)
    finally:
        signal.signal(signal.SIGINT, previous)


__all__ = ["GraspNLP", "NLPSettings", "SUCCESS_STATUSES", "capsule_pair_indices", "constraint_blocks", "sdf_bspline"]
