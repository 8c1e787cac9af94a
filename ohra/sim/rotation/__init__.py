"""In-hand rotation in PyBullet: a Gymnasium environment for any canonical hand or original URDF.

Importing this package registers ``ohra/InHandRotate-v0``::

    import gymnasium as gym
    import ohra.sim.rotation  # registers the id
    env = gym.make("ohra/InHandRotate-v0", hand="leap_hand_right", urdf="original", object="cube")

Needs the ``rl`` extra (gymnasium; training also stable-baselines3): ``pip install ohra[rl]``.
"""

from __future__ import annotations

from ohra.errors import OhraError

try:
    import gymnasium
except ImportError as exc:  # pragma: no cover - exercised only without gymnasium
    class MissingGymnasiumError(OhraError, ImportError):
        """gymnasium is not installed."""

    raise MissingGymnasiumError(
        f"ohra.sim.rotation needs gymnasium ({exc}); install it with `pip install ohra[rl]`") from None

from ohra.sim.rotation.config import GRASP_NOISE, RewardWeights, RotationConfig, RotationConfigError
from ohra.sim.rotation.env import InHandRotateEnv, RotationActionError, RotationEnvClosed, RotationResetNeeded
from ohra.sim.rotation.grasps import GraspGenerationError, GraspSet, load_or_generate
from ohra.sim.rotation.scene import SceneError
from ohra.sim.rotation.task import JointSpace, Task, resolve

ENV_ID = "ohra/InHandRotate-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="ohra.sim.rotation.env:InHandRotateEnv")

__all__ = [
    "ENV_ID", "InHandRotateEnv", "RotationActionError", "RotationEnvClosed", "RotationResetNeeded", "RotationConfig",
    "RewardWeights", "RotationConfigError", "GraspSet",
    "GraspGenerationError", "SceneError", "load_or_generate", "resolve", "Task", "JointSpace", "GRASP_NOISE",
]
