"""Objective: small contact forces plus a posture prior, ``w_force |f|^2 + w_posture |q - q_pref|^2``.

The force term picks, among the equilibria, the one with the least squeeze (forces are in units of
the minimum normal force); the posture term pulls the joints toward a per-start random prior, which
spreads the solutions of different starts over the joint space.
"""

from __future__ import annotations

import casadi as ca


def grasp_objective(f: ca.SX, q: ca.SX, q_pref: ca.SX, w_force: float, w_posture: float) -> ca.SX:
    """The scalar cost: ``f`` all contact forces (normalised units), ``q`` and ``q_pref`` the movable
    joints and their prior [rad]."""
    return w_force * ca.dot(f, f) + w_posture * ca.dot(q - q_pref, q - q_pref)
