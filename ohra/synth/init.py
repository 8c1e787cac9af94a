"""Initial guesses for the grasp NLP: approach directions covering the sphere, palm facing the object."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ohra.canonical.couplings import Coupling, project
from ohra.canonical.kinematics import HandModel
from ohra.objects.model import ObjectModel
from ohra.canonical.urdfgen import palm_geometry


def fibonacci_sphere(n: int) -> np.ndarray:
    """(n,3) unit vectors spread evenly over the sphere."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    th = np.pi * (1 + 5**0.5) * i
    return np.stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)], axis=1)


def initial_poses(hand: HandModel, obj: ObjectModel, n: int, rng: np.random.Generator,
                  couplings: Sequence[Coupling] = ()) -> list[dict]:
    """``n`` starts: approach direction d (Fibonacci sphere, randomly rotated), palm normal -d, random
    roll, palm centre ``0.8 r_obj + U(3, 6) cm`` out along d and shifted 4 cm back along the fingers;
    open pre-shape (25 % of each range from the lower limit) and a randomised posture prior.

    With ``couplings`` the pre-shape and the prior are projected onto them (coupled joints follow
    their drivers, then clipped into the limits), so every start is a pose the hand can take and
    the prior does not pull against the coupling rows."""
    R_palm, _ = palm_geometry(hand.params)
    dirs = fibonacci_sphere(max(n, 1))
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    dirs = dirs @ Q.T
    out = []
    c = obj.center_mass
    span = hand.upper - hand.lower
    for d in dirs[:n]:
        x = -d
        v = rng.normal(size=3)
        z = v - x * (v @ x)
        z /= np.linalg.norm(z)
        y = np.cross(z, x)
        R0 = np.column_stack([x, y, z])
        palm_centre = c + d * (0.8 * obj.radius + rng.uniform(0.03, 0.06)) - z * 0.04
        t0 = palm_centre - R0 @ np.array([0.0, 0.0, R_palm])
        q0 = hand.lower + 0.25 * span
        q_pref = hand.lower + rng.uniform(0.2, 0.5, size=22) * span
        if couplings:
            q0 = np.clip(project(couplings, q0), hand.lower, hand.upper)
            q_pref = np.clip(project(couplings, q_pref), hand.lower, hand.upper)
        out.append({"R0": R0, "t0": t0, "q0": q0, "q_pref": q_pref})
    return out
