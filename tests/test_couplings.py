"""Couplings as data: q[slot] = a * q[driver] + b, applied by the action map both ways."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from ohra.canonical import couplings as cpl
from ohra.canonical.couplings import Coupling
from ohra.canonical.params import JOINT_INDEX, load_params
from ohra.errors import MappingError, ParamsError
from ohra.original.action import ActionMap

I2, I3, I4 = JOINT_INDEX["index_joint2"], JOINT_INDEX["index_joint3"], JOINT_INDEX["index_joint4"]


def test_chains_resolve_to_their_root_driver():
    cs = cpl.resolve([Coupling("index_joint4", "index_joint3", 0.5, 0.1), Coupling("index_joint3", "index_joint2", 2.0, -0.2)])
    assert cs[1] == Coupling("index_joint4", "index_joint2", 1.0, 0.0)  # 0.5 * (2 q2 - 0.2) + 0.1
    q = np.zeros(22)
    q[I2] = 0.7
    p = cpl.project(cs, q)
    assert p[I3] == pytest.approx(1.2) and p[I4] == pytest.approx(0.7)


@pytest.mark.parametrize("bad, message", [
    ([Coupling("index_joint3", "index_joint2", 1.0), Coupling("index_joint3", "index_joint4", 1.0)], "coupled twice"),
    ([Coupling("index_joint3", "index_joint2", 1.0), Coupling("index_joint2", "index_joint3", 1.0)], "cycle"),
])
def test_bad_coupling_sets_are_refused(bad, message):
    with pytest.raises(ParamsError, match=message):
        cpl.resolve(bad)


@pytest.mark.parametrize("kwargs, message", [
    (dict(slot="index_joint9", driver="index_joint2", multiplier=1.0), "not a canonical slot"),
    (dict(slot="index_joint3", driver="index_joint3", multiplier=1.0), "cannot drive itself"),
    (dict(slot="index_joint3", driver="index_joint2", multiplier=0.0), "multiplier 0"),
    (dict(slot="index_joint3", driver="index_joint2", multiplier=float("nan")), "finite"),
])
def test_a_bad_coupling_names_its_problem(kwargs, message):
    with pytest.raises(ParamsError, match=message):
        Coupling(**kwargs)


def test_matrix_residual_and_projection_agree(rng):
    cs = (Coupling("index_joint3", "index_joint2", 1.06399, -0.04545), Coupling("thumb_joint5", "thumb_joint2", -0.667, 0.1))
    A, b = cpl.coupling_matrix(cs)
    q_free = rng.uniform(-1, 1, 22)
    q = A @ q_free + b
    np.testing.assert_allclose(cpl.residual(cs, q), 0.0, atol=1e-15)
    np.testing.assert_allclose(q, cpl.project(cs, q_free))
    np.testing.assert_allclose((np.eye(22) - A) @ q, b, atol=1e-15)  # equality constraints for a solver
    assert not A[:, I3].any() and A[I3, I2] == pytest.approx(1.06399)
    assert cpl.free_mask(cs).sum() == 20
    bad = q.copy()
    bad[I3] += 0.3
    assert cpl.residual(cs, bad)[1] == pytest.approx(0.3)  # resolved couplings are in slot order: thumb first
    np.testing.assert_allclose(cpl.project(cs, cpl.project(cs, bad)), cpl.project(cs, bad))


def test_coupled_limits_are_what_the_driver_reaches():
    lo, up = np.zeros(22), np.zeros(22)
    up[I2] = 1.47
    lo2, up2 = cpl.propagate_limits([Coupling("index_joint3", "index_joint2", -2.0, 0.5)], lo, up)
    assert (lo2[I3], up2[I3]) == pytest.approx((0.5 - 2.94, 0.5))


def test_params_json_key_is_optional_and_reference_keys_are_untouched(shadow_base, tmp_path):
    assert cpl.params_json(shadow_base) == shadow_base.to_json()
    cs = (Coupling("index_joint3", "index_joint2", 1.06399, -0.04545),)
    text = cpl.params_json(shadow_base, cs)
    f = tmp_path / "p.json"
    f.write_text(text)
    d = json.loads(text)
    assert list(d)[:-1] == list(json.loads(shadow_base.to_json())) and list(d)[-1] == "couplings"
    assert load_params(f).isclose(shadow_base, atol=0.0)
    assert cpl.read_couplings(f) == cs
    d["couplings"][0]["slot"] = "index_joint9"
    f.write_text(json.dumps(d))
    with pytest.raises(ParamsError, match=r"couplings\[0\].*index_joint9"):
        load_params(f)
    d["couplings"] = [{"slot": "index_joint3", "driver": "index_joint2", "multiplier": 1.0},
                      {"slot": "index_joint2", "driver": "index_joint3", "multiplier": 1.0}]
    f.write_text(json.dumps(d))
    for read in (load_params, cpl.read_couplings):  # a cycle names the file it is in, like every other params error
        with pytest.raises(ParamsError, match=rf"{re.escape(str(f))}: couplings: coupling cycle: index_joint2 -> index_joint3"):
            read(f)


def _am(**kw) -> ActionMap:
    slots = {"index_joint2": {"name": "a"}, "index_joint3": {"name": "m", "sign": -1.0, "offset": 0.1}}
    return ActionMap(slots, ["a", "w"], couplings=[Coupling("index_joint3", "index_joint2", 1.5, -0.2)], **kw)


def test_action_map_applies_couplings_both_ways():
    am = _am()
    qc = am.to_canonical(np.array([[0.4, 9.0]]))
    assert qc[0, I3] == pytest.approx(1.5 * 0.4 - 0.2)  # the mimic slot filled from its driver
    assert am.passive_joints == {"index_joint3": "m"}
    q = np.zeros(22)
    q[I2], q[I3] = 0.4, 5.0  # violates the coupling
    assert am.residual(q)[0] == pytest.approx(5.0 - 0.4)
    np.testing.assert_allclose(am.to_original(q), [0.4, 0.0])  # only the driver is read
    np.testing.assert_allclose(am.residual(am.project(q)), 0.0)
    assert am.passive_values(q)["m"] == pytest.approx(-(5.0 - 0.1))  # its own slot, sign and offset
    lo, up = am.limits_to_canonical(np.array([0.0, -1.0]), np.array([1.0, 1.0]))
    assert (lo[I3], up[I3]) == pytest.approx((-0.2, 1.3))


def test_declared_coupling_between_actuated_joints_is_enforced_on_the_way_back():
    am = ActionMap({"index_joint2": "a", "index_joint3": "b"}, ["a", "b"],
                   couplings=[Coupling("index_joint3", "index_joint2", 2.0, 0.0)])
    np.testing.assert_allclose(am.to_original(np.eye(22)[I2] * 0.3 + np.eye(22)[I3] * 9.0), [0.3, 0.6])
    assert am.to_canonical(np.array([0.3, 9.0]))[I3] == pytest.approx(0.6)


def test_a_joint_outside_the_vector_needs_a_coupling():
    with pytest.raises(MappingError, match="'m', which is not a movable joint.*coupling"):
        ActionMap({"index_joint2": "a", "index_joint3": "m"}, ["a"])
    with pytest.raises(MappingError, match="not mapped"):
        ActionMap({"index_joint2": "a"}, ["a"], couplings=[Coupling("index_joint3", "index_joint2", 1.0)])


def test_action_map_from_a_urdf_reads_mimic_chains():
    urdf = """<robot name="chain"><link name="p"/><link name="a"/><link name="b"/><link name="c"/>
      <joint name="j1" type="revolute"><parent link="p"/><child link="a"/><axis xyz="0 1 0"/><limit lower="0" upper="1"/></joint>
      <joint name="j2" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 1 0"/><limit lower="0" upper="1"/>
        <mimic joint="j1" multiplier="2.0" offset="0.1"/></joint>
      <joint name="j3" type="revolute"><parent link="b"/><child link="c"/><axis xyz="0 1 0"/><limit lower="0" upper="1"/>
        <mimic joint="j2" multiplier="0.5"/></joint></robot>"""
    am = ActionMap.from_urdf(urdf, {"index_joint2": "j1", "index_joint4": {"name": "j3", "sign": -1.0, "offset": 0.2}})
    assert am.original_joints == ("j1",)
    (c,) = am.couplings
    # q_j3 = 0.5 * (2 q_j1 + 0.1) = q_j1 + 0.05;  slot = -q_j3 + 0.2 = -q_slot2 + 0.15
    assert (c.slot, c.driver, c.multiplier, c.offset) == ("index_joint4", "index_joint2", -1.0, pytest.approx(0.15))
    # two mimics of an actuated joint that drives no slot: the first drives it (a proxy), the other follows
    am = ActionMap.from_urdf(urdf, {"index_joint3": "j2", "index_joint4": "j3"})
    assert am.mapped_original.tolist() == [True]
    (c,) = am.couplings
    # q_j2 = 2 q_j1 + 0.1, q_j3 = q_j1 + 0.05 = 0.5 q_j2
    assert (c.slot, c.driver, c.multiplier, c.offset) == ("index_joint4", "index_joint3", 0.5, pytest.approx(0.0))
    q = am.project(np.eye(22)[JOINT_INDEX["index_joint3"]] * 0.9)
    assert am.to_original(q)[0] == pytest.approx(0.4)
