"""Ferrari-Canny Q1 on analytic cases, the direction of the contact forces, and SDF contact normals.

Flipping *every* normal leaves Q1 unchanged (the wrench set of pulling contacts is the point mirror of
that of pushing ones, and the Q1 ball is centred), so the sign of the forces is pinned where it is
made: :func:`contact_wrenches` must push into the object, and :func:`contact_normals` must point out.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from ohra.objects.model import ObjectModel
from ohra.synth.quality import contact_normals, contact_wrenches, ferrari_canny

S = 0.03  # half edge of the test cube [m]


@pytest.fixture(scope="module")
def cube() -> ObjectModel:
    return ObjectModel(trimesh.creation.box(extents=(2 * S,) * 3), "cube", repair=False)


def _twelve_contacts(d: float) -> tuple[np.ndarray, np.ndarray]:
    """Two contacts on each face of the cube, offset by +-d along one in-face axis, chosen so that the
    x faces make torque about z, the y faces about x and the z faces about y."""
    P, N = [], []
    for sign in (1.0, -1.0):
        for e in (d, -d):
            P += [(sign * S, e, 0.0), (0.0, sign * S, e), (e, 0.0, sign * S)]
            N += [(sign, 0.0, 0.0), (0.0, sign, 0.0), (0.0, 0.0, sign)]
    return np.array(P), np.array(N)


@pytest.mark.parametrize("d, torque_length", [(0.02, 0.05), (0.01, 0.05), (0.025, 0.02)])
def test_frictionless_twelve_contact_cube_has_the_analytic_q1(cube, d, torque_length):
    """Without friction each contact gives one wrench (-n, (p x -n) / L). The twelve lie in three
    orthogonal planes (F_x, tau_z), (F_y, tau_x), (F_z, tau_y), four per plane at (+-1, +-c) with
    c = d / L: the hull is the free sum of three rectangles, whose inradius is min(1, c) / sqrt(3)."""
    P, N = _twelve_contacts(d)
    expected = min(1.0, d / torque_length) / np.sqrt(3.0)
    for facets in (1, 8):
        q1 = ferrari_canny(P, cube, mu=0.0, torque_length=torque_length, facets=facets, normals=N)
        assert q1 == pytest.approx(expected, rel=1e-9)


def test_contacts_on_one_line_resist_no_torque_about_it(cube):
    """Two antipodal contacts cannot stop a spin about the line through them, whatever the friction."""
    P = np.array([[S, 0.0, 0.0], [-S, 0.0, 0.0]])
    N = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    for mu in (0.2, 1.0, 5.0):
        assert ferrari_canny(P, cube, mu=mu, normals=N) == 0.0
    assert ferrari_canny(P[:1], cube, mu=1.0, normals=N[:1]) == 0.0


def test_friction_only_widens_the_wrench_set(cube):
    P, N = _twelve_contacts(0.02)
    q = [ferrari_canny(P, cube, mu=mu, normals=N) for mu in (0.0, 0.3, 0.6)]
    assert q[0] < q[1] < q[2]


def test_contact_forces_push_into_the_object_within_the_friction_cone(cube):
    P, N = _twelve_contacts(0.02)
    c = np.array([0.001, -0.002, 0.003])
    mu, L, facets = 0.4, 0.05, 8
    W = contact_wrenches(P, N, c, mu, L, facets).reshape(len(P), facets, 6)
    F = W[..., :3]
    normal = np.einsum("kfi,ki->kf", F, N)
    assert normal == pytest.approx(np.full((len(P), facets), -1.0))  # unit push along -n: into the cube
    tangential = F - normal[..., None] * N[:, None, :]
    assert np.linalg.norm(tangential, axis=-1) == pytest.approx(np.full((len(P), facets), mu))
    assert tangential.sum(axis=1) == pytest.approx(np.zeros((len(P), 3)), abs=1e-12)  # evenly spread
    assert W[..., 3:] == pytest.approx(np.cross(P[:, None, :] - c, F) / L)


def test_sdf_contact_normals_point_out_of_the_object(cube):
    P, N = _twelve_contacts(0.02)
    n = contact_normals(P, cube)
    assert np.einsum("ki,ki->k", n, N) == pytest.approx(np.ones(len(P)), abs=0.02)
