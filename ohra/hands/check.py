"""Render and load hands in Pinocchio and PyBullet: the smoke test every registered hand must pass."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Iterable

import numpy as np
import pinocchio as pin

from ohra.sim.bullet import captured_c_output, load_urdf_text, pb  # via ohra.sim: imported without its build line
from ohra.canonical.urdfgen import render
from ohra.hands import get_hand


@dataclass(frozen=True)
class HandCheck:
    """Outcome of rendering and loading one hand."""

    name: str
    form: str
    fingers: int
    dof: int
    pinocchio_nq: int
    bullet_joints: int
    warnings: str
    seconds: float

    tips: int = 0

    @property
    def ok(self) -> bool:
        """22 DoF in Pinocchio; in PyBullet the 22 revolute joints plus world_to_palm and one tip
        joint per present finger; nothing printed."""
        return self.pinocchio_nq == 22 and self.bullet_joints == 23 + self.tips and not self.warnings


def check_hand(name: str, form: str | None = None, client: int | None = None, visuals: bool = False) -> HandCheck:
    """Render ``name`` and load it in Pinocchio and in PyBullet (DIRECT), capturing any warning.

    Visual shapes (identical to the collision primitives) are skipped in PyBullet unless ``visuals``;
    that halves the load time.
    """
    from ohra.hands.resolve import resolve_hand

    t0 = time.perf_counter()
    ref = resolve_hand(name, form)  # a spec or params file is listed by its hand's name, not its path
    params, name = ref.params, ref.name
    text = render(params, robot_name=name)
    own = client is None
    with captured_c_output() as captured:
        model = pin.buildModelFromXML(text)
        if own:
            client = pb.connect(pb.DIRECT)
        try:
            flags = 0 if visuals else pb.URDF_IGNORE_VISUAL_SHAPES
            body = load_urdf_text(text, client, useFixedBase=True, flags=flags)
            nj = pb.getNumJoints(body, physicsClientId=client)
            pb.removeBody(body, physicsClientId=client)
        finally:
            if own:
                pb.disconnect(client)
    form_name = params.form if params.form == "base" else params.template
    return HandCheck(
        name, form_name, params.num_fingers, params.dof, model.nq, nj,
        "".join(captured).strip(), time.perf_counter() - t0, int(params.present_fingers.sum()),
    )


def check_hands(names: Iterable[tuple[str, str | None]]) -> list[HandCheck]:
    """Check many hands sharing one PyBullet client."""
    client = pb.connect(pb.DIRECT)
    try:
        return [check_hand(n, f, client) for n, f in names]
    finally:
        pb.disconnect(client)


def fingertip_table(name: str, form: str | None = None) -> np.ndarray:
    """(5,3) fingertip positions at q=0 (NaN for absent fingers)."""
    from ohra.canonical.kinematics import HandModel

    return HandModel.from_params(get_hand(name, form)).fingertips(np.zeros(22))
