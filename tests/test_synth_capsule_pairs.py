"""Exact finger-pair rows (a separating plane per capsule pair) and the self-collisions they prevent."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from ohra.canonical.kinematics import HandModel
from ohra.hands import get_hand
from ohra.objects.procedural import procedural_objects
from ohra.synth.constraints.finger_pairs import (_segment_distance, capsule_pairs, initial_planes, segment_closest,
                                                 select_capsule_pairs)
from ohra.synth.init import initial_poses
from ohra.synth.nlp import GraspNLP, NLPSettings

R = 0.007  # m, capsule radius of the analytic cases
GAP = 0.001


def _rows(ends: list[tuple[np.ndarray, np.ndarray]], planes: np.ndarray) -> np.ndarray:
    caps = [(ca.SX(a), ca.SX(b), R) for a, b in ends]
    block = capsule_pairs(caps, [(0, 1)], ca.SX(planes), GAP)
    return np.asarray(ca.evalf(ca.vertcat(*block.g))).ravel()


def test_segment_distance_matches_dense_sampling():
    rng = np.random.default_rng(0)
    P = rng.normal(size=(50, 4, 3))
    P[:10, 2:] = P[:10, :2] + [0.3, 0.1, 0.0]  # parallel pairs
    s = np.linspace(0.0, 1.0, 801)[:, None]
    for p in P:
        a, b = p[0] + s * (p[1] - p[0]), p[2] + s * (p[3] - p[2])
        brute = np.linalg.norm(a[:, None] - b[None], axis=-1).min()
        d = float(_segment_distance(*p))
        pa, pb = segment_closest(*p)
        assert d <= brute + 1e-12 and d == pytest.approx(brute, abs=1e-4)  # sampling error of the brute force
        assert np.linalg.norm(pa - pb) == pytest.approx(d, abs=1e-12)


@pytest.mark.parametrize("h, feasible", [(2 * R + GAP + 0.0005, True), (2 * R + 0.0005, False)])
def test_parallel_capsules_the_sphere_samples_miss_are_caught(h, feasible):
    """Two parallel 17 mm cores offset by half their length: the four end spheres stay 2r + gap
    apart although the capsules overlap (h < 2r + gap); the plane rows hold only when they do not."""
    L = 0.017
    a = (np.zeros(3), np.array([L, 0.0, 0.0]))
    b = (np.array([L / 2, h, 0.0]), np.array([1.5 * L, h, 0.0]))
    ends_sphere = [np.linalg.norm(p - q) for p in a for q in b]
    if not feasible:
        assert min(ends_sphere) >= 2 * R + GAP  # the old rows are satisfied by an overlap
    planes = initial_planes(np.array([a, b]), np.array([R, R]), [(0, 1)])
    assert planes[:3] == pytest.approx([0.0, -1.0, 0.0])  # from B's closest point toward A's
    rows = _rows([a, b], planes)
    assert len(rows) == 5 and rows[4] == pytest.approx(0.0)
    assert bool(np.all(rows >= -1e-12)) is feasible
    # and no other plane does better: the margin of the best plane is (h - 2r - gap) / 2 on both sides
    assert rows[:4].min() == pytest.approx((h - 2 * R - GAP) / 2, abs=1e-12)


def test_every_finger_pair_is_considered_unless_out_of_reach_or_built_overlapping():
    fingers, radii = [0, 1, 1, 2, 3], [R] * 5
    touch = 2 * R + GAP
    lo, hi = np.zeros((5, 5)), np.ones((5, 5))
    pairs = select_capsule_pairs(fingers, radii, (lo, hi), GAP, 0.01)
    assert (1, 2) not in pairs  # same finger
    assert (1, 4) in pairs and (0, 4) in pairs  # index-ring: not neighbours, still a row
    lo[1, 4] = lo[4, 1] = touch + 0.01 + 1e-6  # never comes within the margin
    hi[0, 3] = hi[3, 0] = touch - 1e-6  # never apart: a row could not hold
    pairs = select_capsule_pairs(fingers, radii, (lo, hi), GAP, 0.01)
    assert (1, 4) not in pairs and (0, 3) not in pairs and (0, 4) in pairs


@pytest.mark.e2e  # four Shadow solves (~13 s)
def test_shadow_solutions_no_longer_self_collide():
    """The recipe's first 4 starts of Shadow on a superquadric: under the sphere samples one solution
    self-collides (Coal) and one more is within 0.5 mm; under the default capsule rows all four
    converge with every pair of fingers at least half the gap apart."""
    from ohra.synth.pipeline import _shard_seed

    hand = HandModel.from_params(get_hand("shadow_hand_right"))
    obj = procedural_objects("superquadric", 1, 0)[0]
    starts = initial_poses(hand, obj, 4, np.random.default_rng(_shard_seed(0, "shadow_hand_right", obj.mesh_hash)))
    half_gap = 0.5 * NLPSettings().finger_gap

    def collide(settings: NLPSettings) -> list[bool | None]:
        nlp = GraspNLP(hand, obj, settings)
        out = []
        for st in starts:
            r = nlp.solve(st["R0"], st["t0"], st["q0"], st["q_pref"])
            out.append(hand.self_collision(r["grasp"][9:], margin=half_gap) if r["success"] else None)
        return out

    assert sum(c is True for c in collide(NLPSettings(finger_pairs="spheres"))) >= 1  # the old rows miss it
    default = NLPSettings()
    assert default.finger_pairs == "capsules"
    assert collide(default) == [False] * 4
