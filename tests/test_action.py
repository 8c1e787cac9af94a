"""ActionMap: original <-> canonical joint vectors by name, with sign and offset."""

from __future__ import annotations

import numpy as np
import pytest

from ohra import MappingError
from ohra.original.action import ActionMap, SlotMap, original_joint_names
from ohra.transforms import xyzrpy_to_matrix

URDF = """<robot name="toy">
  <link name="base"/><link name="a"/><link name="b"/><link name="c"/><link name="d"/>
  <joint name="wrist" type="revolute"><parent link="base"/><child link="a"/><limit lower="-1" upper="1"/></joint>
  <joint name="f1" type="revolute"><parent link="a"/><child link="b"/><limit lower="0" upper="1.5"/></joint>
  <joint name="f2" type="revolute"><parent link="b"/><child link="c"/><limit lower="-0.5" upper="2"/></joint>
  <joint name="tip" type="fixed"><parent link="c"/><child link="d"/></joint>
</robot>"""


def _map(**kw):
    slots = {"index_joint2": SlotMap("f1"), "index_joint3": SlotMap("f2", sign=-1, offset=0.785)}
    return ActionMap.from_urdf(URDF, slots, **kw)


def test_original_order_is_read_by_name_from_the_file():
    assert original_joint_names(URDF) == ["wrist", "f1", "f2"]


def test_maps_with_sign_and_offset_and_fixed_values():
    am = _map(fixed={"index_joint1": 0.088})
    qc = am.to_canonical(np.array([0.3, 0.5, 1.0]))
    assert qc.shape == (22,)
    assert qc[6] == 0.5 and qc[7] == pytest.approx(-1.0 + 0.785) and qc[5] == 0.088
    assert np.count_nonzero(qc) == 3


def test_round_trip_is_exact_on_mapped_joints(rng):
    am = _map()
    q = rng.uniform(-1, 1, size=(100, 3))
    back = am.to_original(am.to_canonical(q))
    assert np.array_equal(back[:, 1], q[:, 1])  # no offset: bit-exact
    assert np.allclose(back[:, 2], q[:, 2], rtol=0, atol=2e-16)  # an offset costs one rounding at most
    assert np.all(back[:, ~am.mapped_original] == 0.0)  # the wrist is not part of the canonical hand
    qc = np.zeros((5, 22))
    qc[:, am.mapped_slots] = rng.uniform(-1, 1, size=(5, 2))
    assert np.allclose(am.to_canonical(am.to_original(qc)), qc, atol=1e-15)


def test_unmapped_default_is_configurable():
    am = _map(unmapped_default={"wrist": 0.2})
    assert am.to_original(np.zeros(22))[0] == 0.2


def test_limits_of_a_negated_joint_swap_and_negate():
    am = _map()
    lo, up = am.limits_to_canonical(np.array([-1, 0, -0.5]), np.array([1, 1.5, 2]))
    assert (lo[6], up[6]) == (0, 1.5)
    assert (lo[7], up[7]) == pytest.approx((-2 + 0.785, 0.5 + 0.785))


def test_wrist_transforms_are_inverse():
    am = _map(palm_origin=[0.01, 0, 0.247, 0.1, -0.2, 0.3])
    T = xyzrpy_to_matrix([0.3, -0.1, 0.5, 1.0, 0.2, -0.4])
    Tc = am.wrist_to_canonical(T)
    assert np.allclose(Tc, T @ xyzrpy_to_matrix(am.palm_origin))
    assert np.allclose(am.wrist_to_original(Tc), T)


def test_errors_name_the_problem():
    with pytest.raises(MappingError, match="'nope', which is not a movable joint"):
        ActionMap.from_urdf(URDF, {"index_joint2": SlotMap("nope")})
    with pytest.raises(MappingError, match="'tip', which is not a movable joint"):
        ActionMap.from_urdf(URDF, {"index_joint2": SlotMap("tip")})
    with pytest.raises(MappingError, match="'f1' is mapped twice"):
        ActionMap.from_urdf(URDF, {"index_joint2": "f1", "index_joint3": "f1"})
    with pytest.raises(MappingError, match="unknown canonical slot 'index_joint9'"):
        ActionMap.from_urdf(URDF, {"index_joint9": "f1"})
    with pytest.raises(MappingError, match=r"shape \(3,\) or \(N, 3\), got \(4,\)"):
        _map().to_canonical(np.zeros(4))
    with pytest.raises(MappingError, match=r"shape \(22,\)"):
        _map().to_original(np.zeros(21))
    with pytest.raises(MappingError, match=r"holds nan at index \(1, 2\) \(2 non-finite"):  # NaN mapped to NaN targets
        _map().to_canonical(np.array([[0.0, 0.1, 0.2], [0.0, 0.1, np.nan], [np.inf, 0.0, 0.0]]))
    with pytest.raises(MappingError, match="holds inf at index"):
        _map().to_original(np.full(22, np.inf))
    with pytest.raises(MappingError, match="both mapped and fixed"):
        _map(fixed={"index_joint2": 0.1})
    with pytest.raises(MappingError, match="sign"):
        SlotMap("f1", sign=2)


@pytest.mark.assets
def test_from_urdf_takes_a_slot_as_a_spec_writes_it_and_names_unknown_keys():
    from ohra.errors import MappingError
    from ohra.hands import registry

    urdf = registry.spec("inspire_hand_right").urdf_path()
    am = ActionMap.from_urdf(urdf, {"index_joint2": {"joint": "index_proximal_joint", "sign": 1}})
    assert am.slots["index_joint2"].name == "index_proximal_joint"
    with pytest.raises(MappingError, match="unknown: jont"):
        ActionMap.from_urdf(urdf, {"index_joint2": {"jont": "index_proximal_joint"}})
