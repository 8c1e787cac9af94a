"""Canonical URDF generation: determinism, structure, inertias, and clean loading everywhere."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pybullet as pb
import pytest

from ohra.sim.bullet import captured_c_output, load_urdf_text
from ohra.hands import get_hand, variant_names
from ohra.canonical.params import JOINT_NAMES
from ohra.canonical.urdfgen import DUMMY_MASS, capsule_inertia, palm_geometry, palm_inertia, render, write


def test_render_is_deterministic(shadow_base, allegro_ext, tmp_path):
    for p in (shadow_base, allegro_ext, get_hand("leap_3303")):
        assert render(p) == render(p.copy())
    a, b = write(shadow_base, tmp_path / "a.urdf"), write(shadow_base, tmp_path / "b.urdf")
    assert a.read_bytes() == b.read_bytes()


def test_all_22_joints_are_revolute_and_tips_only_for_present_fingers(allegro_ext):
    root = ET.fromstring(render(allegro_ext))
    revolute = [j.get("name") for j in root.iter("joint") if j.get("type") == "revolute"]
    assert sorted(revolute) == sorted(JOINT_NAMES)
    tips = sorted(l.get("name") for l in root.iter("link") if l.get("name").endswith("_tip"))
    assert tips == ["index_tip", "little_tip", "middle_tip", "thumb_tip"]  # no ring finger


def test_every_link_has_an_inertial_and_geometry_only_where_present(allegro_ext):
    root = ET.fromstring(render(allegro_ext))
    for link in root.iter("link"):
        assert link.find("inertial") is not None, link.get("name")
    ring = [l for l in root.iter("link") if l.get("name").startswith("ring_")]
    assert ring and all(l.find("collision") is None for l in ring)


def test_capsule_spans_zero_to_length(shadow_base):
    root = ET.fromstring(render(shadow_base))
    link = next(l for l in root.iter("link") if l.get("name") == "index_proximal")
    zs = []
    for c in link.findall("collision"):
        z = float(c.find("origin").get("xyz").split()[2])
        g = c.find("geometry")[0]
        r = float(g.get("radius"))
        if g.tag == "sphere":
            zs += [z - r, z + r]
        else:
            h = float(g.get("length"))
            zs += [z - h / 2, z + h / 2]
    assert min(zs) == pytest.approx(0.0, abs=1e-12)
    assert max(zs) == pytest.approx(shadow_base.finger_lengths[1, 0], abs=1e-12)


def test_exact_pi_in_palm_orientation(shadow_base):
    text = render(shadow_base)
    assert f"{math.pi / 2:.12g}" in text and "3.1416" not in text


def test_capsule_inertia_is_a_solid_capsule():
    r, L = 0.01, 0.05
    m, it, ia = capsule_inertia(r, L)
    assert m == pytest.approx(1000 * (math.pi * r**2 * (L - 2 * r) + 4 / 3 * math.pi * r**3))
    # A capsule of zero cylinder length is a sphere.
    m, it, ia = capsule_inertia(r, 2 * r)
    assert it == pytest.approx(0.4 * m * r * r) and ia == pytest.approx(0.4 * m * r * r)


def _load_everywhere(params, client):
    text = render(params)
    with captured_c_output() as out:
        model = pin.buildModelFromXML(text)
        body = load_urdf_text(text, client, useFixedBase=True)
    return model, body, "".join(out)


def test_every_leap_variant_and_degenerate_hand_loads_without_warnings():
    client = pb.connect(pb.DIRECT)
    try:
        for name in variant_names():
            model, body, out = _load_everywhere(get_hand(name), client)
            assert model.nq == 22, name
            assert out.strip() == "", f"{name}: {out}"
            pb.removeBody(body, physicsClientId=client)
    finally:
        pb.disconnect(client)


def test_reference_hands_load_without_warnings(shadow_base, allegro_ext):
    client = pb.connect(pb.DIRECT)
    try:
        for p in (shadow_base, shadow_base.to_extended(), allegro_ext):
            model, body, out = _load_everywhere(p, client)
            assert model.nq == 22 and out.strip() == ""
    finally:
        pb.disconnect(client)


def test_pybullet_dummy_links_carry_their_small_declared_mass(shadow_base):
    client = pb.connect(pb.DIRECT)
    try:
        body = load_urdf_text(render(shadow_base), client, useFixedBase=True)
        masses = {}
        for j in range(pb.getNumJoints(body, physicsClientId=client)):
            name = pb.getJointInfo(body, j, physicsClientId=client)[12].decode()
            masses[name] = pb.getDynamicsInfo(body, j, physicsClientId=client)[0]
        for dummy in ("thumb_base", "thumb_knuckle", "index_knuckle", "little_base", "index_tip"):
            assert masses[dummy] == pytest.approx(DUMMY_MASS)
        m_prox, _, _ = capsule_inertia(shadow_base.finger_radius, shadow_base.finger_lengths[1, 0])
        assert masses["index_proximal"] == pytest.approx(m_prox, rel=1e-6)
        R, depth = palm_geometry(shadow_base)
        assert masses["palm"] == pytest.approx(palm_inertia(R, depth)[0], rel=1e-6)
        assert max(masses.values()) < 0.5  # nothing got PyBullet's 1 kg default
    finally:
        pb.disconnect(client)


def test_pinocchio_fk_equals_pybullet_fk(shadow_base, allegro_ext):
    """World link frames from PyBullet getLinkState equal Pinocchio frame placements to 1e-6 m."""
    from ohra.canonical.kinematics import HandModel

    client = pb.connect(pb.DIRECT)
    try:
        for params in (shadow_base, allegro_ext, get_hand("leap_3303")):
            hm = HandModel.from_params(params)
            body = load_urdf_text(hm.urdf, client, useFixedBase=True)
            index = {pb.getJointInfo(body, j, physicsClientId=client)[1].decode(): j for j in range(pb.getNumJoints(body, physicsClientId=client))}
            links = {pb.getJointInfo(body, j, physicsClientId=client)[12].decode(): j for j in index.values()}
            for q in hm.random_configurations(5, seed=3):
                for k, name in enumerate(JOINT_NAMES):
                    pb.resetJointState(body, index[name], q[k], physicsClientId=client)
                for link, j in links.items():
                    state = pb.getLinkState(body, j, computeForwardKinematics=True, physicsClientId=client)
                    pos, quat = np.array(state[4]), np.array(state[5])
                    T = hm.frame_pose(q, link)
                    assert np.allclose(pos, T[:3, 3], atol=1e-6), link
                    R = np.array(pb.getMatrixFromQuaternion(quat)).reshape(3, 3)
                    assert np.allclose(R, T[:3, :3], atol=1e-6), link
            pb.removeBody(body, physicsClientId=client)
    finally:
        pb.disconnect(client)
