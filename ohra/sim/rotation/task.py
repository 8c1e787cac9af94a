"""What a rotation config resolves to: the simulated hand, the policy's joint space, the object.

The policy acts and observes in a *joint space*: the canonical 22-D space (canonical URDF; or an
original URDF driven through its :class:`ohra.ActionMap`, the unified action space) or the
original URDF's own driven joints ("native"). :class:`JointSpace` maps that space to the
simulator's driven joints and back.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ohra.sim.hands import SimHand
from ohra.sim.rotation.config import RotationConfig, RotationConfigError
from ohra.sim.rotation.objects import SIZED, ObjectShape, make_object


class JointSpace:
    """The policy's joint space and its (affine) maps to the simulator's driven joints.

    Attributes:
        names: joint names (canonical slot names, or the original URDF's joint names).
        lower, upper: (n,) limits [rad]; a joint with ``upper <= lower`` is immovable (its action is ignored).
        canonical: True for the 22-D canonical space (``SimHand.to_sim`` / ``to_canonical``, i.e. the
            action map for an original URDF), False for the URDF's own driven joints.

    Both maps are affine (signs, offsets, constant slots), so they are evaluated once into matrices:
    a control step then costs two small mat-vecs instead of the general mapping code.
    """

    def __init__(self, names: tuple[str, ...], lower: np.ndarray, upper: np.ndarray, canonical: bool, hand: SimHand):
        self.names, self.canonical, self.hand = tuple(names), canonical, hand
        self.lower, self.upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
        n, m = len(self.names), len(hand.joints)
        if canonical:
            self._b = hand.to_canonical(np.zeros(m))
            self._A = np.stack([hand.to_canonical(e) - self._b for e in np.eye(m)], axis=1)  # (n, m)
            self._d = hand.to_sim(np.zeros(n))
            self._C = np.stack([hand.to_sim(e) - self._d for e in np.eye(n)], axis=1)  # (m, n)
        else:
            self._A, self._b = np.eye(m), np.zeros(m)
            self._C, self._d = np.eye(m), np.zeros(m)

    @property
    def dim(self) -> int:
        return len(self.names)

    @property
    def movable(self) -> np.ndarray:
        return self.upper > self.lower

    def to_sim(self, x: np.ndarray) -> np.ndarray:
        """Policy-space joint values (n,) -> simulator driven joints (m,), clipped into their limits."""
        return np.clip(self._C @ x + self._d, self.hand.lower, self.hand.upper)

    def from_sim(self, qs: np.ndarray) -> np.ndarray:
        """Simulator driven-joint values (m,) -> policy space (n,)."""
        return self._A @ qs + self._b

    def velocity_from_sim(self, dqs: np.ndarray) -> np.ndarray:
        """Driven-joint velocities -> policy space (the linear part of :meth:`from_sim`)."""
        return self._A @ dqs


@dataclass
class Task:
    """A resolved config: the hand, its canonical params, the joint space and the object."""

    cfg: RotationConfig
    hand: SimHand
    params: object
    space: JointSpace
    obj: ObjectShape

    @property
    def palm_radius(self) -> float:
        return float(self.params.palm_radius)


def canonical_form(name: str, form: str | None) -> str | None:
    """The form to use: ``form``, else extended when ``name`` is registered in it (closest to the original), else None."""
    if form is not None:
        return form
    from ohra.hands import registry

    if name in registry.registered_hands() and "extended" in registry.registered_forms(name):
        return "extended"
    return None


def resolve(cfg: RotationConfig, sim_hand: SimHand | None = None) -> Task:
    """Build the :class:`Task` of ``cfg`` (loads the hand; the original URDF needs the hand assets).

    ``sim_hand``: simulate this :class:`SimHand` instead of the one ``cfg`` names (e.g. an original URDF with
    other collision shapes); ``cfg.hand`` still gives the canonical params (object size, palm) and
    ``cfg.urdf`` must say which kind it is (canonical or original).
    """
    from ohra.hands import get_hand

    form = canonical_form(cfg.hand, cfg.form)
    params = get_hand(cfg.hand, form)

    hand = sim_hand
    if hand is not None:
        if hand.canonical != (cfg.urdf == "canonical"):
            raise RotationConfigError(f"hand {hand.name!r} is {'a canonical' if hand.canonical else 'an original'} "
                                      f"hand but the config says urdf={cfg.urdf!r}")
    elif cfg.urdf == "canonical":
        hand = SimHand.from_params(params, name=f"{cfg.hand}:canonical")
        if cfg.inertials == "original":
            from ohra.sim.hands import original_finger_masses

            hand = hand.with_finger_masses(original_finger_masses(cfg.hand, params.form))
    else:
        # a registered name, a spec YAML or a params JSON beside its spec (HandNotFoundError names what is missing)
        hand = SimHand.original_of(cfg.hand, params.form, purpose="urdf='original'")
        if cfg.collisions == "canonical":
            from ohra.sim.hybrid import with_canonical_collisions

            hand, _ = with_canonical_collisions(hand, SimHand.from_params(params, name=f"{cfg.hand}:canonical"))
    if cfg.resolved_space == "canonical":
        space = JointSpace(tuple(_canonical_names()), hand.canon_lower.copy(), hand.canon_upper.copy(), True, hand)
    else:
        space = JointSpace(tuple(hand.joints), hand.lower.copy(), hand.upper.copy(), False, hand)
    # the sized shapes default to the palm radius; other objects keep their own size unless one is given
    size = cfg.object_size if cfg.object_size is not None or cfg.object not in SIZED else float(params.palm_radius)
    return Task(cfg, hand, params, space, make_object(cfg.object, size, cfg.object_density))


def _canonical_names() -> list[str]:
    from ohra.canonical.params import JOINT_NAMES

    return list(JOINT_NAMES)
