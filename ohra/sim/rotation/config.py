"""Settings of the in-hand rotation task: one frozen dataclass with units, read from plain dicts.

The task terms come from the paper (issue 15: 20 Hz PD targets, the observation list, a clipped
+z angular-velocity reward minus drift, pose, torque, work and linear-velocity penalties); the
values it does not give come from HORA (Qi et al., "In-Hand Object Rotation via Rapid Motor
Adaptation"), the palm-up rotation task with these terms: relative targets of 1/24 rad per unit
action, 400-step episodes (20 s), rotation clipped to +-0.5 rad/s, penalty weights linvel 0.3,
pose 0.3, torque 0.1, work 2.0. The drift weight, the termination distances, the phase period and
the object size are ours (stated below).

Physics (chosen for speed, measured in ``benchmarks/bench_rotation.py``): PyBullet steps 1/120 s
(HORA's Isaac step), 6 sub-steps per 20 Hz control step, 20 solver iterations (PyBullet's default
50 costs 1.5x), fixed links merged, finger-finger collisions on and finger-palm off (the
evaluator's filters). The joints are PyBullet's implicit position motors capped at ``motor_force``
N m (the canonical URDF's effort); see :mod:`ohra.sim.rotation.scene` for why not PyBullet's
``numSubSteps`` and not an explicit PD.
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import PurePath
from typing import Any, Mapping

import numpy as np

from ohra.errors import OhraError, reject_unknown


class RotationConfigError(OhraError, ValueError):
    """A rotation setting is unknown or out of range."""


class RotationConfigWarning(UserWarning):
    """A rotation setting that is allowed but probably not meant (e.g. a penalty weight that pays a reward)."""


URDF_KINDS = ("canonical", "original")
INERTIALS = ("capsule", "original")  # canonical finger masses: the template's capsules or the original URDF's
SPACES = ("canonical", "native")
WORK_VELOCITIES = ("step", "instant")
GRASP_HOLDS = ("canonical", "own")
START_TARGETS = ("perturbed", "settled")
COLLISIONS = ("own", "canonical")

# Settings added after rotation runs were saved, with the value those runs ran with: a saved config
# without the key is read with this value (RotationConfig.from_saved), so resuming it changes nothing.
SAVED_BEFORE = {"joint_damping": True, "work_velocity": "instant", "grasp_hold": "own"}

# Reference ranges of the per-joint noise around the holding pose for the initial grasps (issue 15,
# from the paper's setup): LEAP +-0.25 rad, Shadow +-0.1 rad; other hands take Shadow's, the safer one. Chosen
# by the hand's name (a params file's own name, not the folders it lies in).
GRASP_NOISE = {"leap": 0.25, "shadow": 0.1}
DEFAULT_GRASP_NOISE = 0.1


@dataclass(frozen=True)
class RewardWeights:
    """Weights w_k of the total reward sum_k w_k * term_k (penalty terms are >= 0, so their weights are < 0)."""

    rotation: float = 1.0  # clipped angular velocity about world +z [rad/s]
    drift: float = -0.1  # object distance from its start position [m]  (ours)
    pose: float = -0.3  # squared joint deviation from the start pose [rad^2]
    torque: float = -0.1  # squared joint torques [N^2 m^2]
    work: float = -2.0  # squared mechanical power (sum tau * dq)^2 [W^2]
    linvel: float = -0.3  # object linear speed, L1 norm [m/s]
    # once, on the step the object falls or leaves the hand (not in the paper or HORA; 0 = off). A
    # per-step reward that stays below what the discounted rest of an episode is worth makes dropping
    # the object cheap: measured on the LEAP canonical policy resumed to 170 min, it turns the cube at
    # 0.43 rad/s but drops it in every episode (runs/rotation/README.md)
    fall: float = 0.0

    def __post_init__(self) -> None:
        # A penalty term is >= 0, so a positive weight pays for drift, torque, a drop...: allowed (an experiment may
        # want it), but said, since a sign slip (fall = 25 for -25) would otherwise train silently for an hour.
        paid = {k: v for k, v in asdict(self).items() if k != "rotation" and v > 0}
        if paid:
            warnings.warn(f"reward weights: positive penalty weight(s) {paid} reward what they name (penalty weights "
                          f"are <= 0; a drop penalty is e.g. {{\"fall\": -25}})", RotationConfigWarning, stacklevel=3)

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass(frozen=True)
class RotationConfig:
    """Every constant of the rotation environment. Units: metres, radians, seconds, kg, N m."""

    # -- hand and object -----------------------------------------------------------------------
    hand: str = "leap_hand_right"
    urdf: str = "canonical"  # "canonical": the canonical URDF; "original": the hand's own URDF
    inertials: str = "capsule"  # canonical URDF only: "original" gives its fingers the original URDF's masses
    # original URDF only: "canonical" swaps its collision shapes for the canonical hand's (the hybrid hand of
    # ohra.sim.hybrid: original kinematics, limits, masses and inertias, canonical capsules and palm disc)
    collisions: str = "own"
    form: str | None = None  # canonical form; None: extended when registered (closest to the original), else base
    space: str | None = None  # joint space of actions/observations: "canonical" (22) or "native" (the URDF's
    #                           driven joints); None: canonical for the canonical URDF, native for the original
    # "cube", "sphere", "cylinder" (lying along the fingers), or any object ohra resolves: "builtin:NAME",
    # "procedural:FAMILY:SEED", a mesh/URDF file or one-object folder (its primitives or convex pieces)
    object: str = "cube"
    # m: cube side / sphere and cylinder diameter (None: the palm radius); a mesh file's largest extent (None: its own)
    object_size: float | None = None
    object_density: float = 500.0  # kg/m^3
    friction: float = 1.0  # effective hand-object friction (each body gets its square root)

    # -- simulation and control ----------------------------------------------------------------
    control_hz: float = 20.0
    sim_dt: float = 1.0 / 120.0  # s per physics sub-step
    solver_iterations: int = 20
    self_collision: bool = True  # finger-finger contacts (finger-palm never)
    gravity: float = 9.81  # m/s^2 along world -z
    action_scale: float = 1.0 / 24.0  # rad of target change per unit action per control step
    motor_force: float = 1.0  # N m, torque cap of every joint motor
    position_gain: float = 0.3  # PyBullet position-motor gains (per sub-step)
    velocity_gain: float = 1.0
    # Keep the URDF's <dynamics damping>? PyBullet applies it explicitly (tau = -d * dq each sub-step),
    # which diverges when d * sim_dt exceeds ~2x the joint's effective inertia: measured on the original
    # Shadow URDF (d 0.1-0.2 N m s/rad, thumb and knuckle links of 1e-7 kg m^2) as joints chattering at
    # 10-40 rad/s in 60 % of the control steps of a 0.2-noise policy, so the work penalty reached
    # -4,000 per step. The motors' velocity gain damps implicitly; LEAP's URDFs and the canonical ones
    # have no damping, so dropping it changes nothing there.
    joint_damping: bool = False
    # Joint velocity in the work penalty: "step" = change of the joint angle over the control step / its
    # duration (what the joint did, like the rotation term); "instant" = PyBullet's velocity at the
    # last sub-step, which samples any sub-step oscillation (runs saved before this setting used it).
    work_velocity: str = "step"

    # -- episode, observation, reward, termination ---------------------------------------------
    episode_steps: int = 400  # control steps (20 s) before truncation
    phase_period: float = 1.0  # s, period of the 2-D phase clock (sin, cos) in the observation
    angvel_clip: float = 0.5  # rad/s, the rotation term is clip(omega_z, -clip, clip)
    weights: RewardWeights = field(default_factory=RewardWeights)
    fall_height: float = 0.03  # m: terminated when the object is this far below its start height
    max_distance: float = 0.08  # m: terminated when the object is this far from its start position

    # -- initial grasps ------------------------------------------------------------------------
    grasp_count: int = 1000  # cached starting states per (hand, urdf, object)
    grasp_noise: float | None = None  # rad, uniform per-joint noise on the holding pose; None: GRASP_NOISE
    grasp_seed: int = 0
    settle_time: float = 1.5  # s of simulation a perturbed grasp must survive (still over the last 0.5 s)
    min_contacts: int = 2  # distinct hand links touching the object at the end of the settle
    # The holding pose the starting states perturb, for an original URDF: "canonical" = the canonical
    # hand's holding pose (its fingers closed onto the object) mapped through the hand's action map, so
    # both URDFs start from the same hand pose; "own" = the original URDF closes its own fingers (runs
    # saved before this setting). Measured with "own" on the original LEAP: the thumb base touches the
    # object at q = 0 so the thumb never closes and one finger's middle joint bends backwards, leaving the
    # cube held by the thumb base alone (grasps.py). A canonical URDF always closes its own fingers.
    grasp_hold: str = "canonical"
    # Motor targets at reset: "perturbed" = the perturbed pose the starting state settled under (a finger
    # the object blocks keeps pressing: the start squeezes); "settled" = the settled joint angles, as
    # HORA's reset does (targets = cached joint positions), so an episode starts without a squeeze and
    # without the torque it costs. Same starting states either way.
    start_targets: str = "perturbed"

    def __post_init__(self) -> None:
        self._check_types()
        choices = {"urdf": URDF_KINDS, "inertials": INERTIALS, "grasp_hold": GRASP_HOLDS, "collisions": COLLISIONS,
                   "start_targets": START_TARGETS, "work_velocity": WORK_VELOCITIES}
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise RotationConfigError(f"{name} must be one of {allowed}, got {getattr(self, name)!r}")
        if self.inertials == "original" and self.urdf != "canonical":
            raise RotationConfigError("inertials='original' gives the canonical URDF the original's finger masses; "
                                      "the original URDF has them already (use urdf='canonical')")
        if self.collisions == "canonical" and self.urdf != "original":
            raise RotationConfigError("collisions='canonical' gives the original URDF the canonical collision shapes; "
                                      "the canonical URDF has them already (use urdf='original')")
        if self.space is not None and self.space not in SPACES:
            raise RotationConfigError(f"space must be one of {SPACES} or None, got {self.space!r}")
        if self.form is not None and self.form not in ("base", "extended"):
            raise RotationConfigError(f"form must be 'base', 'extended' or None, got {self.form!r}")
        if self.urdf == "canonical" and self.space == "native":
            raise RotationConfigError("the canonical URDF has only the canonical joint space (space='canonical')")
        positive = ("control_hz", "sim_dt", "action_scale", "motor_force", "phase_period", "angvel_clip",
                    "fall_height", "max_distance", "settle_time", "object_density")
        for name in positive:
            if not getattr(self, name) > 0:
                raise RotationConfigError(f"RotationConfig.{name} must be > 0, got {getattr(self, name)}")
        for name in ("solver_iterations", "episode_steps", "grasp_count"):
            if int(getattr(self, name)) < 1:
                raise RotationConfigError(f"RotationConfig.{name} must be >= 1, got {getattr(self, name)}")
        if self.object_size is not None and not self.object_size > 0:
            raise RotationConfigError(f"object_size must be > 0 or None, got {self.object_size}")
        if self.grasp_noise is not None and self.grasp_noise < 0:
            raise RotationConfigError(f"grasp_noise must be >= 0 or None, got {self.grasp_noise}")
        if self.friction < 0 or self.min_contacts < 0:
            raise RotationConfigError("friction and min_contacts must be >= 0")
        if abs(self.substeps * self.sim_dt - self.control_dt) > 1e-9:
            raise RotationConfigError(
                f"1/control_hz = {self.control_dt:.6g} s must be a whole number of sim_dt = {self.sim_dt:.6g} s")
        if isinstance(self.weights, Mapping):
            object.__setattr__(self, "weights", _weights(self.weights, "weights"))

    def _check_types(self) -> None:
        """Each setting of its declared type (a value given as text, such as ``--set sim_dt=abc``, or a
        fractional ``episode_steps`` is named here rather than failing later inside a comparison)."""
        for f in fields(self):
            v, kind = getattr(self, f.name), str(f.type)
            if kind == "RewardWeights" or (v is None and kind.endswith("| None")):
                continue
            kind = kind.removesuffix(" | None")
            if kind == "str" and f.name in ("hand", "object") and isinstance(v, os.PathLike):
                object.__setattr__(self, f.name, os.fspath(v))  # a params JSON or mesh path
                continue
            ok = {"str": isinstance(v, str), "bool": isinstance(v, (bool, np.bool_)),
                  "int": isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_)),
                  "float": isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))
                  and bool(np.isfinite(v))}[kind]  # NaN passed every `< 0` check after this one
            if not ok:
                what = {"str": "text", "bool": "true or false", "int": "a whole number", "float": "a finite number"}[kind]
                raise RotationConfigError(f"RotationConfig.{f.name} must be {what}"
                                          + (" or None" if str(f.type).endswith("| None") else "") + f", got {v!r}")

    @property
    def control_dt(self) -> float:
        """Seconds per control step."""
        return 1.0 / self.control_hz

    @property
    def substeps(self) -> int:
        """Physics sub-steps per control step."""
        return max(1, int(round(self.control_dt / self.sim_dt)))

    @property
    def resolved_space(self) -> str:
        return self.space or ("canonical" if self.urdf == "canonical" else "native")

    @property
    def resolved_grasp_noise(self) -> float:
        if self.grasp_noise is not None:
            return float(self.grasp_noise)
        name = self.hand
        if "/" in name or "\\" in name or name.endswith((".json", ".yaml", ".yml")):
            name = PurePath(name.replace("\\", "/").rsplit("/", 1)[-1]).stem  # the file's own name, not its folders
        for key, v in GRASP_NOISE.items():
            if key in name:
                return v
        return DEFAULT_GRASP_NOISE

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], source: str = "config") -> "RotationConfig":
        """Build from a plain mapping; an unknown key raises :class:`RotationConfigError` naming it."""
        reject_unknown(d, (f.name for f in fields(cls)), RotationConfigError, source, "rotation setting(s)")
        kw = dict(d)
        if "weights" in kw:
            kw["weights"] = _weights(kw["weights"], f"{source}: weights")
        return cls(**kw)

    @classmethod
    def from_saved(cls, d: Mapping[str, Any], source: str = "config") -> "RotationConfig":
        """Like :meth:`from_dict` for a config saved by a run: a setting added to ohra after the run was
        made takes the value the run had (:data:`SAVED_BEFORE`), others their defaults."""
        return cls.from_dict({**{k: v for k, v in SAVED_BEFORE.items() if k not in d}, **d}, source)

    def with_overrides(self, **kw: Any) -> "RotationConfig":
        """A copy with some settings changed (unknown names raise); ``weights`` given as a mapping changes
        only the terms it names."""
        if isinstance(kw.get("weights"), Mapping):
            kw["weights"] = {**self.weights.as_dict(), **kw["weights"]}
        return RotationConfig.from_dict({**self.to_dict(), **kw}, "overrides")


def _weights(w: Any, source: str) -> RewardWeights:
    if isinstance(w, RewardWeights):
        return w
    if not isinstance(w, Mapping):
        raise RotationConfigError(f"{source}: reward weights are a mapping of term to weight, e.g. {{\"fall\": -25}} "
                                  f"(JSON on the command line), got {w!r}")
    reject_unknown(w, (f.name for f in fields(RewardWeights)), RotationConfigError, source, "reward term(s)")
    bad = {k: v for k, v in w.items() if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)}
    if bad:
        raise RotationConfigError(f"{source}: reward weights must be finite numbers, got {bad}")
    return replace(RewardWeights(), **{k: float(v) for k, v in w.items()})
