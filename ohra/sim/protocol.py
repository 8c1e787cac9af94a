"""Constants of the six-direction perturbation protocol (reference values as defaults).

Reference: the OHRA / D(R,O) Isaac Gym filter (survey §5.1), ported to PyBullet (survey §5.5).

One departure: the time step. Isaac runs PhysX TGS at 100 Hz with 2 substeps; PyBullet at that
step lets a squeezed object slip out of grasps that hold at 240 Hz with 100 solver iterations (the
PyBullet recipe of survey §5.5). Measured on the same 45 solver grasps of leap_3333 on three YCB
objects: pass rate 7 / 36 / 6 % at 100 Hz x 2 substeps, 47 / 50 / 69 % at 240 Hz with 100
iterations (the survey's PyBullet prototype measured 64-73 %). The defaults are therefore 240 Hz,
100 iterations; ``Protocol.preset("isaac-step")`` keeps Isaac's literal step for comparison. (Those
100 Hz numbers were measured while PyBullet's substeps doubled every motor's torque limit, fixed
since in :meth:`ohra.sim.world.World.drive_joints`; they were not re-measured.)
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from ohra.errors import OhraError, is_finite_real

# Perturbation order of the reference: +x, +y, +z, -x, -y, -z (object / world frame).
DIRECTIONS = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]], dtype=float)
DIRECTION_NAMES = ("+x", "+y", "+z", "-x", "-y", "-z")
# Isaac's literal stepping (dt s, substeps, solver iterations): Protocol.isaac_step(), ohra eval --isaac-step
ISAAC_STEP = {"dt": 0.01, "substeps": 2, "solver_iterations": 50}
# The reference's Isaac joint drive: stiffness [N m/rad] and damping [N m s/rad] of every DoF
ISAAC_DRIVE = {"stiffness": 1000.0, "damping": 200.0}
# Protocol.urdf_joint_damping of results saved before the setting existed (a saved protocol without
# the key ran with the URDF's damping applied)
URDF_DAMPING_BEFORE = True
OBJECT_POINTS = ("frame", "com")
# [m] GraspEvaluator warns when an object's mesh-frame origin lies farther than this from its centre of
# mass under object_point="frame" (a 0.1 rad turn then moves the origin by over 0.5 cm)
COM_OFFSET_WARN = 0.05


class ProtocolError(OhraError, ValueError):
    """A protocol setting out of range or not a number, or an unknown preset."""


@dataclass(frozen=True)
class Protocol:
    """Every constant of the evaluation; the defaults are the reference's.

    Units: seconds, metres, newtons, kg/m^3. ``friction`` is the *effective* hand-object coefficient:
    PyBullet multiplies the two bodies' coefficients, so each body gets ``sqrt(friction)``.
    """

    dt: float = 1.0 / 240.0  # s, simulation step (Isaac reference: 100 Hz x 2 substeps; see module doc)
    substeps: int = 1  # physics substeps per step
    solver_iterations: int = 100  # PyBullet constraint-solver iterations (PhysX TGS 8 position iterations has no equivalent)
    solver_residual_threshold: float = 1e-7  # PyBullet's: the solver stops early once its residual is below this
    squeeze_time: float = 1.0  # s, phase 1 (no external force)
    direction_time: float = 1.0  # s per perturbation direction
    force_per_mass: float = 0.5  # N/kg: the force is 0.5 * m newtons, re-applied every step
    friction: float = 3.0  # effective hand-object friction
    density: float = 500.0  # kg/m^3, object density (mass = volume x density)
    outer: float = 0.1  # fraction of the way to the opening limit at reset
    inner: float = 0.1  # fraction of the way to the closing limit for the target
    motor_force: float = 1.0  # N m, position-motor force limit (the canonical URDF effort)
    position_gain: float = 0.3
    velocity_gain: float = 1.0
    success_displacement: float = 0.02  # m, final displacement since the end of the squeeze
    filter_max_distance: float = 0.05  # m, filter mode: final distance of the object from the origin
    gravity_in_evaluation: float = 0.0  # m/s^2 along world -z during the perturbation phase
    early_exit: bool = True  # stop a grasp once its failure is certain (never changes an outcome)
    early_exit_margin: float = 0.05  # m beyond the threshold a predicted free flight must end
    early_exit_every: int = 5  # steps between early-exit checks
    merge_fixed_links: bool = True  # like Isaac's collapse_fixed_joints; 2-3x faster stepping
    # The URDF's <dynamics damping>: PyBullet applies it explicitly per step, and on light links
    # (Shadow's 0.1-0.2 N m s/rad on ~1e-7 kg m^2) damping * dt >> inertia diverges and the joints
    # chatter (the rotation environment's RotationConfig.joint_damping). Isaac's drive damps the
    # joints itself, as PyBullet's velocity gain does; canonical, Allegro, Barrett and LEAP URDFs
    # carry none, so only a hand whose URDF has it is affected. Evaluations made before this setting
    # kept the damping (URDF_DAMPING_BEFORE).
    urdf_joint_damping: bool = False
    # The object's reference point: "frame", the origin of its mesh frame (the reference: the fingers
    # close toward the object origin and Isaac reads the actor's root, the object URDF's link frame), or
    # "com", its centre of mass. Both the squeeze (each joint turns so that its link swings toward the
    # point) and the displacement (measured at the point) use it. They differ for a mesh whose frame
    # origin lies away from the object (a turn of angle a moves the origin |offset| x a; fingers close
    # toward a point beside the object), so under "frame" the same grasp can pass or fail depending on
    # where the mesh's author put the origin (a mesh exported in scene coordinates fails almost every
    # grasp). "com" is frame-independent; "frame" stays the default so published results and dataset
    # digests hold. GraspEvaluator warns when the choice matters (an origin over COM_OFFSET_WARN off).
    object_point: str = "frame"

    def __post_init__(self) -> None:
        if self.object_point not in OBJECT_POINTS:
            raise ProtocolError(f"Protocol.object_point must be one of {OBJECT_POINTS}, got {self.object_point!r}")
        for f in fields(self):
            v = getattr(self, f.name)
            if f.type in ("float", "int") and not is_finite_real(v):
                raise ProtocolError(f"Protocol.{f.name} must be a finite number, got {v!r}")
        for name in ("dt", "squeeze_time", "direction_time", "density", "motor_force", "success_displacement"):
            if not getattr(self, name) > 0:
                raise ProtocolError(f"Protocol.{name} must be > 0, got {getattr(self, name)}")
        if self.friction < 0 or self.force_per_mass < 0:
            raise ProtocolError(f"Protocol.friction and force_per_mass must be >= 0, got {self.friction} and {self.force_per_mass}")
        if int(self.substeps) < 1 or int(self.early_exit_every) < 1:
            raise ProtocolError(f"Protocol.substeps and early_exit_every must be >= 1, got {self.substeps} and {self.early_exit_every}")

    @property
    def squeeze_steps(self) -> int:
        return int(round(self.squeeze_time / self.dt))

    @property
    def direction_steps(self) -> int:
        return int(round(self.direction_time / self.dt))

    @property
    def total_steps(self) -> int:
        return self.squeeze_steps + 6 * self.direction_steps

    @classmethod
    def strict(cls, **overrides) -> "Protocol":
        """Harder preset: effective friction 1.0 and gravity (9.81 m/s^2, -z) during the perturbations."""
        return replace(cls(friction=1.0, gravity_in_evaluation=9.81), **overrides)

    @classmethod
    def isaac_step(cls, **overrides) -> "Protocol":
        """The reference's literal Isaac step (100 Hz, 2 substeps, PyBullet's default 50 iterations)."""
        return replace(cls(**ISAAC_STEP), **overrides)

    @classmethod
    def isaac_drive(cls, **overrides) -> "Protocol":
        """The reference's Isaac drive speed: fingers close at Isaac's rate, not 14x faster.

        Isaac drives each joint with ``tau = clip(k (q* - q) - d qdot, +-effort)`` (k = 1000, d = 200):
        links of negligible inertia move at ``qdot = (k / d) (q* - q)``, 5 rad/s per rad of error,
        and press with the effort limit once a contact stops them. PyBullet's position motor is a
        velocity constraint aiming at ``qdot = (position_gain / dt) (q* - q)`` under the same force
        limit, so ``position_gain = dt k / d`` (0.0208 at 240 Hz) closes at Isaac's rate under the
        same torque limit (a blocked joint, though, presses with only a fraction of it: the motor's
        row is not solved to its limit within 100 solver iterations; ``benchmarks/results/yield.md``).
        The default gain 0.3 (the survey's PyBullet prototype) closes at
        72 rad/s per rad: fingers hit the object within milliseconds and the impacts make verdicts
        chaotic (benchmarks/README.md, *Joint-drive speed*, for the measured effect on robust yields).
        """
        dt = float(overrides.get("dt", cls.dt))
        gain = dt * ISAAC_DRIVE["stiffness"] / ISAAC_DRIVE["damping"]
        return replace(cls(position_gain=gain, velocity_gain=1.0), **overrides)

    @classmethod
    def preset(cls, name: str) -> "Protocol":
        """``"reference"`` (the default), ``"strict"``, ``"isaac-step"`` or ``"isaac-drive"``."""
        if name == "reference":
            return cls()
        if name == "strict":
            return cls.strict()
        if name == "isaac-step":
            return cls.isaac_step()
        if name == "isaac-drive":
            return cls.isaac_drive()
        raise ProtocolError(f"unknown protocol preset {name!r}; expected 'reference', 'strict', 'isaac-step' or 'isaac-drive'")
