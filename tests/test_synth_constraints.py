"""Each constraint family of the grasp NLP on an analytic case with a known value."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from ohra.canonical.kinematics import HandModel
from ohra.hands import get_hand
from ohra.objects.model import SDFGrid
from ohra.synth.constraints import ConstraintBlock, stack
from ohra.synth.constraints.clearance import clearance
from ohra.synth.constraints.contact import contact_band
from ohra.synth.constraints.finger_pairs import finger_pairs, neighbour_pairs, select_pairs
from ohra.synth.constraints.friction import friction_cones, inner_mu
from ohra.synth.constraints.objective import grasp_objective
from ohra.synth.constraints.sdf import SdfQuery
from ohra.synth.constraints.variables import Contact, Sphere, contact_links, grasp_variables
from ohra.synth.constraints.wrench import net_wrench, wrench_balance
from ohra.synth.nlp import NLPSettings, constraint_blocks

R_BALL = 0.04  # m, the analytic sphere object


def _ball() -> SdfQuery:
    return SdfQuery.analytic(lambda p: ca.sqrt(ca.dot(p, p)) - R_BALL)


def _values(block: ConstraintBlock, sdf: SdfQuery | None = None) -> np.ndarray:
    """Numeric rows of a block whose expressions hold only constants (and SDF placeholders)."""
    g = ca.vertcat(*block.g)
    if sdf is not None:
        g = sdf.resolve(g)
    return np.asarray(ca.evalf(g)).ravel()


def _contact(centre, normal, force, radius=0.0) -> Contact:
    c, n = ca.SX(np.asarray(centre, dtype=float)), ca.SX(np.asarray(normal, dtype=float))
    return Contact(c, radius, n, c - radius * n, ca.SX(np.asarray(force, dtype=float)))


@pytest.mark.parametrize("d", [-0.002, 0.0, 0.0007])
def test_contact_band_row_is_the_gap_between_sphere_and_surface(d):
    sdf, r = _ball(), 0.01
    u = np.array([1.0, 2.0, -2.0]) / 3.0
    centre = ca.SX((R_BALL + r + d) * u)
    n = sdf.normal(centre)
    c = Contact(centre, r, n, centre - r * n, ca.SX.zeros(3))
    block = contact_band(sdf, [c], (-0.0005, 0.001))
    assert block.name == "contact" and list(block.lower) == [-0.0005] and list(block.upper) == [0.001]
    assert _values(block, sdf) == pytest.approx([d], abs=1e-12)
    # the normal is the outward radial direction and the contact point sits d off the surface
    assert np.asarray(ca.evalf(n)).ravel() == pytest.approx(u, abs=1e-12)
    assert np.linalg.norm(np.asarray(ca.evalf(c.point)).ravel()) == pytest.approx(R_BALL + d, abs=1e-12)


def test_sdf_normal_is_the_unit_outward_gradient():
    steep = SdfQuery.analytic(lambda p: 3.0 * (ca.sqrt(ca.dot(p, p)) - R_BALL))  # |grad| = 3
    n = np.asarray(ca.evalf(steep.normal(ca.SX([0.0, -0.06, 0.08])))).ravel()
    assert n == pytest.approx([0.0, -0.6, 0.8], abs=1e-12)


def test_clearance_rows_are_gaps_with_a_lower_bound_only():
    sdf = _ball()
    spheres = [Sphere(ca.SX([0.0, 0.0, R_BALL + 0.008 + 0.003]), 0.008, 1, "index_distal", 0),
               Sphere(ca.SX([0.0, -(R_BALL + 0.005 - 0.002), 0.0]), 0.005, -1, "palm", 0)]
    block = clearance(sdf, spheres, 0.001)
    assert _values(block, sdf) == pytest.approx([0.003, -0.002], abs=1e-12)
    assert list(block.lower) == [0.001, 0.001] and np.all(np.isinf(block.upper))


def test_sdf_spline_interpolates_its_grid_and_grows_outside_it():
    h = 0.01
    axes = [np.arange(-5, 6) * h] * 3
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    grid = SDFGrid(np.full(3, -5 * h), h, np.sqrt(X**2 + Y**2 + Z**2) - R_BALL)
    sdf = SdfQuery.from_grid(grid)
    nodes = [(0.02, -0.01, 0.03), (-0.04, 0.0, 0.01), (0.0, 0.0, 0.0)]  # interior nodes
    vals = np.asarray(ca.evalf(sdf.resolve(ca.vertcat(*[sdf.value(ca.SX(p)) for p in nodes])))).ravel()
    assert vals == pytest.approx([np.linalg.norm(p) - R_BALL for p in nodes], abs=1e-9)
    # 3 cm beyond the grid's +x face the distance is the face's value plus 3 cm
    out = np.asarray(ca.evalf(sdf.resolve(sdf.value(ca.SX([0.08, 0.0, 0.0]))))).item()
    assert out == pytest.approx(0.05 - R_BALL + 0.03, abs=2e-6)


def test_finger_pair_row_is_squared_distance_minus_squared_touching_distance():
    a = Sphere(ca.SX([0.0, 0.0, 0.0]), 0.01, 0, "thumb_distal", 1)
    b = Sphere(ca.SX([0.03, 0.04, 0.0]), 0.008, 1, "index_distal", 1)  # 5 cm apart
    block = finger_pairs([a, b], [(0, 1)], gap=0.001)
    assert _values(block) == pytest.approx([0.05**2 - 0.019**2], abs=1e-15)
    touching = Sphere(ca.SX([0.019, 0.0, 0.0]), 0.008, 1, "index_distal", 1)
    assert _values(finger_pairs([a, touching], [(0, 1)], gap=0.001)) == pytest.approx([0.0], abs=1e-15)
    assert list(block.lower) == [0.0] and np.isinf(block.upper[0])


def test_pairs_are_thumb_to_all_and_neighbours_without_knuckles_or_unreachable_ones():
    assert neighbour_pairs([0, 1, 2, 4]) == {(0, 1), (0, 2), (0, 4), (1, 2), (2, 4)}
    sp = [Sphere(ca.SX.zeros(3), 0.01, f, f"{name}_proximal", end)
          for f, name in [(0, "thumb"), (1, "index"), (2, "middle"), (3, "ring")] for end in (0, 1)]
    reach = np.zeros((8, 8))  # every pair can touch
    pairs = select_pairs(sp, reach, gap=0.001, margin=0.01)
    fingers = {(sp[i].finger, sp[j].finger) for i, j in pairs}
    assert fingers == {(0, 1), (0, 2), (0, 3), (1, 2), (2, 3)}  # no (1, 3): not neighbours; no same finger
    assert (2, 4) not in pairs and (0, 2) not in pairs  # two knuckles (first sphere of a finger's first link)
    assert (3, 5) in pairs and (2, 5) in pairs  # index end - middle end, index knuckle - middle end
    # index end and middle end never come closer than touching + gap + margin: no row
    reach[3, 5] = reach[5, 3] = 0.02 + 0.001 + 0.01 + 1e-6
    assert (3, 5) not in select_pairs(sp, reach, gap=0.001, margin=0.01)
    reach[3, 5] = reach[5, 3] = 0.02 + 0.001 + 0.01 - 1e-6
    assert (3, 5) in select_pairs(sp, reach, gap=0.001, margin=0.01)


def test_friction_cone_margin_is_zero_on_the_boundary_and_positive_inside():
    mu = 0.5
    n = [0.0, 0.0, 1.0]  # outward normal; the hand pushes along -z
    fn = 2.0
    on = _contact([0, 0, 0.05], n, [inner_mu(mu) * fn, 0.0, -fn])
    inside = _contact([0, 0, 0.05], n, [0.5 * inner_mu(mu) * fn, 0.0, -fn])
    outside = _contact([0, 0, 0.05], n, [0.0, 1.1 * inner_mu(mu) * fn, -fn])
    v = _values(friction_cones([on, inside, outside], mu))
    assert v[0::2] == pytest.approx([fn, fn, fn])  # normal force rows
    assert v[1] == pytest.approx(0.0, abs=1e-12)
    assert v[3] > 0.1 and v[5] < 0.0
    block = friction_cones([on], mu)
    assert list(block.lower) == [1.0, 0.0] and np.all(np.isinf(block.upper))
    # the cone lies inside the 8-facet pyramid Ferrari-Canny uses
    assert inner_mu(mu) < mu * np.cos(np.pi / 8)


def test_symmetric_opposing_forces_balance_and_a_couple_does_not():
    centre = ca.SX([0.01, 0.02, 0.03])
    p = np.array([0.04, 0.0, 0.0])
    c0 = np.array([0.01, 0.02, 0.03])
    pinch = [_contact(c0 + p, [1, 0, 0], [-3.0, 0, 0]), _contact(c0 - p, [-1, 0, 0], [3.0, 0, 0])]
    assert _values(wrench_balance(pinch, centre, 0.05)) == pytest.approx(np.zeros(6), abs=1e-15)
    couple = [_contact(c0 + p, [1, 0, 0], [0, 2.0, 0]), _contact(c0 - p, [-1, 0, 0], [0, -2.0, 0])]
    F, T = (np.asarray(ca.evalf(e)).ravel() for e in net_wrench(couple, centre, 0.05))
    assert F == pytest.approx(np.zeros(3), abs=1e-15)
    assert T == pytest.approx([0.0, 0.0, 2 * 0.04 * 2.0 / 0.05])  # two arms of 4 cm, 2 units each
    # one force alone: torque about the object centre, not the frame origin
    F, T = (np.asarray(ca.evalf(e)).ravel() for e in net_wrench(couple[:1], centre, 0.05))
    assert F == pytest.approx([0.0, 2.0, 0.0]) and T == pytest.approx([0.0, 0.0, 0.04 * 2.0 / 0.05])
    block = wrench_balance(couple, centre, 0.05)
    assert np.all(block.lower == 0.0) and np.all(block.upper == 0.0) and len(block) == 6


def test_objective_weighs_squared_forces_and_posture_error():
    f, q, qp = ca.SX([1.0, 2.0, 2.0]), ca.SX([0.5, -0.5]), ca.SX([0.25, 0.5])
    assert float(ca.evalf(grasp_objective(f, q, qp, 1e-2, 1e-1))) == pytest.approx(1e-2 * 9 + 1e-1 * (0.0625 + 1.0))


def test_blocks_of_a_real_hand_stack_in_family_order_with_one_contact_per_finger():
    hand = HandModel.from_params(get_hand("leap_2200"))  # two fingers: the palm is a contact too
    v = grasp_variables(hand, _ball())
    last = {f: [c[0] for c in hand.capsule_specs if c[1] == f][-1] for f in (0, 1)}  # specs go proximal first
    assert v.contact_links == contact_links(hand) == (last[0], last[1])
    assert v.palm_contact and len(v.contacts) == 3 and v.f.shape == (9, 1)
    blocks = constraint_blocks(hand, v, np.zeros(3), NLPSettings())
    g, lo, hi, rows = stack(blocks)
    assert list(rows) == ["contact", "clearance", "palm_clearance", "finger_pairs", "friction", "wrench"]
    assert g.shape[0] == len(lo) == len(hi) == sum(len(b) for b in blocks)
    assert len(blocks[0]) == 3 and len(blocks[4]) == 6 and len(blocks[5]) == 6
    assert np.all(lo[rows["palm_clearance"]] == 0.0)  # a palm contact may touch


def test_forces_start_as_unit_pushes_toward_the_object_centre():
    from ohra.objects.model import ObjectModel
    from ohra.synth.init import initial_poses
    from ohra.synth.nlp import GraspNLP

    hand = HandModel.from_params(get_hand("leap_2200"))
    obj = ObjectModel.builtin("box")
    nlp = GraspNLP(hand, obj)
    st = initial_poses(hand, obj, 1, np.random.default_rng(0))[0]
    p = np.concatenate([st["R0"].reshape(-1, order="F"), st["q_pref"][nlp.movable]])
    x0 = nlp._initial_guess(p, st["t0"], st["q0"])
    forces = x0[nlp.force_slice].reshape(-1, 3)
    _, points, _ = nlp._pose_fn(x0, p)
    toward = obj.center_mass - np.asarray(points)
    assert np.linalg.norm(forces, axis=1) == pytest.approx(np.ones(3))
    assert np.einsum("ij,ij->i", forces, toward / np.linalg.norm(toward, axis=1, keepdims=True)) == pytest.approx(np.ones(3))
