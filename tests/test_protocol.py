"""The protocol's decision boundaries, each checked against physics known by construction.

Nothing here reads ``ohra.sim.DIRECTIONS`` or the ``Protocol`` defaults to build an expectation: the
reference's numbers are written out below, so that changing one of them in the package fails a test.

* A free cube (the hand 0.5 m away, nothing touches it) moves under the force schedule alone, which
  PyBullet integrates with semi-implicit Euler: the displacements after each phase are known exactly.
  That pins the six directions, the 0.5 N/kg force and the strict preset's gravity (-z).
* Scaling that force down makes the free cube end anywhere we like: just inside and just outside the
  2 cm success threshold, and the 5 cm filter distance.
* A rigid cage with one open side holds the cube against five pushes and loses it on the sixth:
  a failure in one direction only, for each of the six.
"""

from __future__ import annotations

import numpy as np
import pytest

from ohra.sim import GraspEvaluator, Protocol

from sim_fixtures import cage_hand, cube, palm_at

# The reference's schedule (OHRA / D(R,O) Isaac filter, survey §5.1): +x, +y, +z, -x, -y, -z, 1 s each.
REFERENCE_DIRECTIONS = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]], dtype=float)
REFERENCE_FORCE_PER_MASS = 0.5  # N/kg
STRICT_GRAVITY = np.array([0.0, 0.0, -9.81])  # m/s^2, world frame
FAR = (-0.5, -0.5, -0.5)  # palm position [m]: the cage is closed and the flights all head away from it


def free_flight(force_per_mass: float, gravity=np.zeros(3), dt: float = 1.0 / 240.0, steps: int = 240) -> np.ndarray:
    """(6, 3) positions [m] of a free body at the end of each direction phase (starting at rest at 0),
    integrated as Bullet does: v += a dt, then x += v dt."""
    acc = np.repeat(REFERENCE_DIRECTIONS, steps, axis=0) * force_per_mass + np.asarray(gravity, dtype=float)
    x = np.cumsum(np.cumsum(acc * dt, axis=0) * dt, axis=0)
    return x[steps - 1::steps]


def _fly(protocol: Protocol, mode: str = "eval"):
    urdf, am = cage_hand(None)
    with GraspEvaluator.from_urdf(urdf, am, cube(), protocol) as ev:
        r = ev.evaluate(palm_at(FAR), mode=mode).results[0]
        end = ev.world.object_frame()[:3, 3].copy()
    assert r.contacts == 0 and r.displacement[0] == 0.0  # nothing touched it; gravity is off in the squeeze
    return r, end


def _force_for_final_displacement(target: float) -> float:
    """The force per mass [N/kg] that leaves a free body ``target`` metres from its start."""
    return REFERENCE_FORCE_PER_MASS * target / float(np.linalg.norm(free_flight(REFERENCE_FORCE_PER_MASS)[-1]))


def test_free_object_moves_under_the_reference_force_along_the_reference_directions():
    r, end = _fly(Protocol(early_exit=False))
    expected = free_flight(REFERENCE_FORCE_PER_MASS)
    assert r.displacement[1:] == pytest.approx(np.linalg.norm(expected, axis=1), rel=1e-6)
    assert end == pytest.approx(expected[-1], abs=1e-6)  # (1.5, 1.5, 1.5) m after the six seconds
    assert not r.success


def test_strict_preset_adds_gravity_along_minus_z_in_the_perturbation_phase_only():
    r, end = _fly(Protocol.strict(early_exit=False))
    expected = free_flight(REFERENCE_FORCE_PER_MASS, STRICT_GRAVITY)
    assert r.displacement[1:] == pytest.approx(np.linalg.norm(expected, axis=1), rel=1e-6)
    assert end == pytest.approx(expected[-1], abs=1e-6)
    assert end[2] < -100.0  # it fell ~175 m


@pytest.mark.parametrize("early_exit", [True, False])
def test_success_threshold_is_two_centimetres(early_exit):
    """Free flights that end 1.8 and 2.2 cm from where the squeeze left the object."""
    outcomes = []
    for final in (0.018, 0.022):
        r, _ = _fly(Protocol(force_per_mass=_force_for_final_displacement(final), early_exit=early_exit))
        assert r.displacement[-1] == pytest.approx(final, rel=1e-6)
        outcomes.append(r.success)
    assert outcomes == [True, False]


def test_filter_mode_requires_ending_within_five_centimetres_of_the_origin():
    """With a 20 cm success threshold, flights ending 4.5 and 5.5 cm from the origin both pass the
    evaluation; the filter keeps only the first."""
    for final, filtered in ((0.045, True), (0.055, False)):
        prot = Protocol(force_per_mass=_force_for_final_displacement(final), success_displacement=0.2)
        r, end = _fly(prot, "eval")
        assert r.success and r.final_distance_from_origin == pytest.approx(final, rel=1e-6)
        assert np.linalg.norm(end) == pytest.approx(final, rel=1e-6)
        r, _ = _fly(prot, "filter")
        assert r.success is filtered, final


@pytest.mark.parametrize("k", range(6), ids=["+x", "+y", "+z", "-x", "-y", "-z"])
def test_a_cage_open_on_one_side_loses_the_cube_in_that_direction_only(k):
    """The cube sits in a cage with 1 mm clearance, open toward reference direction ``k``: every
    earlier push leaves it within 2 mm, the push toward the opening carries it out (a free second
    at 0.5 N/kg is 25 cm). Frictionless (effective friction 0), because a cube pressed into a wall
    by one push otherwise sticks there under the next: PyBullet's penetration recovery gives a
    small normal force, and friction 3 times that exceeds the 0.5 N/kg push."""
    urdf, am = cage_hand(REFERENCE_DIRECTIONS[k])
    with GraspEvaluator.from_urdf(urdf, am, cube(), Protocol(friction=0.0)) as ev:
        r = ev.evaluate(palm_at()).results[0]
    assert not r.success
    # held = within the cage's play: 1 mm clearance per side lets pushes move the cube up to 2 mm per
    # axis (3.5 mm diagonally, the object has no collision margin); lost = carried > 20 cm
    assert np.all(r.displacement[1:k + 1] < 0.004), r.displacement
    assert r.displacement[k + 1] > 0.2, r.displacement


def test_the_closed_cage_holds_the_cube_against_all_six_pushes():
    urdf, am = cage_hand(None)
    with GraspEvaluator.from_urdf(urdf, am, cube(), Protocol(friction=0.0)) as ev:
        r = ev.evaluate(palm_at()).results[0]
    assert r.success and np.all(r.displacement[1:] < 0.004), r.displacement


# -- the joint drive ---------------------------------------------------------------------------------
ISAAC_STIFFNESS, ISAAC_DAMPING = 1000.0, 200.0  # the reference's DoF drive [N m/rad], [N m s/rad]


def _drive_speed(protocol: Protocol, error: float = 0.02) -> float:
    """Joint speed [rad/s] of a free canonical index finger (hand far from the object) a few steps
    after its target is set ``error`` rad past its position: small enough not to hit the force limit."""
    from ohra.hands import get_hand
    from ohra.sim import SimHand

    ev = GraspEvaluator(SimHand.from_params(get_hand("leap_3333"), "leap_3333"), cube(), protocol)
    w = ev.world
    T = np.eye(4)
    T[:3, 3] = (0.5, 0.5, 0.5)
    q = np.clip(np.full(len(w.jidx), 0.3), w.hand.lower, w.hand.upper)
    w.reset_hand(T, q)
    w.new_object()
    k = int(np.argmax(w.hand.upper - w.hand.lower))
    target = q.copy()
    target[k] += error
    w.drive_joints(target)
    import pybullet as pb

    for _ in range(2):
        pb.stepSimulation(physicsClientId=w.client)
    remaining = target[k] - w.joint_values()[k]  # the error the next step's motor sees
    pb.stepSimulation(physicsClientId=w.client)
    v = pb.getJointState(w.body, int(w.jidx[k]), physicsClientId=w.client)[1]
    ev.close()
    return v / remaining


def test_isaac_drive_closes_fingers_at_isaacs_rate():
    """Isaac's PD (k 1000, d 200) moves a light link at k/d = 5 rad/s per rad of error; the default
    PyBullet gain 0.3 at 240 Hz at 0.3 * 240 = 72."""
    assert _drive_speed(Protocol.isaac_drive()) == pytest.approx(ISAAC_STIFFNESS / ISAAC_DAMPING, rel=0.05)
    assert _drive_speed(Protocol()) == pytest.approx(0.3 * 240.0, rel=0.05)
    assert Protocol.preset("isaac-drive") == Protocol.isaac_drive()
    assert Protocol.isaac_drive(dt=0.01).position_gain == pytest.approx(0.01 * 5.0)


def _sag(protocol: Protocol, seconds: float = 0.06) -> float:
    """Largest joint motion [rad] of a LEAP hand whose fingers hang sideways under gravity while
    weak motors (the protocol's motor_force) try to hold them at their start."""
    import pybullet as pb

    from ohra.hands import get_hand
    from ohra.sim import SimHand

    ev = GraspEvaluator(SimHand.from_params(get_hand("leap_3333"), "leap_3333"), cube(), protocol)
    w = ev.world
    T = np.eye(4)
    T[:3, 3] = (0.5, 0.5, 0.5)
    T[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]
    q = np.clip(np.zeros(len(w.jidx)), w.hand.lower, w.hand.upper)
    w.reset_hand(T, q)
    w.new_object()
    w.drive_joints(q)
    pb.setGravity(0, 0, -9.81, physicsClientId=w.client)
    for _ in range(int(round(seconds / protocol.dt))):
        pb.stepSimulation(physicsClientId=w.client)
    sag = float(np.abs(w.joint_values() - q).max())
    ev.close()
    return sag


def test_substeps_keep_the_motor_torque_limit():
    """PyBullet applies a motor's impulse cap in every substep; 2 substeps of 1/200 s must hold a
    finger exactly like 1/200 s steps with the same torque limit (not like a limit twice as large)."""
    one = _sag(Protocol(dt=1 / 200, motor_force=0.004))
    two = _sag(Protocol(dt=1 / 100, substeps=2, motor_force=0.004))
    assert one > 0.1  # the limit binds: the fingers sag
    assert _sag(Protocol(dt=1 / 200, motor_force=0.002)) > 1.04 * one  # and the sag depends on it
    assert two == pytest.approx(one, rel=0.01)


@pytest.mark.parametrize("kw, message", [
    ({"friction": -1.0}, "friction and force_per_mass must be >= 0, got -1.0"),
    ({"friction": float("nan")}, "Protocol.friction must be a finite number, got nan"),
    ({"dt": "x"}, "Protocol.dt must be a finite number, got 'x'"),
    ({"substeps": True}, "Protocol.substeps must be a finite number, got True"),
    ({"object_point": "centre"}, "object_point must be one of"),
])
def test_a_bad_protocol_setting_is_an_ohra_error_naming_it(kw, message):
    from ohra.errors import OhraError

    with pytest.raises(OhraError, match=message):
        Protocol(**kw)


def test_an_unknown_preset_is_an_ohra_error_listing_the_known_ones():
    from ohra.sim import ProtocolError

    with pytest.raises(ProtocolError, match="unknown protocol preset 'fast'; expected 'reference', 'strict'"):
        Protocol.preset("fast")
