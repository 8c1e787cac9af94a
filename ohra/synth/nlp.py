"""The force-closure grasp NLP (CasADi + IPOPT) for one canonical hand and one object.

Decision variables: palm translation ``t`` (object frame, m), a rotation-vector increment ``w``
about a sampled initial orientation ``R0`` (``R = R0 Exp(w)``), the movable joints, and one contact
force per contact (object frame, normalised units). Contacts are the end sphere of the last present
segment of every present finger (plus the palm face for hands with fewer than three fingers, whose
point contacts cannot resist every wrench).

Constraints: contact spheres on the surface (``-0.5 mm <= sdf - r <= 1 mm``), every other capsule
sample and palm sample at least 1 mm clear of the object, different fingers' samples apart, force
and torque balance, friction cones with the design friction ``mu`` (0.5, well below the simulator's
3.0) and a unit minimum normal force. Objective: small forces plus a posture prior. The object is a
C2 cubic B-spline that interpolates its SDF grid (coefficients by scipy's prefilter, milliseconds).
One solver per (hand, object) is reused across all restarts, which differ only in their parameters
(``R0``, posture prior) and initial guesses; building one takes ~0.2 s for a 4-finger hand (~0.5 s for a hand's first object), so it is
rebuilt per object rather than carrying a ~100k-coefficient SDF as an NLP parameter. IPOPT runs with
an L-BFGS Hessian by default (see :class:`NLPSettings`).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ohra.canonical.kinematics import HandModel
from ohra.objects.model import ObjectModel
from ohra.canonical.urdfgen import palm_geometry
from ohra.synth.fk import frame_transforms

SUCCESS_STATUSES = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
_REACH_CACHE: dict[tuple, np.ndarray] = {}  # GraspNLP._pair_reach per hand (a few hands per process)


@dataclass(frozen=True)
class NLPSettings:
    mu: float = 0.5  # design friction
    contact_band: tuple[float, float] = (-0.0005, 0.001)  # m, sdf - r at the contacts
    clearance: float = 0.001  # m, other links and palm
    finger_gap: float = 0.001  # m between different fingers
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
    # "limited-memory" (L-BFGS) or "exact". The exact Hessian through the SDF spline costs ~6 ms per
    # evaluation for a 4-finger hand; L-BFGS needs about as many iterations at a third of the time
    # and converged more often on YCB objects.
    hessian: str = "limited-memory"
    mu_oracle: str = "probing"  # IPOPT's barrier update; converged on 24/24 YCB starts where "quality-function" did 21/24


def sdf_bspline(grid) -> ca.Function:
    """The C2 cubic B-spline that interpolates an SDF grid exactly at its nodes, as a CasADi Function.

    The coefficients come from scipy's recursive prefilter (mirror boundary), the same spline as
    ``scipy.ndimage.map_coordinates(order=3, mode="mirror")``; this takes milliseconds where
    ``casadi.interpolant(..., "bspline")`` solves a 100k-unknown fit in seconds. Valid inside the grid.
    """
    from scipy import ndimage

    n = np.array(grid.shape)
    coeffs = np.pad(ndimage.spline_filter(grid.values, order=3, mode="mirror"), 1, mode="reflect")
    knots = [list(grid.origin[d] + grid.spacing * np.arange(-3, n[d] + 3)) for d in range(3)]
    spline = ca.Function.bspline("sdf_spline", knots, coeffs.ravel(order="F").tolist(), [3, 3, 3], 1, {})
    x = ca.MX.sym("x", 3)
    return ca.Function("sdf", [x], [spline(x)])


def _rodrigues(w: ca.SX) -> ca.SX:
    th = ca.sqrt(ca.dot(w, w) + 1e-12)
    K = ca.skew(w / th)
    return ca.SX.eye(3) + ca.sin(th) * K + (1 - ca.cos(th)) * (K @ K)


class GraspNLP:
    """A compiled IPOPT problem for one hand and one object, solved from many starts."""

    def __init__(self, hand: HandModel, obj: ObjectModel, settings: NLPSettings | None = None):
        self.hand, self.obj = hand, obj
        self.s = s = settings or NLPSettings()
        grid = obj.sdf(max_cells=s.sdf_cells)
        self.grid = grid
        sdf_fn = sdf_bspline(grid)
        lo, hi = grid.origin, grid.upper

        ps = ca.SX.sym("p", 3)
        pcl = ca.fmin(ca.fmax(ps, lo + 1e-6), hi - 1e-6)
        # an SX call node (never inlined: the B-spline node has no SX form)
        dist = sdf_fn.call([pcl], False, True)[0] + ca.sqrt(ca.dot(ps - pcl, ps - pcl) + 1e-12) - 1e-6
        phi_f = ca.Function("phi", [ps], [dist])
        # SDF queries become placeholders, evaluated at the end by one mapped call (one graph node
        # for all of them: ~15 % faster derivatives than one call node per query)
        _pending: list = []

        def phi(p):
            sym = ca.SX.sym(f"phi{len(_pending)}")
            _pending.append((sym, p))
            return sym
        grad_phi = ca.Function("grad_phi", [ps], [ca.gradient(dist, ps)])

        self.movable = np.flatnonzero(hand.movable_joints)
        nq = len(self.movable)
        caps = hand.capsule_specs
        fingers = sorted({c[1] for c in caps})
        last = {f: max((c for c in caps if c[1] == f), key=lambda c: ("proximal", "middle", "distal").index(c[0].split("_")[1])) for f in fingers}
        self.contact_links = [last[f][0] for f in fingers]
        R_palm, depth = palm_geometry(hand.params)
        self.palm_contact = len(fingers) < 3 or s.palm_contact
        n_c = len(fingers) + (1 if self.palm_contact else 0)
        self.n_contacts = n_c

        t = ca.SX.sym("t", 3)
        w = ca.SX.sym("w", 3)
        qm = ca.SX.sym("q", nq)
        f = ca.SX.sym("f", 3 * n_c)
        R0 = ca.SX.sym("R0", 3, 3)
        q_pref = ca.SX.sym("q_pref", nq)
        center = ca.SX(obj.center_mass)
        q_full = ca.SX.zeros(22)
        fixed = np.clip(np.zeros(22), hand.lower, hand.upper)
        for k in range(22):
            q_full[k] = fixed[k]
        for i, k in enumerate(self.movable):
            q_full[int(k)] = qm[i]
        R = R0 @ _rodrigues(w)
        links = [c[0] for c in caps]
        poses = dict(zip(links, frame_transforms(hand, q_full, links))) if links else {}

        g, lbg, ubg = [], [], []
        contact_pts, normals = [], []
        spheres: list[tuple[ca.SX, float, int, str, int]] = []  # (world point, radius, finger, link, sample index)
        for (link, fi, r, L) in caps:
            Rl, pl = poses[link]
            a = R @ (pl + Rl @ ca.SX([0, 0, r])) + t
            b = R @ (pl + Rl @ ca.SX([0, 0, L - r])) + t
            samples = [a, b] if L - 2 * r < 0.02 else [a, 0.5 * (a + b), b]
            if link in self.contact_links:
                d = phi(b)
                g.append(d - r); lbg.append(s.contact_band[0]); ubg.append(s.contact_band[1])
                grad = grad_phi(b)
                n = grad / ca.sqrt(ca.dot(grad, grad) + 1e-12)
                contact_pts.append(b - r * n)
                normals.append(n)
                samples = samples[:-1]
            for p in samples:
                g.append(phi(p) - r); lbg.append(s.clearance); ubg.append(ca.inf)
            spheres += [(p, r, fi, link, k) for k, p in enumerate([a, b])]
            if L - 2 * r >= 0.02 and (s.middle_spheres == "all" or (s.middle_spheres == "fingertips" and link in self.contact_links)):
                spheres.append((0.5 * (a + b), r, fi, link, 2))  # long links can cross mid-segment
        # palm: spheres of the palm's half-thickness over its disc
        pr = depth / 2.0
        ys = np.linspace(-(R_palm - pr), R_palm - pr, 4)
        zs = np.linspace(pr, 2 * R_palm - pr, 4)
        for y in ys:
            for z in zs:
                if y * y + (z - R_palm) ** 2 <= (R_palm - pr) ** 2 + 1e-9:
                    p = R @ ca.SX([0.0, y, z]) + t
                    g.append(phi(p) - pr); lbg.append(s.clearance if not self.palm_contact else 0.0); ubg.append(ca.inf)
        if self.palm_contact:
            pc = R @ ca.SX([depth / 2.0, 0.0, R_palm]) + t
            d = phi(pc)
            g.append(d); lbg.append(s.contact_band[0]); ubg.append(s.contact_band[1])
            grad = grad_phi(pc)
            n = grad / ca.sqrt(ca.dot(grad, grad) + 1e-12)
            contact_pts.append(pc)
            normals.append(n)
        # different fingers keep apart: the thumb against every finger, other fingers against their
        # neighbours (non-neighbours cannot meet without passing through the finger between them);
        # knuckle spheres (first sample of the first segment) sit at fixed spacing and are skipped, and
        # so are pairs that never come close anywhere in the joint space (``_pair_reach``). Long links
        # add a middle sphere (end spheres alone let two closing fingertips cross: ~20 % of 4-finger
        # solutions); the pipeline still re-checks every solution exactly with Coal
        order = [f for f in fingers if f != 0]
        neighbours = {(a, b) for a, b in zip(order, order[1:])} | {(0, f) for f in order}
        first_link = {f: min((c for c in caps if c[1] == f), key=lambda c: ("proximal", "middle", "distal").index(c[0].split("_")[1]))[0] for f in fingers}
        reach = self._pair_reach(hand, [(sp[3], sp[4]) for sp in spheres])
        for i in range(len(spheres)):
            for j in range(i + 1, len(spheres)):
                pa, ra, fa, la, ka = spheres[i]
                pb_, rb, fb, lb, kb = spheres[j]
                if (min(fa, fb), max(fa, fb)) not in neighbours:
                    continue
                if (la == first_link[fa] and ka == 0) and (lb == first_link[fb] and kb == 0):
                    continue
                if reach[i, j] > ra + rb + s.finger_gap + s.pair_margin:
                    continue  # these two spheres never come close anywhere in the joint space
                dd = pa - pb_
                g.append(ca.dot(dd, dd) - (ra + rb + s.finger_gap) ** 2); lbg.append(0.0); ubg.append(ca.inf)
        # wrench balance and friction cones
        F = ca.SX.zeros(3)
        Tq = ca.SX.zeros(3)
        for i, (p, n) in enumerate(zip(contact_pts, normals)):
            fi_ = f[3 * i : 3 * i + 3]
            fn = -ca.dot(fi_, n)
            ft = fi_ + fn * n
            g.append(fn); lbg.append(1.0); ubg.append(ca.inf)
            # the circular cone is shrunk to lie strictly inside the 8-facet cone that Q1 uses, so an
            # equilibrium found here is one of strictly interior forces (force closure, Q1 > 0)
            mu_in = s.mu * np.cos(np.pi / 8) * 0.95
            g.append(mu_in**2 * fn * fn - ca.dot(ft, ft)); lbg.append(0.0); ubg.append(ca.inf)
            F += fi_
            Tq += ca.cross(p - center, fi_) / s.torque_length
        for k in range(3):
            g.append(F[k]); lbg.append(0.0); ubg.append(0.0)
        for k in range(3):
            g.append(Tq[k]); lbg.append(0.0); ubg.append(0.0)
        gvec = ca.vertcat(*g)
        if _pending:
            P = ca.horzcat(*[p for _, p in _pending])
            vals = phi_f.map(len(_pending))(P)
            gvec = ca.substitute([gvec], [ca.vertcat(*[v for v, _ in _pending])], [vals.T])[0]
        J = s.w_force * ca.dot(f, f) + s.w_posture * ca.dot(qm - q_pref, qm - q_pref)
        x = ca.vertcat(t, w, qm, f)
        p_par = ca.vertcat(ca.reshape(R0, 9, 1), q_pref)
        opts = {"ipopt.print_level": 0, "print_time": 0, "ipopt.sb": "yes", "ipopt.max_iter": s.max_iter,
                "ipopt.tol": s.tol, "ipopt.constr_viol_tol": 1e-4, "ipopt.mu_strategy": "adaptive",
                "ipopt.mu_oracle": s.mu_oracle}
        if s.hessian != "exact":
            opts["ipopt.hessian_approximation"] = "limited-memory"
        self.solver = ca.nlpsol("grasp", "ipopt", {"x": x, "p": p_par, "f": J, "g": gvec}, opts)
        self.lbg, self.ubg = np.array(lbg, dtype=float), np.array(ubg, dtype=float)
        n_x = x.shape[0]
        self.lbx = np.full(n_x, -np.inf)
        self.ubx = np.full(n_x, np.inf)
        self.lbx[3:6], self.ubx[3:6] = -np.pi, np.pi
        self.lbx[6 : 6 + nq] = hand.lower[self.movable]
        self.ubx[6 : 6 + nq] = hand.upper[self.movable]
        self.n_x, self.nq = n_x, nq
        self._contact_fn = ca.Function("contacts", [x, p_par], [ca.horzcat(*contact_pts).T, ca.horzcat(*normals).T])

    @staticmethod
    def _pair_reach(hand: HandModel, samples: list[tuple[str, int]], n: int = 4096) -> np.ndarray:
        """Smallest distance [m] between capsule spheres over ``n`` seeded configurations within the
        limits: pairs that stay far apart everywhere need no constraint (about half of them).

        Depends only on the hand, so it is cached per hand params (it is ~half of a solver build)."""
        if not samples:
            return np.zeros((0, 0))
        key = None if hand.params is None else (hand.params.to_json(), tuple(samples), n)
        if key is not None and key in _REACH_CACHE:
            return _REACH_CACHE[key]
        caps = hand.capsules(hand.random_configurations(n, seed=0))
        k_of = {name: k for k, name in enumerate(caps.link)}
        ends = {0: caps.p0, 1: caps.p1, 2: 0.5 * (caps.p0 + caps.p1)}  # start, end, middle of each core segment
        pts = np.stack([ends[end][:, k_of[link]] for link, end in samples], axis=1)  # (n, S, 3)
        d = np.full((len(samples), len(samples)), np.inf)
        for i in range(len(samples)):
            d[i] = np.linalg.norm(pts - pts[:, i : i + 1], axis=-1).min(axis=0)
        if key is not None:
            if len(_REACH_CACHE) >= 16:
                _REACH_CACHE.pop(next(iter(_REACH_CACHE)))
            _REACH_CACHE[key] = d
        return d

    def solve(self, R0: np.ndarray, t0: np.ndarray, q0: np.ndarray, q_pref: np.ndarray) -> dict:
        """Solve from one start; returns grasp (31,), status, success, constraint violation, contacts."""
        x0 = np.zeros(self.n_x)
        x0[:3] = t0
        x0[6 : 6 + self.nq] = q0[self.movable]
        # forces start along the direction to the object centre from each contact's rough position
        x0[6 + self.nq :] = np.tile([0.0, 0.0, 0.0], self.n_contacts)
        p = np.concatenate([np.asarray(R0, dtype=float).reshape(-1, order="F"), q_pref[self.movable]])
        sol = self.solver(x0=x0, p=p, lbx=self.lbx, ubx=self.ubx, lbg=self.lbg, ubg=self.ubg)
        stats = self.solver.stats()
        x = np.asarray(sol["x"]).ravel()
        gval = np.asarray(sol["g"]).ravel()
        viol = float(np.maximum(np.maximum(self.lbg - gval, gval - self.ubg), 0.0).max()) if gval.size else 0.0
        w = x[3:6]
        th = np.sqrt(w @ w + 1e-12)
        K = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]) / th
        R = R0 @ (np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K)
        q = np.clip(np.zeros(22), self.hand.lower, self.hand.upper)
        # IPOPT may relax bounds by ~1e-8; clip so the grasp is exactly within the limits
        q[self.movable] = np.clip(x[6 : 6 + self.nq], self.hand.lower[self.movable], self.hand.upper[self.movable])
        from ohra.rotations import matrix_to_rot6d

        grasp = np.concatenate([x[:3], matrix_to_rot6d(R), q])
        contacts, normals = (np.asarray(v) for v in self._contact_fn(x, p))
        forces = x[6 + self.nq :].reshape(-1, 3)
        status = stats.get("return_status", "unknown")
        return {
            "grasp": grasp, "status": status, "success": bool(stats.get("success", False)) and viol <= 1e-3,
            "violation": viol, "iterations": int(stats.get("iter_count", -1)), "contacts": contacts, "normals": normals, "forces": forces,
        }
