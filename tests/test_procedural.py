"""Procedural objects: seeded, watertight, 3-20 cm, exact where closed-form, usable everywhere."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from ohra.errors import ObjectError
from ohra.objects.model import ObjectModel
from ohra.objects.procedural import EXTENT_M, FAMILIES, procedural_objects
from ohra.objects.resolve import resolve_objects, size_problem


@pytest.mark.parametrize("family", FAMILIES)
def test_procedural_objects_are_deterministic_watertight_and_in_range(family):
    objs = procedural_objects(family, 6, seed=10)
    again = ObjectModel.procedural(family, 12)
    assert again.mesh_hash == objs[2].mesh_hash and again.name == f"{family}-12"
    assert len({o.mesh_hash for o in objs}) == 6
    for o in objs:
        assert o.watertight and size_problem(o) is None
        ext = o.extents
        assert np.all(ext >= EXTENT_M[0] - 1e-9) and np.all(ext <= EXTENT_M[1] + 1e-9), (o.name, ext)
        assert o.volume == pytest.approx(abs(o.mesh.volume), rel=0.02)
        assert o.describe()["procedural"]["seed"] == int(o.name.split("-")[1])


@pytest.mark.parametrize("family", ["box", "cylinder", "capsule"])
def test_closed_form_families_have_an_exact_signed_distance(family):
    o = ObjectModel.procedural(family, 3)
    assert o.body.kind == "primitives" and o.sdf_sample_spacing == 0.0
    rng = np.random.default_rng(0)
    pts = (rng.random((300, 3)) - 0.5) * (o.extents + 0.04)
    _, dist, _ = trimesh.proximity.closest_point(o.mesh, pts)
    inside = o.mesh.contains(pts)
    mesh_sdf = np.where(inside, -dist, dist)
    # the surface meshes approximate round primitives with 48-96 segments: ~0.1 mm apart
    assert np.abs(o.signed_distance(pts) - mesh_sdf).max() < 5e-4


def test_superquadrics_vary_in_shape():
    ratios = [o.volume / np.prod(o.extents) for o in procedural_objects("superquadric", 12, seed=0)]
    assert min(ratios) < 0.45 and max(ratios) > 0.7  # pinched to box-like (an ellipsoid fills pi/6 = 0.52)


def test_procedural_objects_on_the_command_line():
    (o,) = resolve_objects(["procedural:capsule:4"])
    assert o.name == "capsule-4"
    for bad, msg in [("procedural:teapot:1", "unknown procedural family"), ("procedural:box", "expected procedural:FAMILY:SEED"),
                     ("procedural:box:x", "expected procedural:FAMILY:SEED"),
                     ("procedural:box:-1", "expected procedural:FAMILY:SEED"),
                     ("procedural:box:4294967303", r"a procedural seed is a whole number in \[0, 2\*\*32\)")]:
        with pytest.raises(ObjectError, match=msg):
            resolve_objects([bad])



def test_superquadric_powers_go_through_the_c_library_not_numpys_simd_kernels(monkeypatch):
    """NumPy's ``power`` takes other kernels on AVX-512 CPUs (last-bit differences), so a procedural mesh,
    and its hash in every dataset manifest, depended on the machine that made it. Every power of the
    superquadric goes through ``_pow`` (libm's ``pow``, the same bits everywhere): an ulp planted there
    must show in the vertices, and ``_pow`` must equal ``math.pow`` bit for bit."""
    import itertools
    import math

    import ohra.objects.procedural as proc

    x = np.random.default_rng(0).uniform(1e-3, 3.0, 500)
    assert np.array_equal(proc._pow(x, 0.7361), np.array([math.pow(v, 0.7361) for v in x]))
    args = (np.array([0.05, 0.04, 0.03]), 0.6, 1.3)
    want = proc.superquadric_mesh(*args).vertices.copy()
    real = proc._pow
    for planted in range(5):  # one ulp on each of the five powers in turn
        calls = itertools.count()
        monkeypatch.setattr(proc, "_pow", lambda v, p: (lambda r, i: np.nextafter(r, np.inf) if i == planted else r)(real(v, p), next(calls)))
        assert not np.array_equal(proc.superquadric_mesh(*args).vertices, want), planted


@pytest.mark.parametrize("seed", [-1, 2**32, 2.7, "2", True])
def test_a_seed_the_shape_stream_cannot_hold_is_refused_not_aliased(seed):
    """The stream keeps 32 bits of the seed: 2**32 + 7 would be box-7's shape under another name."""
    from ohra.objects.model import ObjectModel

    with pytest.raises(ObjectError, match=r"a procedural seed is a whole number in \[0, 2\*\*32\)"):
        ObjectModel.procedural("box", seed)
    assert ObjectModel.procedural("box", 2**32 - 1).name == f"box-{2**32 - 1}"


def test_a_seed_range_past_the_largest_seed_names_the_range():
    from ohra.objects.procedural import procedural_objects

    with pytest.raises(ObjectError, match=r"seeds 4294967295 .. 4294967296 pass 2\*\*32 - 1"):
        procedural_objects("box", 2, seed=2**32 - 1)
